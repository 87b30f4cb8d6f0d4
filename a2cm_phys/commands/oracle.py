"""``python -m a2cm_phys.oracle``: the exact optimum of a grid scenario, cached, and as a policy.

The grid game is solved by value iteration over the joint state (every pursuer's cell and
the evader's) with :mod:`a2cm_phys.solve`. The objective is the scenario's own expected
total raw reward until the episode terminates, undiscounted: with the step penalty alone
(experiment 1) that is minus the expected number of steps to capture; with collision
penalties it includes them, and in ``terminate`` mode a collision ends the episode.
Truncation at ``max_steps`` is ignored by the optimisation (its probability is reported).

The solution is cached as ``<cache dir>/<key>.npz``, the key a hash of the fields that
define the game (:mod:`a2cm_phys.solve.cache`); the cache directory defaults to
``$XDG_CACHE_HOME/a2cm_phys/oracle`` (``~/.cache/a2cm_phys/oracle``).
:class:`a2cm_phys.analysis.policies.OraclePolicy` plays the optimal policy from observations, so
evaluations and replays can put learned policies next to it.

``--best-response evader|pursuers`` solves one team's exact best response to the other's
fixed policy (:mod:`a2cm_phys.solve.best_response`); ``--game-value`` brackets the game's
value when both teams play their best (:mod:`a2cm_phys.solve.nash`). ``--pursuers`` and
``--evader`` take the names ``evaluate`` takes (:mod:`a2cm_phys.analysis.names`), meaning the
same policies; ``--evader best-response``, the one name without a table, says why.

The solvers report their iterations and residual on stderr while they run (a bar on a
terminal, a line every 30 s elsewhere; ``--no-progress`` or ``A2CM_PROGRESS=0`` silences
them); the results go to stdout. The solvers are imported once the options are parsed, so
``--help`` is quick.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING

from ..analysis.names import EVADER_TABLES, PURSUER_TABLES
from ..config import SCRIPTED_EVADERS, Scenario, build, merge_overrides, to_dict
from .options import (
    Parser,
    UsageError,
    add_scenario_options,
    positive_float,
    run_cli,
    scenario_from_args,
    split_assignments,
    writable_dir,
)
from .oracle_report import optimum_report

if TYPE_CHECKING:  # the solvers (numpy arrays, torch) are imported after parsing
    from ..solve.best_response import BestResponse, Outcome
    from ..solve.minimax import MinimaxBounds
    from ..solve.nash import GameValue

TOLERANCE = 1e-9
"""``--tol``'s default: :data:`a2cm_phys.solve.best_response.TOLERANCE` (a test keeps them
equal; the solvers are not imported for ``--help``)."""

# --------------------------------------------------------------------------- command


def _outcome_lines(out: Outcome, start: int, horizon: int, terminate: bool) -> list[str]:
    lines = [f"    P(capture within {horizon} steps) {out.p_capture[start]:.6f}"]
    if terminate:
        lines[0] += f", P(ended by a collision) {out.p_end[start] - out.p_capture[start]:.6f}"
    lines[0] += f", P(truncated) {1.0 - out.p_end[start]:.6f}"
    stop = "all steps" if out.iterations == horizon else "stopped early"
    lines.append(
        f"    backward induction: {out.iterations} of {horizon} steps ({stop}, error bound "
        f"{out.error_bound:.1e}), {out.kind} table, {out.seconds:.1f} s"
    )
    return lines


def _scenario_line(sc: Scenario) -> str:
    return (
        f"oracle: {sc.name}: {sc.size}x{sc.size} grid, {sc.pursuers} pursuer(s), "
        f"{sc.actions} actions, collisions {sc.collisions.mode}, max_steps {sc.max_steps}"
    )


def _evader_report(sc: Scenario, label: str, br: BestResponse, random: Outcome) -> str:
    """The evader's best response against a pursuer policy, and the random evader's value."""
    start, terminate = br.start, sc.collisions.mode == "terminate"
    worst, typical = br.value_from_start, float(random.values[start])
    what = "episode length (capture or collision)" if terminate else "capture time"
    lines = [
        _scenario_line(sc),
        f"  pursuers: {label}",
        "  evader's best response (maximises the expected episode length, truncated at "
        f"{sc.max_steps}):",
        f"    worst-case {what}: {worst:.6f}",
        *_outcome_lines(br.outcome, start, sc.max_steps, terminate),
        "  random evader for comparison:",
        f"    expected {what}: {typical:.6f}",
        *_outcome_lines(random, start, sc.max_steps, terminate),
    ]
    if typical > 0:
        lines.append(f"  exploitability: the best response lasts {worst / typical:.2f}x as long")
    return "\n".join(lines)


def _pursuers_report(sc: Scenario, label: str, br: BestResponse) -> str:
    """The pursuers' best response (the oracle against the evader) from the start."""
    meta, terminate = br.meta, sc.collisions.mode == "terminate"
    lines = [
        _scenario_line(sc),
        f"  evader: {label}",
        "  pursuers' best response (the oracle solved against this evader):",
        f"    expected capture time: {br.value_from_start:.6f}",
        *_outcome_lines(br.outcome, br.start, sc.max_steps, terminate),
    ]
    if "sweeps" in meta:
        lines.append(f"    oracle: {meta['sweeps']} sweeps, {meta['dp_seconds']:.1f} s")
    if meta.get("losing_states"):
        lines.append(f"    {meta['losing_states']:,} states from which capture cannot be forced")
    return "\n".join(lines)


def _bounds_report(bounds: MinimaxBounds) -> str:
    """The bounds on the game's minimax value that come with the minimax team."""
    k_lo, k_hi = bounds.iterations
    return "\n".join(
        [
            "  the game's minimax capture time (both teams at their best, mixed strategies),"
            " from the start:",
            f"    at least {bounds.lower_from_start:g} (the evader moving first,"
            f" {k_lo} steps of recursion): no team's worst case is lower",
            f"    at most {bounds.upper_from_start:g} (the pursuers moving first,"
            f" {k_hi} steps): the minimax team's worst case; {bounds.seconds:.1f} s",
        ]
    )


def _value_report(sc: Scenario, value: GameValue, bounds: MinimaxBounds) -> str:
    """The game's value bracketed (:mod:`.solve.nash`), beside the perfect-information
    games' bounds."""
    return "\n".join(
        [
            _scenario_line(sc),
            "  the game's value (both teams at their best, mixed strategies), from the start:",
            f"    at least {value.lower:.6f}: the equilibrium evader's worst case (the team's"
            " best response to it)",
            f"    at most {value.upper:.6f}: the equilibrium team's worst case (the evader's"
            " best response; the team draws its moves jointly)",
            f"    from {value.sweeps} Shapley sweeps, each state's game by regret matching+;"
            f" {value.seconds:.0f} s{' (cached)' if value.cached else ''}",
            f"  the perfect-information games: at least {bounds.lower_from_start:g} (the"
            f" evader moving first), at most {bounds.upper_from_start:g} (the pursuers"
            " moving first)",
        ]
    )


def _game_value(args: argparse.Namespace) -> int:
    """``--game-value``: solve, print, exit status."""
    from ..solve.cache import load_or_solve_value
    from ..solve.minimax import minimax_bounds

    args.scenario = args.scenario or "grid"
    sc = scenario_from_args(args, train=False)
    shown = not args.no_progress
    with _solver_errors():
        value = load_or_solve_value(sc, args.cache_dir, not args.no_cache, progress=shown)
        print(_value_report(sc, value, minimax_bounds(sc, progress=shown)))
    return 0


def _best_response_scenario(args: argparse.Namespace) -> Scenario:
    """``--scenario`` with ``--set``; without ``--scenario``, a run directory's own."""
    from ..analysis.sources import run_scenario

    names = PURSUER_TABLES if args.best_response == "evader" else EVADER_TABLES
    spec = args.pursuers if args.best_response == "evader" else args.evader
    if args.scenario is None and spec is not None and spec not in names:
        trained = run_scenario(spec, names)
        overrides, train_set = split_assignments(args.set)
        if train_set:
            raise UsageError(f"--set train.{next(iter(train_set))}: this command does not train")
        return build(Scenario, merge_overrides(to_dict(trained), overrides), "--set")
    args.scenario = args.scenario or "grid"
    return scenario_from_args(args, train=False)


def _best_response(args: argparse.Namespace) -> int:
    """``--best-response evader|pursuers``: solve, print, exit status."""
    from ..analysis.sources import evader_source, pursuer_source
    from ..solve.best_response import (
        evader_best_response,
        evaluate_tables,
        pursuers_best_response,
    )
    from ..solve.minimax import MinimaxBounds
    from ..solve.pursuer_step import check_size
    from ..solve.tables import uniform_table

    shown = not args.no_progress
    cache = {"cache_dir": args.cache_dir, "use_cache": not args.no_cache, "progress": shown}
    with _solver_errors():
        sc = _best_response_scenario(args)
        if args.best_response == "evader":
            spec = args.pursuers or "oracle"
            check_size(sc, _TABLE_KINDS.get(spec, "general"))
            source = pursuer_source(sc, spec, **cache)
            br = evader_best_response(sc, source.table, args.tol, progress=shown)
            random_evader = uniform_table(sc, 1)
            random = evaluate_tables(sc, source.table, random_evader, args.tol, progress=shown)
            print(_evader_report(sc, source.label, br, random))
            if isinstance(source.solution, MinimaxBounds):
                print(_bounds_report(source.solution))
            return 0
        spec = args.evader or sc.evader
        if spec not in SCRIPTED_EVADERS and spec == sc.evader:
            raise UsageError(f"the scenario's evader is {spec!r}: name one with --evader")
        check_size(sc, "deterministic")
        source = evader_source(sc, spec, **cache)
        solved = None if source.solution is None else source.solution.policy
        br = pursuers_best_response(sc, source.table, args.tol, joint_policy=solved, progress=shown)
        print(_pursuers_report(sc, source.label, br))
        return 0


_TABLE_KINDS = {
    "random": "product",
    "pursuit": "deterministic",
    "oracle": "deterministic",
    "minimax": "deterministic",
}
"""The kind of each named pursuer table (:func:`~a2cm_phys.solve.pursuer_step.check_size`:
how large an arena its best response can take); a run's actors are "general"."""


@contextmanager
def _solver_errors() -> Iterator[None]:
    """Turns the solvers' and the sources' refusals into a one-line :class:`UsageError`."""
    try:
        yield
    except Exception as err:
        from ..analysis.sources import SourceError
        from ..solve import TooLargeError, UnsupportedError

        if isinstance(err, (TooLargeError, UnsupportedError, SourceError)):
            raise UsageError(str(err)) from None
        raise


def main(argv: Sequence[str] | None = None) -> int:
    """Solve (or load) a grid scenario's optimum and print its statistics; exit code."""
    return run_cli(_main, argv)


def build_parser() -> argparse.ArgumentParser:
    """The ``python -m a2cm_phys.oracle`` argument parser."""
    parser = Parser(
        prog="python -m a2cm_phys.oracle",
        description="Exact optimal pursuit policy of a grid scenario (value iteration).",
    )
    add_scenario_options(
        parser,
        default=None,
        train=False,
        scenario_help="scenario name (see a2cm_phys/scenarios/) or path to a TOML file"
        " (default: grid; with --best-response and a run directory, the run's scenario)",
    )
    parser.add_argument(
        "--cache-dir",
        type=Path,
        default=None,
        metavar="DIR",
        help="where solutions are cached (default: $XDG_CACHE_HOME/a2cm_phys/oracle,"
        " ~/.cache/a2cm_phys/oracle without XDG_CACHE_HOME)",
    )
    parser.add_argument(
        "--no-cache", action="store_true", help="neither read nor write the cache: solve again"
    )
    parser.add_argument(
        "--best-response",
        choices=["evader", "pursuers"],
        help="solve that team's exact best response to the other team's fixed policy"
        " (default: neither; the oracle's optimum against the scenario's evader)",
    )
    parser.add_argument(
        "--game-value",
        action="store_true",
        help="bracket the game's value with mixed strategies (both teams at their best) by"
        " the exact worst cases of an equilibrium evader and team; minutes on 5x5",
    )
    parser.add_argument(
        "--pursuers",
        metavar="|".join((*PURSUER_TABLES, "RUN_DIR")),
        help="with --best-response evader: the pursuers' policy, as evaluate's --pursuers"
        " (default: oracle, the team optimal against the scenario's scripted evader, the"
        " random one where it is learned; minimax: the team optimal when the evader sees"
        " its move, with bounds on the game's value)",
    )
    parser.add_argument(
        "--evader",
        metavar="|".join((*EVADER_TABLES, "RUN_DIR")),
        help="with --best-response pursuers: the evader's policy, as evaluate's --evader"
        " (default: the scenario's; equilibrium: the game's, see --game-value)",
    )
    parser.add_argument(
        "--tol",
        type=positive_float,
        default=TOLERANCE,
        help="error bound that stops the backward induction early, in steps",
    )
    parser.add_argument(
        "--no-progress",
        action="store_true",
        help="no progress bar or lines on stderr while the solvers run",
    )
    return parser


def _main(argv: Sequence[str]) -> int:
    args = build_parser().parse_args(argv)
    if args.cache_dir is not None and not args.no_cache:
        writable_dir(args.cache_dir, "--cache-dir")
    if args.pursuers is not None and args.best_response != "evader":
        raise UsageError("--pursuers goes with --best-response evader")
    if args.evader is not None and args.best_response != "pursuers":
        raise UsageError("--evader goes with --best-response pursuers")
    if args.game_value and args.best_response:
        raise UsageError("--game-value and --best-response are separate questions: give one")
    if args.game_value:
        return _game_value(args)
    if args.best_response:
        return _best_response(args)
    from ..solve.cache import load_or_solve_optimum

    args.scenario = args.scenario or "grid"
    scenario = scenario_from_args(args, train=False)
    with _solver_errors():
        sol = load_or_solve_optimum(
            scenario, args.cache_dir, not args.no_cache, progress=not args.no_progress
        )
    print(optimum_report(sol))
    return 0


if __name__ == "__main__":
    sys.exit(main())
