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

``--render gif|png`` then plays ``--render-episodes`` more episodes of the same pairing in
one game from the same seed (greedy or not, as evaluated: greedy, the first is the first
episode of the evaluation's first game) and draws each as ``replay`` draws a logged one
(:mod:`a2cm_phys.analysis.playback`, :mod:`a2cm_phys.analysis.pictures`): a GIF at the
game's pace or a PNG contact sheet, with a legend and a caption for a capture or a
collision, one file per episode, by default ``STEM-epN.gif`` in the current folder
(``pretrained-NAME``, ``onnx-FOLDER``, ``POLICY-SCENARIO`` or the run's name); each file
written is a line ``wrote FILE (…how the episode ended)`` after the report (with
``--json``: the report's ``pictures``). So ``evaluate --pursuers pretrained:grid_collision
--greedy --render gif`` shows a trained team right after installing, with no training.

The episodes played are counted on stderr (a bar on a terminal, else a line every
``A2CM_PROGRESS_SECONDS``, 30 s by default; ``--no-progress`` or ``A2CM_PROGRESS=0``
silences it), as are a reference policy's and the solvers' work; stdout holds the report.

Episodes are played in several games at once without favouring short ones: each game plays
a fixed quota of consecutive episodes (episodes it finishes after its quota are ignored).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..analysis.names import EVADER_POLICIES, PURSUER_POLICIES, is_named
from ..config import ConfigError, Scenario
from .options import SEED, Parser, add_scenario_options, int_range, run_cli, scenario_from_args
from .picture_options import add_render_options, check_render, draw_episodes

if TYPE_CHECKING:
    from ..analysis.policies import Matchup

# Modules that reach torch or the solvers are imported where they are used, after the
# command line is parsed, so that --help answers at once.

# ---------------------------------------------------------------------- formatting


def format_report(report: dict[str, Any], title: str) -> str:
    """The report as an aligned text table, with the reference and the gap to it."""
    lines = [title, f"{'':24}{'value':>12}  95% CI"]

    def row(name: str, s: dict[str, float], pct: bool = False) -> None:
        if not math.isfinite(s["value"]):  # a statistic of no episode: no capture
            lines.append(f"{name:24}{'none':>12}  (no episode ended in a capture)")
            return
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
        lines.append(f"gap to the reference, capture steps: {_gap(steps, ref_steps, ' steps')}")
        lines.append(f"gap to the reference, return: {_gap(ret, ref_ret)}")
    return "\n".join(lines)


def _gap(value: float, ref: float, unit: str = "") -> str:
    """``value`` against ``ref`` as a difference, with the per cent where ``ref`` is a
    positive amount (steps): never a ratio of two returns, whose sign would mislead."""
    if not (math.isfinite(value) and math.isfinite(ref)):
        missing = "the result" if not math.isfinite(value) else "the reference"
        return f"none ({missing} has no value: no episode of it ended in a capture)"
    diff = value - ref
    pct = f" ({100 * diff / ref:+.1f}%)" if unit and ref > 0 else ""
    return f"{diff:+,.3f}{unit}{pct} against the reference's {ref:,.3f}"


def format_cross_play(rows: list[dict[str, Any]]) -> str:
    """The cross-play table (Markdown): one row per pairing."""
    lines = [
        "| pursuers | evader | capture steps (mean, 95% CI) | capture rate | collisions / ep |",
        "|---|---|---|---|---|",
    ]
    for r in rows:
        s, c, k = r["capture_steps"]["mean"], r["capture_rate"], r["collisions_per_episode"]
        steps = (
            f"{s['value']:.3f} [{s['lo']:.3f}, {s['hi']:.3f}]"
            if math.isfinite(s["value"])
            else "none (no capture)"
        )
        lines.append(
            f"| {r['pursuers']} | {r['evader']} | {steps}"
            f" | {100 * c['value']:.1f}% | {k['value']:.4f} [{k['lo']:.4f}, {k['hi']:.4f}] |"
        )
    return "\n".join(lines)


# ---------------------------------------------------------------------- command line

STATUS_WIDTH = 20
"""The most characters of a status beside the count: more would push a bar past 80
columns, where it is cut."""


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
        help="the pursuers as a named policy (same as --pursuers NAME; trained: RUN)"
        " (default: trained)",
    )
    p.add_argument(
        "--reference",
        choices=["oracle", "pursuit", "random", "qmdp", "search", "none"],
        help="what to show beside the result (default: the oracle: on grids its exact"
        " optimum, in physics with discrete moves played in the arena; under continuous"
        " control the pursuit policy, played; with sensing also qmdp (grids) or search"
        " (continuous control), played)",
    )
    p.add_argument(
        "--cross-play",
        action="store_true",
        help="every pursuers × evader pairing, as a table (no reference)",
    )
    p.add_argument(
        "--episodes",
        type=int_range(1, 100_000_000),
        default=1000,
        help="episodes to play (with --cross-play: per pairing; a played reference plays as many)",
    )
    p.add_argument("--greedy", action="store_true", help="most probable action, no sampling")
    p.add_argument(
        "--seed",
        type=SEED,
        default=0,
        help="seed of the games and of the policies' sampling (default: %(default)s)",
    )
    p.add_argument("--num-envs", type=int_range(1, 65_536), default=16, help="games at once")
    add_scenario_options(p, train=False, scenario_help="the scenario (default: the run's own)")
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    p.add_argument(
        "--no-progress",
        action="store_true",
        help="no progress bar or lines on stderr (as A2CM_PROGRESS=0)",
    )
    add_render_options(p)
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


def _runs(specs: Sequence[str | None]) -> list[str]:
    """The run directories among ``specs`` (the others name policies)."""
    return [s for s in specs if s and not (is_named(s, "pursuers") or is_named(s, "evader"))]


def _scenario(args: argparse.Namespace, specs: Sequence[str | None]) -> Scenario:
    if args.set and not args.scenario:
        raise ConfigError(_set_needs_scenario(args.set, _runs(specs)))
    if args.scenario:
        return scenario_from_args(args, train=False)
    from ..analysis.policies import exported_scenario
    from ..training.runs import load_trained_run

    runs = _runs(specs)
    if runs:  # the first run (or exported team) among the policies names the game
        exported = exported_scenario(runs[0])
        return exported if exported is not None else load_trained_run(runs[0]).scenario
    raise ConfigError("named policies need --scenario (or a run directory)")


def _set_needs_scenario(items: Sequence[str], runs: Sequence[str]) -> str:
    """Why ``--set`` without ``--scenario`` is refused, with the command line that works."""
    from ..training.runs import run_identity

    name = "NAME"
    if runs:
        with contextlib.suppress(ConfigError):  # no run there: --scenario's error says so
            name = run_identity(runs[0]).scenario
    sets = " ".join(f"--set {item}" for item in items)
    return (
        f"--set needs --scenario: a trained run is evaluated in its own scenario unless"
        f" --scenario names one; write --scenario {name} {sets}"
    )


def _main(argv: Sequence[str]) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    check_render(args, parser)
    if args.cross_play:
        return _cross_play(args)
    from ..analysis.evaluation import play, reference_policy, reference_report
    from ..analysis.policies import matchup
    from ..base.progress import Progress

    show = not args.no_progress
    pursuers = _pursuers_spec(args)
    scenario = _scenario(args, [pursuers, args.evader])
    game = matchup(scenario, pursuers, args.evader, greedy=args.greedy, progress=show)
    with Progress("evaluate", args.episodes, "ep", enabled=show) as bar:
        result = play(
            game.scenario, game.pursuers, args.episodes, args.num_envs, args.seed, game.evader, bar
        )
    report: dict[str, Any] = {
        "scenario": scenario.name,
        "policy": game.label,
        **result.report(args.seed),
    }
    reference = args.reference or reference_policy(scenario)
    if game.evader is None and pursuers != reference:
        report["reference"] = reference_report(
            game.scenario, reference, args.episodes, args.num_envs, args.seed, show
        )
    if args.json:
        if args.render:
            report["pictures"] = list(draw_episodes(args, game, pursuers))
        print(json.dumps(report, indent=2))
        return 0
    print(format_report(report, f"{scenario.name}: {game.label}, seed {args.seed}"), flush=True)
    for picture in draw_episodes(args, game, pursuers) if args.render else ():
        ending = f": {picture['ending']}" if picture["ending"] else ""
        print(f"wrote {picture['file']} (episode {picture['episode']}, {picture['length']}"
              f" steps{ending})", flush=True)  # fmt: skip
    return 0


def _cross_play(args: argparse.Namespace) -> int:
    from ..analysis.evaluation import play
    from ..analysis.policies import matchup
    from ..base.progress import Progress

    show = not args.no_progress
    pursuers = [s.strip() for s in _pursuers_spec(args).split(",") if s.strip()]
    evaders = [s.strip() for s in (args.evader or "").split(",") if s.strip()] or [None]
    scenario = _scenario(args, [*pursuers, *evaders])
    games: list[tuple[str, str, Matchup]] = [
        (p, e or scenario.evader, matchup(scenario, p, e, greedy=args.greedy, progress=show))
        for p in pursuers
        for e in evaders
    ]
    rows = []
    total = len(games) * args.episodes
    with Progress("cross-play", total, "ep", enabled=show) as bar:
        for i, (p, e, game) in enumerate(games, 1):
            status = f"{i}/{len(games)} {Path(p).name} vs {Path(e).name}"
            if len(status) > STATUS_WIDTH:
                status = f"pairing {i}/{len(games)}"
            result = play(
                game.scenario,
                game.pursuers,
                args.episodes,
                args.num_envs,
                args.seed,
                game.evader,
                progress=bar,
                status=status,
            )
            rows.append({"pursuers": p, "evader": e, **result.report(args.seed)})
    print(json.dumps(rows, indent=2) if args.json else format_cross_play(rows))
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python -m a2cm_phys.evaluate``; returns the exit status."""
    return run_cli(_main, argv)


if __name__ == "__main__":
    sys.exit(main())
