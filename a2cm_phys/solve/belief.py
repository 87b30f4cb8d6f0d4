"""A Bayes filter over the evader's cell for a team that senses it only up close (SPEC §6b).

The belief of a game is a probability vector over the ``C = size²`` cells (cell
``x + size · y``). It starts at the evader's known start cell (SPEC §2: the centre) or, from
random starts, uniform over the cells the sampler could have put the evader on given the
pursuers' cells (the sampler is uniform over valid starts, so the evader is uniform over
its valid cells given the pursuers'), and each step of the game updates it in three parts:

1. **predict** through the scripted evader's known move law: uniform over the scenario's
   ``actions`` (``random``) or always stay (``static``); a move off the arena or into a
   cell an obstacle blocks leaves it on its cell (the rules' own move table,
   :class:`~a2cm_phys.envs.grid.GridRules`);
2. **no capture**: the episode went on, so the evader met no pursuer in the step (the
   rules' :func:`~a2cm_phys.envs.grid.meet`: the same end cell, or swapped cells), from
   the pursuers' cells at the step's start and end;
3. **sightings**: if any pursuer senses the evader, the belief is that cell; otherwise
   every cell within the sensing radius (Chebyshev) of any pursuer is ruled out, and the
   rest is renormalised.

The filter reads only what the pursuers sense: each pursuer's own position and its mask
bit and features for the evader, from the pursuers' slices of the team vector
(:func:`pursuer_sightings`), never the state prefix. It pools every pursuer's sightings
whatever ``sensing.share`` says: it is a *centralised* reference (one planner for the
team), so with ``share = false`` it knows more than any one pursuer does.

If the sightings contradict the model (an evader other than the one modelled, or placed
elsewhere than the start), the belief would vanish; it then falls back to uniform over the
free cells no pursuer senses.
"""

from __future__ import annotations

import numpy as np

from ..config import Scenario
from ..envs.core import default_start
from ..envs.evaders.scripted import STAY
from ..envs.grid import GridRules, meet
from ..envs.sensing import agent_slice, features
from .transitions import UnsupportedError

__all__ = ["EvaderFilter", "evader_moves", "pursuer_sightings"]


def evader_moves(scenario: Scenario) -> np.ndarray:
    """The scripted evader's moves, each equally likely: every one of the scenario's
    ``actions`` (``random``), or only stay (``static``). Raises
    :class:`~.transitions.UnsupportedError` for any other evader (its law is not uniform,
    or not known)."""
    if scenario.evader == "random":
        return np.arange(scenario.actions)
    if scenario.evader == "static":
        return np.array([STAY])
    raise UnsupportedError(
        f"the belief filter models the random or static evader, got evader={scenario.evader!r}"
    )


def pursuer_sightings(scenario: Scenario, obs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """What the pursuers sense, pooled, from team vectors ``(B, team_dim)`` (grid, sensing
    on): the pursuers' cells ``(B, N)`` (each from its own slice) and the evader's cell
    ``(B,)`` where any pursuer senses it, ``-1`` where none does. Reads only the pursuers'
    slices (:func:`~a2cm_phys.envs.sensing.agent_slice`), never the state prefix."""
    obs = np.asarray(obs, dtype=np.float64)
    n, k, top = scenario.pursuers, features(scenario), scenario.size - 1
    cells = np.empty((len(obs), n), dtype=np.int64)
    seen = np.full(len(obs), -1, dtype=np.int64)
    for i in range(n):
        own = obs[:, agent_slice(scenario, i)]
        xy = np.rint(own[:, :k] * top).astype(np.int64)
        cells[:, i] = xy[:, 0] + scenario.size * xy[:, 1]
        mask, where = own[:, -(k + 1)], own[:, -k:]  # the evader is every pursuer's last body
        exy = np.rint(where * top).astype(np.int64)
        seen = np.where(mask > 0.5, exy[:, 0] + scenario.size * exy[:, 1], seen)
    return cells, seen


class EvaderFilter:
    """The Bayes filter of one grid scenario with sensing (see the module docstring).

    Beliefs are float64 arrays ``(B, C)``; pursuer cells are ``(B, N)`` cell indices.
    Raises :class:`~.transitions.UnsupportedError` for an evader it does not model.
    """

    def __init__(self, scenario: Scenario) -> None:
        self.scenario = scenario
        rules = GridRules(scenario)
        self.n_cells = c = scenario.size**2
        self.moves = evader_moves(scenario)
        self.emove = rules.move.reshape(c, 5)[:, self.moves].astype(np.int64)  # (C, nb)
        self.free = ~rules.blocked_cell  # (C,): cells no obstacle blocks, the evader's
        xy = rules.cell_xy
        cheb = np.abs(xy[:, None, :] - xy[None, :, :]).max(-1)
        self.near = cheb <= float(scenario.sensing.radius)  # (C, C): within the radius
        self.manhattan = np.abs(xy[:, None, :] - xy[None, :, :]).sum(-1)  # (C, C)
        start = default_start(scenario.size, scenario.pursuers)[-1]
        self.start = int(start[0] + scenario.size * start[1])

    def initial(self, pursuers: np.ndarray) -> np.ndarray:
        """Beliefs ``(B, C)`` at an episode's start, the pursuers at cells ``(B, N)``: the
        evader's known start cell, or from random starts uniform over the free cells at
        Manhattan distance ``>= start.min_evader_distance`` from every pursuer (which no
        pursuer is on)."""
        start = self.scenario.start
        if not start.random:
            out = np.zeros((len(pursuers), self.n_cells))
            out[:, self.start] = 1.0
            return out
        far = self.manhattan[pursuers] >= max(start.min_evader_distance, 1)  # (B, N, C)
        out = (far.all(axis=1) & self.free).astype(np.float64)
        return out / out.sum(axis=1, keepdims=True)

    def predict(self, belief: np.ndarray, before: np.ndarray, after: np.ndarray) -> np.ndarray:
        """The beliefs after the evader's move, given that it met no pursuer moving from
        cells ``before`` to ``after`` ``(B, N)``; unnormalised (the mass left is the
        probability that the step did not end the episode)."""
        b, c = belief.shape
        old = np.arange(c)[None, None, :, None]  # (1, 1, C, 1)
        new = self.emove[None, None]  # (1, 1, C, nb)
        met = meet(before[:, :, None, None], after[:, :, None, None], old, new).any(axis=1)
        mass = np.where(met, 0.0, belief[:, :, None] / len(self.moves))  # (B, C, nb)
        dest = (np.arange(b)[:, None, None] * c + new[0]).ravel()
        return np.bincount(dest, weights=mass.ravel(), minlength=b * c).reshape(b, c)

    def observe(self, belief: np.ndarray, pursuers: np.ndarray, seen: np.ndarray) -> np.ndarray:
        """The beliefs given the pooled sightings: pursuers at cells ``(B, N)``, the evader
        seen at ``seen`` ``(B,)`` (``-1``: nobody senses it); normalised."""
        sensed = self.near[pursuers].any(axis=1)  # (B, C): cells some pursuer senses
        out = np.where(sensed, 0.0, belief)
        total = out.sum(axis=1, keepdims=True)
        lost = total[:, 0] <= 0.0  # the model is contradicted: uniform over unsensed cells
        if lost.any():
            out[lost] = np.where(sensed[lost] | ~self.free, 0.0, 1.0)
            out[lost & ~(out > 0).any(axis=1)] = 1.0
            total = out.sum(axis=1, keepdims=True)
        out /= total
        rows = np.flatnonzero(seen >= 0)
        out[rows] = 0.0
        out[rows, seen[rows]] = 1.0
        return out

    def update(
        self, belief: np.ndarray, before: np.ndarray, after: np.ndarray, seen: np.ndarray
    ) -> np.ndarray:
        """One step: :meth:`predict` from ``before`` to ``after``, then :meth:`observe`."""
        return self.observe(self.predict(belief, before, after), after, seen)
