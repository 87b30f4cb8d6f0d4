"""Policy tables over joint states: the one format in which the exact solvers take and
return stochastic, stationary policies of either team.

**The format.** A *policy table* of a team of ``K`` agents (``K = pursuers`` for the
pursuers, ``K = 1`` for the evader) is a float64 array of shape ``(S, K, M)``::

    table[s, k, m] = P(agent k of the team takes action m | joint state s)

- ``s`` runs over all ``S = C ** (N + 1)`` joint states (``C = size²`` cells) in the
  index layout of :class:`~a2cm_phys.solve.model.GridModel`:
  ``((p_0 · C + p_1) · C + …) · C + e`` with cell ``x + size · y`` — pursuers in order,
  then the evader (:func:`state_cells` decodes it).
- ``M = scenario.actions`` (``0`` up, ``1`` down, ``2`` left, ``3`` right, ``4`` stay when
  ``actions = 5``). An *evader* table may instead have 5 columns whatever ``actions`` is,
  column 4 being stay: that is how the scripted ``static`` evader is written.
- Agents of a team act independently given the state (a product distribution): the
  joint law of the pursuers is ``Π_k table[s, k, a_k]``.
- Rows of states in which a pursuer stands on the evader are never read (such a state has
  already ended the episode), nor those of states with an agent on a cell an obstacle
  blocks (they never occur); the builders below fill them like any other row.

A trained model's actors give a table directly: :func:`model_table` evaluates any
object with the method ``action_probs_np(obs) -> (B, K, A)`` (pursuers' actor–critic, a
learned evader's actor with ``K = 1``) on the observations of every joint state
(:func:`joint_observations`, SPEC §5). :class:`TablePolicy` plays a table back through the
same method, so a best response can stand wherever a learned model is expected.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from ..config import SCRIPTED_EVADERS, Scenario
from ..envs.core import default_start
from ..envs.evaders.scripted import STAY
from ..envs.grid import GridRules
from ..envs.starts import grid_start_chunks

ROW_TOLERANCE = 1e-6
"""How far from 1 a row of a table may sum (models' softmax outputs are float32-exact)."""


class ProbabilityModel(Protocol):
    """Anything with the actors' method: action probabilities ``(B, K, A)`` of observations."""

    def action_probs_np(self, obs: np.ndarray) -> np.ndarray: ...


def n_states(scenario: Scenario) -> int:
    """Number of joint states ``size ** (2 (N + 1))``."""
    return scenario.size ** (2 * (scenario.pursuers + 1))


def state_shape(scenario: Scenario) -> tuple[int, ...]:
    """``(C,) * (N + 1)``: the shape an array over joint states reshapes to."""
    return (scenario.size**2,) * (scenario.pursuers + 1)


def state_cells(scenario: Scenario, index: np.ndarray | None = None) -> np.ndarray:
    """Cells ``(N + 1, K)`` (pursuers, then the evader) of state indices (default: all)."""
    index = np.arange(n_states(scenario)) if index is None else np.asarray(index)
    return np.stack(np.unravel_index(index, state_shape(scenario))).astype(np.int64)


def state_of_cells(scenario: Scenario, cells: np.ndarray) -> np.ndarray:
    """State indices of cells ``(N + 1, …)`` (pursuers, then the evader): the inverse of
    :func:`state_cells`."""
    return np.ravel_multi_index(tuple(np.asarray(cells)), state_shape(scenario))


def valid_states(scenario: Scenario) -> np.ndarray:
    """``(S,)`` mask of states that can occur: no pursuer on the evader's cell, and no agent
    on a cell an obstacle blocks (no start puts one there, no move enters one)."""
    cells = state_cells(scenario)
    valid = ~np.any(cells[:-1] == cells[-1], axis=0)
    if scenario.obstacles:
        valid &= ~np.any(scenario.blocked_cells()[cells], axis=0)
    return valid


def state_index(scenario: Scenario, positions: np.ndarray) -> np.ndarray:
    """State indices of integer positions ``(..., N + 1, 2)`` ``(x, y)``, pursuers first."""
    xy = np.asarray(positions, dtype=np.int64)
    n, size = scenario.pursuers, scenario.size
    if xy.shape[-2:] != (n + 1, 2):
        raise ValueError(f"positions must have shape (..., {n + 1}, 2), got {xy.shape}")
    if np.any((xy < 0) | (xy >= size)):
        raise ValueError(f"positions off the {size}x{size} arena")
    cells = xy[..., 0] + size * xy[..., 1]
    return state_of_cells(scenario, np.moveaxis(cells, -1, 0))


def start_state(scenario: Scenario) -> int:
    """Index of the scenario's default (fixed) start (SPEC §1)."""
    return int(state_index(scenario, default_start(scenario.size, scenario.pursuers)))


def start_law(scenario: Scenario, ordered: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """The scenario's start distribution over joint states: state indices and their
    probabilities (one state for the fixed start; uniform over every valid start for
    ``start = "random"``, :func:`~a2cm_phys.envs.starts.grid_start_chunks`, whose
    ``ordered`` it passes on)."""
    idx = np.concatenate(
        [state_index(scenario, chunk) for chunk in grid_start_chunks(scenario, ordered)]
    )
    return idx, np.full(len(idx), 1.0 / len(idx))


def joint_observations(scenario: Scenario, index: np.ndarray | None = None) -> np.ndarray:
    """Observations ``(K, 2 (N + 1))`` float32 of states (default: all), as ``GridCore``
    gives them: every ``(x, y)``, pursuers then the evader, divided by ``size − 1``."""
    cell_obs = GridRules(scenario).cell_obs
    return cell_obs[state_cells(scenario, index).T].reshape(-1, 2 * (scenario.pursuers + 1))


def state_of_observations(scenario: Scenario, obs: np.ndarray) -> np.ndarray:
    """State indices ``(B,)`` of grid observations ``(B, 2 (N + 1))``."""
    obs = np.asarray(obs, dtype=np.float64)
    n, size = scenario.pursuers, scenario.size
    xy = np.rint(obs.reshape(len(obs), n + 1, 2) * (size - 1)).astype(np.int64)
    return state_index(scenario, xy)


# --------------------------------------------------------------------------- builders


def uniform_table(scenario: Scenario, agents: int) -> np.ndarray:
    """Every agent uniformly random over the scenario's actions: ``(S, agents, A)``."""
    a = scenario.actions
    return np.full((n_states(scenario), agents, a), 1.0 / a)


def joint_actions(scenario: Scenario, joint: np.ndarray) -> np.ndarray:
    """Per-pursuer actions ``(K, N)`` int64 of joint action indices ``(K,)``
    ``(a_0 · A + a_1) · A + …``."""
    shape = (scenario.actions,) * scenario.pursuers
    return np.stack(np.unravel_index(np.asarray(joint), shape), axis=-1).astype(np.int64)


def joint_policy_table(scenario: Scenario, joint: np.ndarray) -> np.ndarray:
    """The pursuers' table ``(S, N, A)`` of a deterministic joint policy.

    ``joint[s]`` is a joint action index ``(a_0 · A + a_1) · A + …`` (the oracle's
    ``policy`` array).
    """
    n, a = scenario.pursuers, scenario.actions
    actions = joint_actions(scenario, joint)  # (S, N)
    table = np.zeros((len(actions), n, a))
    np.put_along_axis(table, actions[..., None], 1.0, axis=-1)
    return table


def model_table(
    scenario: Scenario, model: ProbabilityModel, agents: int, batch: int = 1 << 16
) -> np.ndarray:
    """The table ``(S, agents, A)`` of a model's ``action_probs_np`` on every joint state."""
    s, a = n_states(scenario), scenario.actions
    out = np.empty((s, agents, a))
    for lo in range(0, s, batch):
        index = np.arange(lo, min(s, lo + batch))
        probs = np.asarray(model.action_probs_np(joint_observations(scenario, index)))
        if probs.shape != (len(index), agents, a):
            raise ValueError(
                f"the model gives action probabilities of shape {probs.shape[1:]} per state, "
                f"expected {(agents, a)} for {scenario.size}x{scenario.size}, "
                f"{scenario.pursuers} pursuer(s), {a} actions"
            )
        out[lo : lo + len(index)] = probs
    return out


def flee_law(scenario: Scenario) -> np.ndarray:
    """``(S, A)`` probabilities of the fleeing evader's moves ``0 … A-1`` (SPEC §1).

    The moves maximising the Manhattan distance from the evader's cell after the move to
    the nearest pursuer's cell at the start of the step, each equally likely. Two moves
    that both bump into a wall are two moves, as in the core.
    """
    rules, a = GridRules(scenario), scenario.actions
    xy = rules.cell_xy
    move = rules.move.reshape(-1, 5)[:, :a]
    cells = state_cells(scenario)
    cand = xy[move[cells[-1]]]  # (S, A, 2)
    pursuers = xy[cells[:-1]]  # (N, S, 2)
    dist = np.abs(cand[None] - pursuers[:, :, None, :]).sum(-1).min(0)  # (S, A)
    best = dist == dist.max(axis=1, keepdims=True)
    return best / best.sum(axis=1, keepdims=True)


def scripted_evader_table(scenario: Scenario, name: str) -> np.ndarray:
    """The evader table of a scripted policy: ``random``, ``flee`` or ``static``.

    ``static`` has 5 columns (it stays, action 4, also when ``actions = 4``).
    """
    if name == "random":
        return uniform_table(scenario, 1)
    if name == "flee":
        return flee_law(scenario)[:, None, :]
    if name == "static":
        table = np.zeros((n_states(scenario), 1, 5))
        table[:, 0, STAY] = 1.0
        return table
    choices = ", ".join(SCRIPTED_EVADERS)
    raise ValueError(f"unknown scripted evader {name!r} (choose from {choices})")


# --------------------------------------------------------------------------- checks


def check_table(scenario: Scenario, table: np.ndarray, team: str) -> np.ndarray:
    """``table`` as float64, rows scaled to sum to 1, after checking it is a policy table.

    ``team`` is ``"pursuers"`` or ``"evader"``. Raises ``ValueError`` saying what is wrong:
    the shape, negative or non-finite entries, or a row (of a state that can occur) that
    does not sum to 1.
    """
    table = np.asarray(table, dtype=np.float64)
    k = scenario.pursuers if team == "pursuers" else 1
    widths = (scenario.actions,) if team == "pursuers" else (scenario.actions, 5)
    s = n_states(scenario)
    if table.ndim != 3 or table.shape[:2] != (s, k) or table.shape[2] not in widths:
        want = " or ".join(str((s, k, w)) for w in widths)
        raise ValueError(f"{team} policy table: shape {table.shape}, expected {want}")
    if not np.all(np.isfinite(table)) or np.any(table < 0):
        raise ValueError(f"{team} policy table: negative or non-finite probabilities")
    sums = table.sum(-1, keepdims=True)
    worst = float(np.max(np.abs(sums[valid_states(scenario)] - 1.0), initial=0.0))
    if worst > ROW_TOLERANCE:
        raise ValueError(f"{team} policy table: rows must sum to 1 (one is off by {worst:.1e})")
    return table / np.where(sums > 0, sums, 1.0)  # exact sums: no mass leaks into the DP


class TablePolicy:
    """A policy table played from observations, with the actors' interface.

    :meth:`action_probs_np` looks the rows of the observed states up: ``(B, K, M)``;
    :meth:`act` samples them (or takes the most probable action with ``greedy``).
    """

    def __init__(self, scenario: Scenario, table: np.ndarray) -> None:
        self.scenario = scenario
        self.table = np.asarray(table, dtype=np.float64)

    def action_probs_np(self, obs: np.ndarray) -> np.ndarray:
        """Rows ``(B, K, M)`` of the states observed in ``obs`` ``(B, 2 (N + 1))``."""
        return self.table[state_of_observations(self.scenario, obs)]

    def act(self, obs: np.ndarray, rng: np.random.Generator, greedy: bool = False) -> np.ndarray:
        """Actions ``(B, K)`` int64: sampled from the rows, or their argmax if ``greedy``."""
        probs = self.action_probs_np(obs)
        if greedy:
            return probs.argmax(-1).astype(np.int64)
        cdf = np.cumsum(probs, axis=-1)
        u = rng.random((*probs.shape[:-1], 1)) * cdf[..., -1:]
        return np.minimum((u >= cdf).sum(-1), probs.shape[-1] - 1).astype(np.int64)
