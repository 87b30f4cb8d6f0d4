"""Policy tables by name: what ``python -m a2cm_phys.oracle --pursuers`` and ``--evader``
accept, as a library.

Pursuers: ``random`` (uniform), ``oracle`` (the exact optimum of the scenario against its
scripted evader, from the cache or solved), ``minimax`` (the deterministic team optimal when
the evader sees its move, :mod:`a2cm_phys.solve.minimax`) or a run directory (its trained actors).
Evader: ``random``, ``flee``, ``static``, ``equilibrium`` (the game's equilibrium evader,
:mod:`a2cm_phys.solve.nash`) or a run directory with a learned evader. Each
gives a :class:`Source`: the policy table (:mod:`a2cm_phys.solve.tables`) and a label to print.
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
    uniform_table,
)
from ..training.runs import load_trained, load_trained_evader
from .names import PURSUER_TABLES


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


def pursuer_source(
    scenario: Scenario,
    spec: str,
    cache_dir: str | Path | None = None,
    use_cache: bool = True,
) -> Source:
    """The pursuers' table of ``random``, ``oracle``, ``minimax`` or a run directory.

    ``oracle`` needs the scenario's evader to be scripted (the oracle is optimal against
    it). Raises :class:`SourceError`, or the solvers' TooLargeError / UnsupportedError.
    """
    n = scenario.pursuers
    if spec == "random":
        return Source(uniform_table(scenario, n), "uniformly random pursuers")
    if spec == "minimax":
        from ..solve.minimax import minimax_bounds

        bounds = minimax_bounds(scenario)
        label = "the minimax team (deterministic, optimal when the evader sees its move)"
        return Source(joint_policy_table(scenario, bounds.policy), label, bounds)
    if spec == "oracle":
        if scenario.evader not in SCRIPTED_EVADERS:
            raise SourceError(
                f"--pursuers oracle is optimal against a scripted evader; the scenario's is "
                f"{scenario.evader!r} (add --set evader=random)"
            )
        sol = load_or_solve(scenario, cache_dir, use_cache)
        label = f"the oracle's policy (optimal against the {scenario.evader} evader)"
        return Source(joint_policy_table(scenario, sol.policy), label, sol)
    trained, model = load_pursuer_run(spec)
    check_compatible(scenario, trained, spec)
    return Source(_model_table(scenario, model, n, spec), f"the trained actors of {spec}")


def evader_source(
    scenario: Scenario,
    spec: str,
    cache_dir: str | Path | None = None,
    use_cache: bool = True,
) -> Source:
    """The evader's table of ``random``, ``flee``, ``static``, ``equilibrium`` (the game's,
    :mod:`a2cm_phys.solve.nash`; minutes) or a run directory.

    For a scripted evader the oracle against it is loaded from the cache or solved too
    (:attr:`Source.solution`): that is the pursuers' best response.
    """
    if spec in SCRIPTED_EVADERS:
        sol = load_or_solve(dataclasses.replace(scenario, evader=spec), cache_dir, use_cache)
        return Source(scripted_evader_table(scenario, spec), f"the {spec} evader", sol)
    if spec == "equilibrium":
        value = load_or_solve_value(scenario, cache_dir, use_cache)
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
    """The scenario a run directory was trained on (``None`` for a named policy)."""
    if spec in names:
        return None
    if names == PURSUER_TABLES:
        return load_pursuer_run(spec)[0]
    return load_evader_run(spec)[0]


__all__ = [
    "Source",
    "SourceError",
    "evader_source",
    "pursuer_source",
    "run_scenario",
]
