"""Where episodes start (the scenario's ``[start]``): the fixed start, random starts drawn
from each episode's seed, and (grid) the enumeration of every random start, over which the
oracle takes its exact expectation.

Random starts are uniform over the *valid* starts (:class:`~a2cm_phys.config.Start`): all
agents drawn at once, the whole draw rejected and redrawn until it is valid, which keeps
the law exactly uniform over the valid set. On a grid with obstacles each agent is drawn
from the free cells only (no agent starts on a blocked cell). The draws are counter-based
hashes of the episode seed (as the evader's, :mod:`.evaders.scripted`, in a stream of their
own), so an episode's start is a pure function of its seed: the same in any batch, in any
worker, and re-simulated by ``replay --verify`` from the seed the log already holds.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterator

import numpy as np

from ..config import ConfigError, Scenario
from .core import default_start
from .evaders.scripted import draws, mix64
from .obstacles import clear_of_obstacles

_STREAM = np.uint64(0x5354415254)  # "START": keeps these draws apart from the evader's
_ATTEMPTS = 10_000
"""Redraws before a game gives up (a valid start is then too rare to be found by chance)."""
_UNIT = 2.0**-53


def _uniform(drawn: np.ndarray) -> np.ndarray:
    """Floats in ``[0, 1)`` from uint64 draws (their top 53 bits)."""
    return (drawn >> np.uint64(11)).astype(np.float64) * _UNIT


def _grid_valid(xy: np.ndarray, min_distance: float) -> np.ndarray:
    """``(K,)`` whether cells ``(K, N + 1, 2)`` are a valid start: all distinct, every
    pursuer at Manhattan distance ``>= min_distance`` from the evader."""
    same = np.all(xy[:, :, None] == xy[:, None, :], axis=-1)  # (K, N + 1, N + 1)
    distinct = same.sum(axis=(1, 2)) == xy.shape[1]
    far = np.abs(xy[:, :-1] - xy[:, -1:]).sum(axis=-1) >= min_distance
    return distinct & np.all(far, axis=1)


def _physics_valid(scenario: Scenario, xy: np.ndarray) -> np.ndarray:
    """``(K,)`` whether positions ``(K, N + 1, 2)`` (metres) are a valid start: pursuers'
    (axis-aligned) boxes apart and their centres ``min_pursuer_distance`` apart, each
    pursuer at least ``min_evader_distance`` and clear of the evader's circle (its box's
    circumcircle outside it), every body clear of the obstacles."""
    ph, n = scenario.physics, scenario.pursuers
    gap = np.abs(xy[:, :n, None] - xy[:, None, :n])  # (K, N, N, 2)
    apart = np.any(gap >= ph.box_side, axis=-1) | np.eye(n, dtype=bool)
    spread = scenario.start.min_pursuer_distance
    if spread > 0:
        apart &= (np.hypot(gap[..., 0], gap[..., 1]) >= spread) | np.eye(n, dtype=bool)
    dist = np.linalg.norm(xy[:, :n] - xy[:, n:], axis=-1)
    clear = max(scenario.start.min_evader_distance, ph.evader_radius + ph.box_side / np.sqrt(2))
    valid = np.all(apart, axis=(1, 2)) & np.all(dist >= clear, axis=1)
    if scenario.obstacles:
        valid &= clear_of_obstacles(scenario, xy)
    return valid


def free_cells(scenario: Scenario) -> np.ndarray:
    """The cells ``x + size · y`` of a grid scenario that no obstacle blocks, ascending."""
    return np.flatnonzero(~scenario.blocked_cells())


def _candidates(
    scenario: Scenario, key: np.ndarray, attempt: int, free: np.ndarray | None = None
) -> np.ndarray:
    """One candidate start ``(K, N + 1, 2)`` per key at redraw ``attempt``; on a grid each
    agent's cell uniform over all cells, or over ``free`` (the free cells, with obstacles)."""
    n, size = scenario.pursuers, scenario.size
    t = np.full(len(key), attempt, dtype=np.int64)
    if scenario.mode == "grid":
        count = size * size if free is None else len(free)
        cells = ((draws(key, t, n + 1) >> np.uint64(11)) % np.uint64(count)).astype(np.int64)
        if free is not None:
            cells = free[cells]
        return np.stack([cells % size, cells // size], axis=-1)
    ph = scenario.physics
    margin = np.full(n + 1, ph.box_side / 2)  # unrotated boxes at the start
    margin[n] = ph.evader_radius
    u = _uniform(draws(key, t, 2 * (n + 1))).reshape(len(key), n + 1, 2)
    return margin[:, None] + u * (size - 2 * margin[:, None])


def random_starts(scenario: Scenario, seeds: np.ndarray) -> np.ndarray:
    """Each episode seed's random start ``(B, N + 1, 2)``: cells (int64, grid) or metres
    (float64, physics), pursuers first. Raises :class:`~a2cm_phys.config.ConfigError`
    (naming ``start.min_evader_distance``, and ``start.min_pursuer_distance`` when set) if
    a valid start is too rare to be drawn (physics
    only: :meth:`~a2cm_phys.config.Scenario.validate` refuses every grid game without one)."""
    seeds = np.atleast_1d(np.asarray(seeds, dtype=np.uint64))
    grid = scenario.mode == "grid"
    out = np.zeros((len(seeds), scenario.pursuers + 1, 2), np.int64 if grid else np.float64)
    key, todo = mix64(seeds ^ _STREAM), np.arange(len(seeds))
    free = free_cells(scenario) if grid and scenario.obstacles else None
    for attempt in range(_ATTEMPTS):
        xy = _candidates(scenario, key[todo], attempt, free)
        if grid:
            ok = _grid_valid(xy, scenario.start.min_evader_distance)
        else:
            ok = _physics_valid(scenario, xy)
        out[todo[ok]] = xy[ok]
        todo = todo[~ok]
        if not len(todo):
            return out
    start = scenario.start
    key = "start.min_evader_distance"
    lower = f"lower {key} ({start.min_evader_distance:g})"
    if start.min_pursuer_distance > 0:  # either may be what leaves no room
        key = "start.min_evader_distance, start.min_pursuer_distance"
        lower += f" or start.min_pursuer_distance ({start.min_pursuer_distance:g})"
    raise ConfigError(
        f"scenario '{scenario.name}': key '{key}': no valid random start found in"
        f" {_ATTEMPTS:,} draws; {lower}"
    )


def episode_starts(scenario: Scenario, seeds: np.ndarray) -> np.ndarray:
    """Each episode's start ``(B, N + 1, 2)`` under the scenario's ``[start]``: the fixed
    start (cells, or their centres in metres) repeated, or :func:`random_starts`."""
    seeds = np.atleast_1d(np.asarray(seeds, dtype=np.uint64))
    if scenario.start.random:
        return random_starts(scenario, seeds)
    xy = default_start(scenario.size, scenario.pursuers)
    if scenario.mode == "physics":
        xy = xy.astype(np.float64) + 0.5
    return np.repeat(xy[None], len(seeds), axis=0)


def grid_start_chunks(scenario: Scenario, ordered: bool = True) -> Iterator[np.ndarray]:
    """Every start of a grid scenario's start distribution, one chunk ``(K, N + 1, 2)`` of
    cells per evader cell; the law is uniform over all rows of all chunks.

    ``ordered``: pursuers as distinct agents (every ordered tuple of cells); ``False``: one
    row per set of cells (sorted), for solvers whose pursuers are interchangeable: as every
    ordering of a valid set is valid, uniform over sets is the same law. Cells an obstacle
    blocks hold no agent.
    """
    if not scenario.start.random:
        yield default_start(scenario.size, scenario.pursuers)[None]
        return
    size, n = scenario.size, scenario.pursuers
    cells = np.stack(np.divmod(np.arange(size * size), size)[::-1], axis=-1)  # (C, 2) x, y
    free = ~scenario.blocked_cells()
    pick = itertools.permutations if ordered else itertools.combinations
    for e in free_cells(scenario):
        evader = cells[e]
        far = np.abs(cells - evader).sum(axis=-1) >= scenario.start.min_evader_distance
        allowed = np.flatnonzero(far & free & (np.arange(size * size) != e))
        tuples = np.array(list(pick(allowed, n)), dtype=np.int64).reshape(-1, n)
        if len(tuples):
            rows = np.concatenate([cells[tuples], np.broadcast_to(evader, (len(tuples), 1, 2))], 1)
            yield rows


def count_grid_starts(scenario: Scenario) -> int:
    """How many ordered starts the grid scenario's distribution is uniform over."""
    if not scenario.start.random:
        return 1
    size = scenario.size
    cells = np.stack(np.divmod(free_cells(scenario), size)[::-1], axis=-1)
    far = np.abs(cells[:, None] - cells[None]).sum(axis=-1) >= scenario.start.min_evader_distance
    np.fill_diagonal(far, False)
    return sum(math.perm(int(k), scenario.pursuers) for k in far.sum(axis=1))
