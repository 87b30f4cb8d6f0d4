"""One Bellman backup over the canonical states of a grid game (:mod:`.symmetry`), by
chunks: every joint action and evader move of each canonical state, its successors looked
up through the canonical map, the greedy joint action kept with its successors and reward
(what the cheap policy-evaluation sweeps of :mod:`.symmetric` replay).

A successor that ends the episode (a capture; a collision in ``terminate`` mode) is the
sentinel id, whose value is 0. Joint actions are numbered ``(a_0 · A + a_1) · A + …`` over
the canonical state's pursuers in sorted order, in the canonical frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..config import Scenario
from ..envs.evaders.scripted import STAY
from ..envs.grid import GridRules
from .symmetry import CanonicalIndex
from .transitions import free_table, pair_table

CHUNK_ENTRIES = 1 << 19
"""Target number of (state, joint action) entries of one chunk of a greedy sweep."""


@dataclass
class Greedy:
    """A greedy sweep's result over canonical states ``0 … n − 1``: the backed-up
    ``value``, the greedy joint ``action``, and under it the expected immediate
    ``reward`` and the successors' ids ``succ (nb, n)`` int64, one row per evader move."""

    value: np.ndarray
    action: np.ndarray
    reward: np.ndarray
    succ: np.ndarray


class CanonicalBackup:
    """The Bellman backup of ``scenario`` over the canonical states of ``index``.

    The evader is random (uniform over the ``actions`` moves) or static (stays). Rewards:
    ``step`` every step, ``wall`` per pursuer bump, ``collision`` per colliding pursuer
    pair unless collisions are ``off``, ``capture`` on capture.
    """

    def __init__(self, scenario: Scenario, index: CanonicalIndex) -> None:
        self.scenario, self.index = scenario, index
        self.n = n = scenario.pursuers
        self.n_actions = a = scenario.actions
        self.n_cells = c = scenario.size**2
        self.n_joint = a**n
        moves = np.array([STAY]) if scenario.evader == "static" else np.arange(a)
        self.n_moves = len(moves)
        rules = GridRules(scenario)
        # Tables are action-major (A, …): a chunk's arrays are (joint action, state), so
        # numpy's broadcasting runs along the long state axis.
        move = rules.move.reshape(c, 5).astype(np.int64)
        self.pmove = np.ascontiguousarray(move[:, :a].T)  # (A, C)
        self.emove = move[:, moves]  # (C, nb)
        free = (free_table(scenario, moves) > 0.5).astype(np.uint8)  # (C, A, C, nb)
        # (nb, A, pursuer cell · C + evader cell): one gather per pursuer and move; uint8
        # because numpy's bitwise_and of uint8 is faster than its logical_and of bool
        self.free = np.ascontiguousarray(free.transpose(3, 1, 0, 2)).reshape(-1, a, c * c)
        self.walls = np.ascontiguousarray(rules.blocked.reshape(c, 5)[:, :a].T).astype(float)
        mode = scenario.collisions.mode
        self.terminate = mode == "terminate"
        self.pairs = None  # (A, A, C, C): collisions of two pursuers' (action, cell) pairs
        if n > 1 and mode != "off":
            self.pairs = np.ascontiguousarray(pair_table(scenario).transpose(1, 3, 0, 2))
        self.collision = scenario.rewards.collision if mode != "off" else 0.0
        self.chunk = max(1, CHUNK_ENTRIES // self.n_joint)

    def joint(self, per_pursuer: list[np.ndarray], op: np.ufunc) -> np.ndarray:
        """``(A^N, K)``: ``op``-combination of per-pursuer ``(A, K)`` arrays along the joint
        action axis (pursuer 0 most significant)."""
        out = per_pursuer[0]
        for x in per_pursuer[1:]:
            # into a given array: letting numpy allocate it picks a slow loop order
            new = np.empty((len(out), len(x), out.shape[-1]), dtype=np.result_type(out, x))
            op(out[:, None, :], x[None, :, :], out=new)
            out = new.reshape(-1, out.shape[-1])
        return out

    def _reward(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """Immediate reward ``(A^N, K)`` but the capture's, and the no-collision mask
        (``terminate`` mode, else ``None``), of pursuers' cells ``p (N, K)``."""
        rw, k, a, n = self.scenario.rewards, p.shape[1], self.n_actions, self.n
        r = np.full((self.n_joint, k), rw.step)
        if rw.wall:
            r += rw.wall * self.joint([self.walls[:, c] for c in p], np.add)
        if self.pairs is None:
            return r, None
        hits = np.zeros((a,) * n + (k,))
        for i in range(n):
            for j in range(i + 1, n):
                shape = [a if ax in (i, j) else 1 for ax in range(n)] + [k]
                hits += self.pairs[:, :, p[i], p[j]].reshape(shape)
        hits = hits.reshape(-1, k)
        r += self.collision * hits
        return r, (hits == 0 if self.terminate else None)

    def sweep(self, v: np.ndarray) -> Greedy:
        """``max_a Q(s, a)`` for every canonical state, of values ``v (n + 1,)`` (the last,
        the sentinel's, 0)."""
        n_canon = self.index.n
        out = Greedy(
            np.empty(n_canon), np.empty(n_canon, dtype=np.int32), np.empty(n_canon),
            np.empty((self.n_moves, n_canon), dtype=np.intp),
        )  # fmt: skip
        for lo in range(0, n_canon, self.chunk):
            self._chunk(v, lo, min(n_canon, lo + self.chunk), out)
        return out

    def _chunk(self, v: np.ndarray, lo: int, hi: int, out: Greedy) -> None:
        """:meth:`sweep` over canonical states ``[lo, hi)``, written into ``out``."""
        cells = self.index.cells[:, lo:hi].astype(np.int64)
        p, e = cells[: self.n], cells[self.n]
        c, sentinel = self.n_cells, self.index.n
        scale = [c ** (self.n - i) for i in range(self.n)]
        base = self.joint([self.pmove[:, pi] * w for pi, w in zip(p, scale, strict=True)], np.add)
        r, nocoll = self._reward(p)
        acc, buf = np.zeros(r.shape), np.empty(r.shape)
        captures = np.zeros(r.shape) if self.scenario.rewards.capture else None
        succ, pe = [], [pi * c + e for pi in p]
        for b in range(self.n_moves):
            free = self.joint([self.free[b][:, x] for x in pe], np.bitwise_and).view(bool)
            if captures is not None:
                captures += ~free
            if nocoll is not None:
                free &= nocoll
            # int64 ids: numpy's gathers convert int32 indices first, several times slower
            ids = self.index.ids[base + self.emove[e, b]].astype(np.intp)
            ids[~free] = sentinel
            acc += np.take(v, ids, out=buf)
            succ.append(ids)
        if captures is not None:
            r += self.scenario.rewards.capture * captures / self.n_moves
        q = r + acc / self.n_moves
        best = q.argmax(axis=0)
        cols = np.arange(hi - lo)
        out.value[lo:hi] = q[best, cols]
        out.action[lo:hi] = best
        out.reward[lo:hi] = r[best, cols]
        for b, ids in enumerate(succ):
            out.succ[b, lo:hi] = ids[best, cols]
