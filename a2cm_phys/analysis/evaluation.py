"""Play pursuers against an evader and measure (the ``evaluate`` command prints it):
:func:`play` runs episodes of any two policies and returns every episode's outcome;
:func:`optimum` is the exact oracle's figures for a grid scenario, and
:func:`reference_report` the one reference every command, figure and the report compare
against (the optimum on grids; the oracle driven in physics, or ``pursuit`` under
continuous control)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..analysis.policies import (
    pursuer_policy,
)
from ..analysis.stats import describe
from ..config import ConfigError, Scenario
from ..envs.vector import VectorEnv
from ..training.rollout import Policy
from ..training.seeding import policy_rng

__all__ = ["EvalResult", "optimum", "play", "reference_report"]


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
    scenario: Scenario,
    policy: Policy,
    episodes: int,
    num_envs: int = 16,
    seed: int = 0,
    evader: Policy | None = None,
) -> EvalResult:
    """Play ``episodes`` episodes of ``policy`` in up to ``num_envs`` games, seeded; a
    learned evader's ``evader`` policy acts where the scenario's evader is learned."""
    num_envs = max(1, min(num_envs, episodes))
    env = VectorEnv(scenario, num_envs)
    obs, rng = env.reset(seed), policy_rng(seed)
    quota = np.full(num_envs, episodes // num_envs)
    quota[: episodes % num_envs] += 1
    per_env: list[list] = [[] for _ in range(num_envs)]
    remaining = episodes
    while remaining:
        actions = policy(obs, rng)
        if evader is None:
            step = env.step(actions, validate=False)
        else:
            step = env.step(actions, evader(obs, rng)[:, 0], validate=False)
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


# ---------------------------------------------------------------------- references


def optimum(scenario: Scenario) -> dict[str, float] | None:
    """The exact optimum of a grid scenario from its default start (expected capture steps
    and return under the raw reward), or ``None`` where the oracle does not solve it."""
    if scenario.mode != "grid" or scenario.evader == "learned":
        return None
    from ..solve import TooLargeError, UnsupportedError
    from ..solve.cache import load_or_solve

    try:
        sol = load_or_solve(scenario)
    except (TooLargeError, UnsupportedError):
        return None
    start = sol.start_positions()
    return {
        "capture_steps": float(sol.expected_capture_steps(start)),
        "return": float(sol.optimal_return(start)),
    }


def reference_report(
    scenario: Scenario, name: str, episodes: int, num_envs: int, seed: int
) -> dict[str, Any] | None:
    """The reference beside a result: the exact optimum on grids the oracle solves, else
    the named pursuer policy played on the same episodes (``None`` for ``none``)."""
    if name == "none":
        return None
    best = optimum(scenario) if name == "oracle" else None
    if best is not None:
        return {"policy": "optimum (exact oracle)", "exact": True, **best}
    try:
        policy = pursuer_policy(name, scenario)
    except ConfigError as err:  # e.g. an arena too large for the oracle: no reference
        return {"policy": name, "unavailable": str(err)}
    result = play(scenario, policy, episodes, num_envs, seed)
    return {"policy": f"{name} (played)", "exact": False, **result.report(seed)}
