"""The grid game's symmetries and the canonical joint states they leave (issue 35).

**The group.** The square arena has 8 symmetries (the dihedral group: 4 rotations, 4
reflections). Each maps cells to cells and, being linear on displacements, moves to moves:
the four directions permute among themselves and ``stay`` stays; a move off the arena is
mapped to a move off the arena, so walls (and their bumps) are symmetric. The pursuers are
interchangeable (the rules and every reward treat them alike), so their ``N!`` permutations
are symmetries too. The group acting on joint states has ``8 · N!`` elements; the random
evader's law (uniform over the moves) and the static one (stay) are invariant under it.

**Obstacles.** Cells an obstacle blocks break the square's symmetry: only the maps that
carry the set of blocked cells onto itself (a subgroup, at least the identity) map the
game onto itself, moves into a blocked cell onto moves into a blocked cell. The group then
has ``G · N!`` elements for the ``G`` maps kept. States with an agent on a blocked cell
never occur and are left out like those with a pursuer on the evader.

**Canonical states.** A joint state's *key* under a map ``g`` is the joint-state index
(pursuers, then the evader, :mod:`.tables`' layout) of its image with the pursuers' cells
sorted ascending; its *canonical key* is the least key over the group's maps. States with one
canonical key form an orbit and share their optimal value; the canonical states are those
whose index is their own canonical key, numbered ``0 … n − 1`` in increasing order
(:class:`CanonicalIndex`). States with a pursuer on the evader's cell never occur (the
episode has ended); they are left out and all point at a *sentinel* id ``n``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..base.progress import Progress
from ..envs.core import ACTION_DELTAS

CHUNK_STATES = 1 << 20
"""Joint states canonicalised at once when the index is built (arrays of ~4 MB)."""


def geometric_maps(size: int) -> tuple[np.ndarray, np.ndarray]:
    """The square's 8 symmetries as ``(cells (8, C) int64, actions (8, 5) int64)``.

    ``cells[g, c]`` is the image of cell ``c = x + size · y``; ``actions[g, a]`` the action
    whose displacement is the image of action ``a``'s. Map ``g = 4 · swap + 2 · flip_x +
    flip_y`` swaps ``x`` and ``y`` if ``swap``, then mirrors ``x`` and ``y`` as asked; map 0
    is the identity.
    """
    top = size - 1
    y, x = np.divmod(np.arange(size * size), size)
    cells, actions = [], []
    for g in range(8):
        swap, flip_x, flip_y = g >> 2 & 1, g >> 1 & 1, g & 1
        gx, gy = (y, x) if swap else (x, y)
        gx, gy = (top - gx if flip_x else gx), (top - gy if flip_y else gy)
        cells.append(gx + size * gy)
        d = ACTION_DELTAS[:, ::-1] if swap else ACTION_DELTAS
        d = d * np.array([-1 if flip_x else 1, -1 if flip_y else 1])
        match = np.all(d[:, None, :] == ACTION_DELTAS[None, :, :], axis=-1)
        actions.append(match.argmax(axis=1))
    return np.array(cells, dtype=np.int64), np.array(actions, dtype=np.int64)


def sort_network(rows: list[np.ndarray]) -> list[np.ndarray]:
    """The arrays ``rows`` sorted elementwise (``out[0] <= out[1] <= …``), by compare-swaps."""
    rows = list(rows)
    for i in range(len(rows) - 1):
        for j in range(len(rows) - 1 - i):
            a, b = rows[j], rows[j + 1]
            rows[j], rows[j + 1] = np.minimum(a, b), np.maximum(a, b)
    return rows


class Symmetry:
    """The symmetry group of the ``size × size`` game with ``pursuers`` pursuers and the
    cells ``blocked`` (``(size²,)`` bool, or ``None``: no obstacles) an obstacle blocks.

    ``cell_maps`` and ``action_maps`` are those of :func:`geometric_maps` that carry the
    blocked cells onto themselves (all 8 without obstacles), in its order; map 0 is the
    identity. ``action_inverse[g]`` undoes ``action_maps[g]``. Cells arrays are agent-major
    ``(N + 1, K)`` (pursuers, then the evader), as in :mod:`.tables`.
    """

    def __init__(self, size: int, pursuers: int, blocked: np.ndarray | None = None) -> None:
        self.size, self.n = size, pursuers
        self.n_cells = size * size
        self.n_states = self.n_cells ** (pursuers + 1)
        cell_maps, action_maps = geometric_maps(size)
        self.blocked = np.zeros(self.n_cells, dtype=bool) if blocked is None else blocked
        keep = np.all(self.blocked[cell_maps] == self.blocked, axis=1)
        self.cell_maps, self.action_maps = cell_maps[keep], action_maps[keep]
        self.action_inverse = np.argsort(self.action_maps, axis=1)

    @property
    def maps(self) -> int:
        """Number of geometric maps in the group (8 without obstacles)."""
        return len(self.cell_maps)

    @property
    def order(self) -> int:
        """Number of elements of the group: ``G · N!`` for the :attr:`maps` ``G``."""
        return self.maps * int(np.prod(np.arange(1, self.n + 1)))

    def encode(self, cells: list[np.ndarray] | np.ndarray, dtype: type = np.int64) -> np.ndarray:
        """Joint-state indices ``((p_0 · C + p_1) · C + …) · C + e`` of cell rows."""
        out = np.asarray(cells[0], dtype=dtype)
        for row in cells[1:]:
            out = out * self.n_cells + row
        return out

    def decode(self, index: np.ndarray) -> np.ndarray:
        """Cells ``(N + 1, K)`` int64 of joint-state indices ``(K,)``."""
        shape = (self.n_cells,) * (self.n + 1)
        return np.stack(np.unravel_index(np.asarray(index), shape)).astype(np.int64)

    def key(self, cells: np.ndarray, g: int, dtype: type = np.int64) -> np.ndarray:
        """Key of states ``cells`` under map ``g``: the index of their image, pursuers sorted."""
        m = self.cell_maps[g].astype(dtype)
        rows = sort_network([m[c] for c in cells[: self.n]])
        return self.encode([*rows, m[cells[self.n]]], dtype)

    def canonical_key(self, cells: np.ndarray, dtype: type = np.int64) -> np.ndarray:
        """The least :meth:`key` over the maps: the same for every state of an orbit."""
        best = self.key(cells, 0, dtype)
        for g in range(1, self.maps):
            np.minimum(best, self.key(cells, g, dtype), out=best)
        return best

    def frames(self, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """How states ``cells (N + 1, K)`` map onto their canonical state: ``(g, rank)``.

        ``g (K,)`` is a map whose key is canonical and ``rank (N, K)`` the place of each
        pursuer among the image's sorted pursuers (ties broken by pursuer order).
        """
        cells = np.asarray(cells, dtype=np.int64)
        keys = np.stack([self.key(cells, g) for g in range(self.maps)])
        g = keys.argmin(axis=0)
        images = self.cell_maps[g[None, :], cells[: self.n]]
        rank = np.argsort(np.argsort(images, axis=0, kind="stable"), axis=0, kind="stable")
        return g, rank

    def own_actions(self, cells: np.ndarray, canonical: np.ndarray) -> np.ndarray:
        """Per-pursuer actions ``(K, N)`` in the states' own frame, from the actions
        ``canonical (K, N)`` of their canonical states (sorted pursuers, canonical frame)."""
        g, rank = self.frames(cells)
        picked = np.take_along_axis(np.asarray(canonical), rank.T, axis=1)
        return self.action_inverse[g[:, None], picked]

    def index(self, progress: bool = False) -> CanonicalIndex:
        """The canonical states and every joint state's canonical id (:class:`CanonicalIndex`)."""
        return build_index(self, progress)


@dataclass
class CanonicalIndex:
    """The canonical states of a :class:`Symmetry` and the map onto them.

    ``keys (n,)`` are the canonical states' joint-state indices in increasing order,
    ``cells (N + 1, n)`` int32 their cells (pursuers sorted), ``ids (S,)`` int32 every joint
    state's canonical id (``n``, the sentinel, where a pursuer stands on the evader or an
    agent on a blocked cell).
    """

    symmetry: Symmetry
    keys: np.ndarray
    cells: np.ndarray
    ids: np.ndarray

    @property
    def n(self) -> int:
        """Number of canonical states (also the sentinel id)."""
        return len(self.keys)


def build_index(sym: Symmetry, progress: bool = False) -> CanonicalIndex:
    """Canonicalise every joint state of ``sym`` (chunks of :data:`CHUNK_STATES`).

    Two passes over ``ids``: the first stores each valid state's canonical key (``-1`` for
    the others) and collects the canonical states (key equal to the index); the second
    turns keys into ranks among them.
    """
    s, n = sym.n_states, sym.n
    if s >= 2**31:
        raise ValueError(f"{s:,} joint states do not fit the int32 canonical map")
    ids = np.empty(s, dtype=np.int32)
    found = []
    bounds = [(lo, min(s, lo + CHUNK_STATES)) for lo in range(0, s, CHUNK_STATES)]
    with Progress("symmetry", total=2 * len(bounds), unit="chunks", enabled=progress) as bar:
        for lo, hi in bounds:
            index = np.arange(lo, hi, dtype=np.int32)
            cells = np.empty((n + 1, hi - lo), dtype=np.int32)
            rest = index
            for i in range(n, -1, -1):
                rest, cells[i] = np.divmod(rest, sym.n_cells)
            key = sym.canonical_key(cells, np.int32)
            valid = np.all(cells[:n] != cells[n], axis=0)
            if sym.blocked.any():
                valid &= ~np.any(sym.blocked[cells], axis=0)
            found.append(index[valid & (key == index)])
            key[~valid] = -1
            ids[lo:hi] = key
            bar.update()
        keys = np.concatenate(found)
        for lo, hi in bounds:
            key = ids[lo:hi]
            rank = np.searchsorted(keys, key).astype(np.int32)
            rank[key < 0] = len(keys)
            ids[lo:hi] = rank
            bar.update()
    cells = sym.decode(keys).astype(np.int32)
    return CanonicalIndex(sym, keys, cells, ids)
