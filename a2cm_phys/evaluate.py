"""Play a trained (or baseline) policy: ``python -m a2cm_phys.evaluate RUN_DIR --episodes N``.

Reports the mean, median and 95th percentile of the episode length (the capture steps when
every episode ends in a capture), the same over captured episodes only, the capture rate
and the collisions per episode, each with a seeded bootstrap 95% confidence interval.

Episodes are played in several games at once without favouring short ones: each game plays
a fixed quota of consecutive episodes (episodes it finishes after its quota are ignored).
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from . import checkpoint
from .algos import ActorCritic, make_model
from .cli import SEED, Parser, add_scenario_options, int_range, run_cli, scenario_from_args
from .config import ConfigError, Scenario, build, load_train
from .envs.vector import VectorEnv
from .rollout import Policy
from .stats import describe
from .trainer import policy_rng


@dataclass
class EvalResult:
    """Per-episode outcomes of an evaluation, in the order (game, episode)."""

    lengths: np.ndarray
    returns: np.ndarray
    captured: np.ndarray
    truncated: np.ndarray
    collisions: np.ndarray

    def report(self, seed: int = 0) -> dict[str, Any]:
        """Point estimates with bootstrap 95% CIs (``{"value", "lo", "hi"}`` per statistic)."""
        return {
            "episodes": len(self.lengths),
            "length": describe(self.lengths, seed=seed),
            "capture_steps": describe(self.lengths[self.captured], seed=seed),
            "capture_rate": describe(self.captured, ("mean",), seed=seed)["mean"],
            "collisions_per_episode": describe(self.collisions, ("mean",), seed=seed)["mean"],
            "return": describe(self.returns, ("mean",), seed=seed)["mean"],
            "truncated": int(self.truncated.sum()),
        }


def play(
    scenario: Scenario, policy: Policy, episodes: int, num_envs: int = 16, seed: int = 0
) -> EvalResult:
    """Play ``episodes`` episodes of ``policy`` in up to ``num_envs`` games, seeded."""
    num_envs = max(1, min(num_envs, episodes))
    env = VectorEnv(scenario, num_envs)
    obs, rng = env.reset(seed), policy_rng(seed)
    quota = np.full(num_envs, episodes // num_envs)
    quota[: episodes % num_envs] += 1
    per_env: list[list] = [[] for _ in range(num_envs)]
    remaining = episodes
    while remaining:
        step = env.step(policy(obs, rng), validate=False)
        obs = step.obs
        for ep in step.episodes:
            if len(per_env[ep.env]) < quota[ep.env]:
                per_env[ep.env].append(ep)
                remaining -= 1
    env.close()
    eps = [ep for game in per_env for ep in game]
    return EvalResult(
        lengths=np.array([e.length for e in eps], dtype=np.int64),
        returns=np.array([e.ret for e in eps], dtype=np.float64),
        captured=np.array([e.captured for e in eps], dtype=bool),
        truncated=np.array([e.truncated for e in eps], dtype=bool),
        collisions=np.array([e.collisions for e in eps], dtype=np.int64),
    )


def load_trained(path: str | Path) -> tuple[Scenario, ActorCritic]:
    """The scenario and trained model of a run directory or checkpoint file."""
    state = checkpoint.load(path)
    scenario = build(Scenario, state["scenario"], f"{path} (checkpoint)")
    cfg = load_train({**state["train"], "device": "cpu"}, f"{path} (checkpoint)")
    model = make_model(cfg, scenario)
    model.load_state_dict(state["learner"]["model"])
    return scenario, model


def model_policy(model: ActorCritic, greedy: bool = False) -> Policy:
    """The actors of ``model`` as a rollout policy (sampled, or the most probable action)."""
    return lambda obs, rng: model.act(obs, rng, greedy=greedy)


def random_policy(scenario: Scenario) -> Policy:
    """Uniformly random actions for every pursuer (the baseline)."""
    shape = (scenario.pursuers,)
    return lambda obs, rng: rng.integers(0, scenario.actions, size=(len(obs), *shape))


def oracle_policy(scenario: Scenario) -> Policy:
    """The exact optimum of a grid scenario (:class:`a2cm_phys.oracle.OraclePolicy`)."""
    from .oracle import OraclePolicy

    oracle = OraclePolicy(scenario)
    return lambda obs, rng: oracle.act(obs)


def format_report(report: dict[str, Any], title: str) -> str:
    """The report as an aligned text table."""
    lines = [title, f"{'':24}{'value':>10}  95% CI"]

    def row(name: str, s: dict[str, float], pct: bool = False) -> None:
        k, fmt = (100.0, "{:.1f}%") if pct else (1.0, "{:.3f}")
        v, lo, hi = (fmt.format(k * s[key]) for key in ("value", "lo", "hi"))
        lines.append(f"{name:24}{v:>10}  [{lo}, {hi}]")

    sections = [("capture_steps", "capture steps"), ("length", "episode length")]
    if report["capture_rate"]["value"] == 1.0:  # every episode is a capture: same numbers
        sections = sections[:1]
    for key, label in sections:
        for stat in ("mean", "median", "p95"):
            row(f"{label} {stat}", report[key][stat])
    row("capture rate", report["capture_rate"], pct=True)
    row("collisions / episode", report["collisions_per_episode"])
    row("return", report["return"])
    lines.append(f"{'episodes':24}{report['episodes']:>10}  (truncated: {report['truncated']})")
    return "\n".join(lines)


def build_parser() -> argparse.ArgumentParser:
    """The ``python -m a2cm_phys.evaluate`` argument parser."""
    p = Parser(
        prog="python -m a2cm_phys.evaluate",
        description="Play a trained policy (or a baseline) and report capture statistics.",
    )
    p.add_argument("run", nargs="?", help="run directory or checkpoint file")
    p.add_argument("--episodes", type=int_range(1, 100_000_000), default=1000)
    p.add_argument("--greedy", action="store_true", help="most probable action, no sampling")
    p.add_argument("--seed", type=SEED, default=0)
    p.add_argument("--num-envs", type=int_range(1, 65_536), default=16, help="games at once")
    p.add_argument("--policy", choices=["trained", "random", "oracle"], default="trained")
    add_scenario_options(
        p, train=False, scenario_help="scenario for --policy random/oracle without a run"
    )
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    return p


def _setup(args: argparse.Namespace) -> tuple[Scenario, Policy, str]:
    if args.set and not args.scenario:
        raise ConfigError("--set: needs --scenario (a trained run's scenario is fixed)")
    if args.policy == "trained" or (args.run and not args.scenario):
        if not args.run:
            raise ConfigError("give a run directory or checkpoint (or --policy random/oracle)")
        try:
            scenario, model = load_trained(args.run)
        except (OSError, ValueError) as err:
            raise ConfigError(str(err)) from None
    elif args.scenario:
        scenario, model = scenario_from_args(args, train=False), None
    else:
        raise ConfigError("--policy random/oracle needs --scenario or a run directory")
    if args.policy == "trained":
        mode = "greedy" if args.greedy else "sampled"
        return scenario, model_policy(model, args.greedy), f"trained policy ({mode})"
    if args.policy == "random":
        return scenario, random_policy(scenario), "random policy"
    from .solve import TooLargeError, UnsupportedError

    try:
        return scenario, oracle_policy(scenario), "oracle policy"
    except (TooLargeError, UnsupportedError) as err:
        raise ConfigError(f"--policy oracle: {err}") from None


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python -m a2cm_phys.evaluate``; returns the exit status."""
    return run_cli(_main, argv)


def _main(argv: Sequence[str]) -> int:
    args = build_parser().parse_args(argv)
    scenario, policy, label = _setup(args)
    result = play(scenario, policy, args.episodes, args.num_envs, args.seed)
    report = {"scenario": scenario.name, "policy": label, **result.report(args.seed)}
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        print(format_report(report, f"{scenario.name}: {label}, seed {args.seed}"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
