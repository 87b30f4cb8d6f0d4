"""Policy tables by name: what ``python -m a2cm_phys.oracle --pursuers`` and ``--evader``
accept, as a library: the names ``evaluate`` accepts (:mod:`.names`), meaning the same
policies, wherever a policy has an exact table.

Pursuers: ``random`` (uniform), ``pursuit`` (each pursuer straight at the evader,
:mod:`.baselines`), ``oracle`` (the exact optimum of the scenario against its scripted
evader, or against the random evader where the scenario's is learned, as ``evaluate`` plays
it; from the cache or solved), ``minimax`` (the deterministic team optimal when the evader
sees its move, :mod:`a2cm_phys.solve.minimax`) or a run directory (its trained actors).
Evader: ``random``, ``flee``, ``static``, ``equilibrium`` (the game's equilibrium evader,
:mod:`a2cm_phys.solve.nash`) or a run directory with a learned evader (``best-response``
has no table of its own: :func:`check_tabled` says why). Each gives a :class:`Source`: the
policy table (:mod:`a2cm_phys.solve.tables`) and a label to print. ``progress=True``
reports the solvers' progress on stderr.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..config import Scenario
from ..solve.cache import load_or_solve, load_or_solve_value
from ..solve.tables import (
    SCRIPTED_EVADERS,
    joint_policy_table,
    model_table,
    scripted_evader_table,
    state_cells,
    uniform_table,
)
from ..training.runs import load_trained, load_trained_evader
from .baselines import pursuit_actions
from .names import PURSUER_TABLES, Side, no_table, oracle_evader


class SourceError(ValueError):
    """A policy named on the command line cannot be had (one line, for the user)."""


@dataclass
class Source:
    """A policy table and what it is. ``solution`` is the oracle's, when the table is one
    (an :class:`~a2cm_phys.solve.cache.OracleSolution`, with its cache status and statistics),
    or the :class:`~a2cm_phys.solve.minimax.MinimaxBounds` the minimax team comes from."""

    table: np.ndarray
    label: str
    solution: Any = None


def load_pursuer_run(path: str | Path) -> tuple[Scenario, Any]:
    """The scenario and trained pursuers of a run directory (or checkpoint file), or a
    SourceError."""
    try:
        return load_trained(path)
    except (OSError, ValueError, KeyError, RuntimeError) as err:
        message = str(err)  # most already name the path
        raise SourceError(message if str(path) in message else f"{path}: {message}") from None


def load_evader_run(path: str | Path) -> tuple[Scenario, Any]:
    """The scenario and learned evader of a run; its model's ``action_probs_np`` gives
    ``(B, 1, A)``."""
    try:
        return load_trained_evader(path)
    except (OSError, ValueError, KeyError, RuntimeError) as err:
        raise SourceError(f"{path}: no learned evader in this run ({err})") from None


def check_compatible(scenario: Scenario, trained: Scenario, path: str | Path) -> None:
    """A run's model reads the scenario's observations and plays its actions."""
    got = (trained.mode, trained.size, trained.pursuers, trained.actions)
    want = (scenario.mode, scenario.size, scenario.pursuers, scenario.actions)
    if got != want:
        raise SourceError(
            f"{path} was trained on {trained.mode} {trained.size}x{trained.size}, "
            f"{trained.pursuers} pursuer(s), {trained.actions} actions; the scenario is "
            f"{scenario.mode} {scenario.size}x{scenario.size}, {scenario.pursuers} "
            f"pursuer(s), {scenario.actions} actions"
        )


def check_tabled(spec: str, side: Side) -> None:
    """A :class:`SourceError` saying why, when ``spec`` names a policy of ``side`` that has
    no exact table (:attr:`~.names.NamedPolicy.no_table`)."""
    why = no_table(spec, side)
    if why:
        raise SourceError(f"--{side} {spec}: {why}")


def pursuer_source(
    scenario: Scenario,
    spec: str,
    cache_dir: str | Path | None = None,
    use_cache: bool = True,
    progress: bool = False,
) -> Source:
    """The pursuers' table of ``random``, ``pursuit``, ``oracle``, ``minimax`` or a run
    directory.

    ``oracle`` is the team optimal against the scenario's scripted evader, or against the
    random evader where the scenario's is learned (:func:`~.names.oracle_evader`, as
    ``evaluate`` plays it). Raises :class:`SourceError`, or the solvers' TooLargeError /
    UnsupportedError.
    """
    check_tabled(spec, "pursuers")
    n = scenario.pursuers
    if spec == "random":
        return Source(uniform_table(scenario, n), "uniformly random pursuers")
    if spec == "pursuit":
        return Source(
            pursuit_table(scenario),
            "pursuit (each pursuer straight at the evader, around obstacles)",
        )
    if spec == "minimax":
        from ..solve.minimax import minimax_bounds

        bounds = minimax_bounds(scenario, progress)
        label = "the minimax team (deterministic, optimal when the evader sees its move)"
        return Source(joint_policy_table(scenario, bounds.policy), label, bounds)
    if spec == "oracle":
        against = oracle_evader(scenario)
        solved = dataclasses.replace(scenario, evader=against)
        sol = load_or_solve(solved, cache_dir, use_cache, progress)
        label = f"the oracle's policy (optimal against the {against} evader)"
        return Source(joint_policy_table(scenario, sol.policy), label, sol)
    trained, model = load_pursuer_run(spec)
    check_compatible(scenario, trained, spec)
    return Source(_model_table(scenario, model, n, spec), f"the trained actors of {spec}")


def pursuit_table(scenario: Scenario) -> np.ndarray:
    """The pursuers' table ``(S, N, A)`` of ``pursuit`` (:func:`~.baselines.pursuit_actions`
    in every joint state; one-hot rows). Grids only: a :class:`SourceError` elsewhere."""
    if scenario.mode != "grid" or scenario.continuous:
        raise SourceError("--pursuers pursuit: exact tables exist for grid moves only")
    cells = state_cells(scenario)  # (N + 1, S)
    positions = np.stack([cells % scenario.size, cells // scenario.size], axis=-1)
    actions = pursuit_actions(scenario, positions.transpose(1, 0, 2))  # (S, N)
    table = np.zeros((*actions.shape, scenario.actions))
    np.put_along_axis(table, actions[..., None], 1.0, axis=-1)
    return table


def evader_source(
    scenario: Scenario,
    spec: str,
    cache_dir: str | Path | None = None,
    use_cache: bool = True,
    progress: bool = False,
) -> Source:
    """The evader's table of ``random``, ``flee``, ``static``, ``equilibrium`` (the game's,
    :mod:`a2cm_phys.solve.nash`; minutes) or a run directory.

    For a scripted evader the oracle against it is loaded from the cache or solved too
    (:attr:`Source.solution`): that is the pursuers' best response.
    """
    check_tabled(spec, "evader")
    if spec in SCRIPTED_EVADERS:
        scripted = dataclasses.replace(scenario, evader=spec)
        sol = load_or_solve(scripted, cache_dir, use_cache, progress)
        return Source(scripted_evader_table(scenario, spec), f"the {spec} evader", sol)
    if spec == "equilibrium":
        value = load_or_solve_value(scenario, cache_dir, use_cache, progress)
        return Source(value.evader, "the game's equilibrium evader")
    trained, model = load_evader_run(spec)
    check_compatible(scenario, trained, spec)
    return Source(_model_table(scenario, model, 1, spec), f"the learned evader of {spec}")


def _model_table(scenario: Scenario, model: Any, agents: int, spec: str) -> np.ndarray:
    try:
        return model_table(scenario, model, agents)
    except ValueError as err:
        raise SourceError(f"{spec}: {err}") from None


def run_scenario(spec: str, names: tuple[str, ...]) -> Scenario | None:
    """The scenario a run directory was trained on (``None`` for a named policy; a
    :class:`SourceError` for a name without a table)."""
    if spec in names:
        return None
    check_tabled(spec, "pursuers" if names == PURSUER_TABLES else "evader")
    if names == PURSUER_TABLES:
        return load_pursuer_run(spec)[0]
    return load_evader_run(spec)[0]


__all__ = [
    "Source",
    "SourceError",
    "check_tabled",
    "evader_source",
    "pursuer_source",
    "pursuit_table",
    "run_scenario",
]
