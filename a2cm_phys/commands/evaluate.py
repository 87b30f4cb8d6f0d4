"""Play pursuers against an evader and report: ``python -m a2cm_phys.evaluate RUN --greedy``.

The pursuers and the evader are chosen apart, each a run directory or a named policy
(``--pursuers random|pursuit|oracle|minimax|RUN``, ``--evader
random|flee|static|best-response|equilibrium|RUN``; see :mod:`a2cm_phys.analysis.names`). The
report gives the mean, median and 95th percentile of the capture steps, the capture rate,
the collisions per episode and the return under the scenario's raw reward, each with a
seeded bootstrap 95% confidence interval, and beside them the scenario's reference
(:func:`~a2cm_phys.analysis.evaluation.reference_of`, as ``plot`` and the report draw it):
on grids the oracle solves, the exact optimum and the gap to it; in physics a reference
policy played on the same episodes (``--reference``).
``--cross-play`` plays every pairing of comma-separated lists of pursuers and evaders.

Episodes are played in several games at once without favouring short ones: each game plays
a fixed quota of consecutive episodes (episodes it finishes after its quota are ignored).
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from typing import Any

from ..analysis.evaluation import (
    play,
    reference_policy,
    reference_report,
)
from ..analysis.names import EVADER_POLICIES, PURSUER_POLICIES, is_named
from ..analysis.policies import Matchup, matchup
from ..config import ConfigError, Scenario
from ..training.runs import load_trained_run
from .options import SEED, Parser, add_scenario_options, int_range, run_cli, scenario_from_args

# ---------------------------------------------------------------------- formatting


def format_report(report: dict[str, Any], title: str) -> str:
    """The report as an aligned text table, with the reference and the gap to it."""
    lines = [title, f"{'':24}{'value':>12}  95% CI"]

    def row(name: str, s: dict[str, float], pct: bool = False) -> None:
        k, fmt = (100.0, "{:.1f}%") if pct else (1.0, "{:,.3f}")
        v, lo, hi = (fmt.format(k * s[key]) for key in ("value", "lo", "hi"))
        lines.append(f"{name:24}{v:>12}  [{lo}, {hi}]")

    sections = [("capture_steps", "capture steps"), ("length", "episode length")]
    if report["capture_rate"]["value"] == 1.0:  # every episode is a capture: same numbers
        sections = sections[:1]
    for key, label in sections:
        for stat in ("mean", "median", "p95"):
            row(f"{label} {stat}", report[key][stat])
    row("capture rate", report["capture_rate"], pct=True)
    row("collisions / episode", report["collisions_per_episode"])
    row("return", report["return"])
    lines.append(f"{'episodes':24}{report['episodes']:>12}  (truncated: {report['truncated']})")
    ref = report.get("reference")
    if ref and "unavailable" in ref:
        lines.append(f"reference ({ref['policy']}) unavailable: {ref['unavailable']}")
    elif ref:
        steps = report["capture_steps"]["mean"]["value"]
        ret = report["return"]["value"]
        if ref["exact"]:
            ref_steps, ref_ret = ref["capture_steps"], ref["return"]
            lines.append(f"{ref['policy']}: capture steps {ref_steps:.3f}, return {ref_ret:,.3f}")
        else:
            ref_steps = ref["capture_steps"]["mean"]["value"]
            ref_ret = ref["return"]["value"]
            coll = ref["collisions_per_episode"]["value"]
            lines.append(
                f"reference, {ref['policy']}: capture steps {ref_steps:.3f}, return "
                f"{ref_ret:,.3f}, collisions / episode {coll:.4f}"
            )
        lines.append(
            f"gap to the reference: capture steps {100 * (steps / ref_steps - 1):+.1f}%,"
            f" return {ret / ref_ret:.3f}× the reference's"
        )
    return "\n".join(lines)


def format_cross_play(rows: list[dict[str, Any]]) -> str:
    """The cross-play table (Markdown): one row per pairing."""
    lines = [
        "| pursuers | evader | capture steps (mean, 95% CI) | capture rate | collisions / ep |",
        "|---|---|---|---|---|",
    ]
    for r in rows:
        s, c, k = r["capture_steps"]["mean"], r["capture_rate"], r["collisions_per_episode"]
        lines.append(
            f"| {r['pursuers']} | {r['evader']} | {s['value']:.3f} [{s['lo']:.3f}, {s['hi']:.3f}]"
            f" | {100 * c['value']:.1f}% | {k['value']:.4f} [{k['lo']:.4f}, {k['hi']:.4f}] |"
        )
    return "\n".join(lines)


# ---------------------------------------------------------------------- command line


def build_parser() -> argparse.ArgumentParser:
    """The ``python -m a2cm_phys.evaluate`` argument parser."""
    p = Parser(
        prog="python -m a2cm_phys.evaluate",
        description="Play pursuers against an evader and report capture statistics.",
    )
    p.add_argument("run", nargs="?", help="run directory or checkpoint file (the pursuers)")
    p.add_argument(
        "--pursuers",
        help=f"a run directory or {'|'.join(PURSUER_POLICIES)} (default: RUN); with"
        " --cross-play a comma-separated list",
    )
    p.add_argument(
        "--evader",
        help=f"a run directory with a learned evader, {'|'.join(EVADER_POLICIES)},"
        " best-response (exact, grids) or equilibrium (the game's, grids; minutes)"
        " (default: the scenario's); with --cross-play a comma-separated list",
    )
    p.add_argument(
        "--policy",
        choices=["trained", *PURSUER_POLICIES],
        help="the pursuers as a named policy (same as --pursuers NAME; trained: RUN)",
    )
    p.add_argument(
        "--reference",
        choices=["oracle", "pursuit", "random", "none"],
        help="what to show beside the result (default: the oracle: on grids its exact"
        " optimum, in physics with discrete moves played in the arena; under continuous"
        " control the pursuit policy, played)",
    )
    p.add_argument("--cross-play", action="store_true", help="every pursuers × evader pairing")
    p.add_argument("--episodes", type=int_range(1, 100_000_000), default=1000)
    p.add_argument("--greedy", action="store_true", help="most probable action, no sampling")
    p.add_argument("--seed", type=SEED, default=0)
    p.add_argument("--num-envs", type=int_range(1, 65_536), default=16, help="games at once")
    add_scenario_options(p, train=False, scenario_help="the scenario (default: the run's own)")
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    return p


def _pursuers_spec(args: argparse.Namespace) -> str:
    if args.policy and args.policy != "trained":
        if args.pursuers:
            raise ConfigError("--policy and --pursuers name the same thing: give one")
        return args.policy
    spec = args.pursuers or args.run
    if not spec:
        raise ConfigError(
            f"give a run directory, or --pursuers {'|'.join(PURSUER_POLICIES)} with --scenario"
        )
    return spec


def _scenario(args: argparse.Namespace, specs: Sequence[str | None]) -> Scenario:
    if args.set and not args.scenario:
        raise ConfigError("--set: needs --scenario (a trained run's scenario is fixed)")
    if args.scenario:
        return scenario_from_args(args, train=False)
    for spec in specs:  # the first run among the policies names the game
        if spec and not (is_named(spec, "pursuers") or is_named(spec, "evader")):
            return load_trained_run(spec).scenario
    raise ConfigError("named policies need --scenario (or a run directory)")


def _main(argv: Sequence[str]) -> int:
    args = build_parser().parse_args(argv)
    if args.cross_play:
        return _cross_play(args)
    pursuers = _pursuers_spec(args)
    scenario = _scenario(args, [pursuers, args.evader])
    game = matchup(scenario, pursuers, args.evader, greedy=args.greedy)
    result = play(
        game.scenario, game.pursuers, args.episodes, args.num_envs, args.seed, game.evader
    )
    report: dict[str, Any] = {
        "scenario": scenario.name,
        "policy": game.label,
        **result.report(args.seed),
    }
    reference = args.reference or reference_policy(scenario)
    if game.evader is None and pursuers != reference:
        report["reference"] = reference_report(
            game.scenario, reference, args.episodes, args.num_envs, args.seed
        )
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        print(format_report(report, f"{scenario.name}: {game.label}, seed {args.seed}"))
    return 0


def _cross_play(args: argparse.Namespace) -> int:
    pursuers = [s.strip() for s in _pursuers_spec(args).split(",") if s.strip()]
    evaders = [s.strip() for s in (args.evader or "").split(",") if s.strip()] or [None]
    scenario = _scenario(args, [*pursuers, *evaders])
    games: list[tuple[str, str, Matchup]] = [
        (p, e or scenario.evader, matchup(scenario, p, e, greedy=args.greedy))
        for p in pursuers
        for e in evaders
    ]
    rows = []
    for p, e, game in games:
        result = play(
            game.scenario, game.pursuers, args.episodes, args.num_envs, args.seed, game.evader
        )
        rows.append({"pursuers": p, "evader": e, **result.report(args.seed)})
    print(json.dumps(rows, indent=2) if args.json else format_cross_play(rows))
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python -m a2cm_phys.evaluate``; returns the exit status."""
    return run_cli(_main, argv)


if __name__ == "__main__":
    sys.exit(main())
