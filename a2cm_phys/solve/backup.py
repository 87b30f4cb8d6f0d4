"""The Bellman backup's expectation and immediate reward over every joint state and joint
action of a grid game's tables (:class:`~.transitions.GridTables`), one slice of the first
pursuer's cell at a time.

The full tensor's axes are ``(p_0, a_0, p_1, a_1, …, p_{N-1}, a_{N-1}, e)``. The expected
next value is a chain of ``np.take`` calls over the model's per-agent tables, one per
agent, each times that agent's no-capture factor (:meth:`SlicedBackup.expect`); only the
last one, along ``p_0``, is taken a slice ``[lo, hi)`` at a time, so the full tensor is
never built.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from .transitions import GridTables


class SlicedBackup:
    """The expectation and the immediate reward of one backup of ``model``, by slices of
    ``model.chunk`` values of ``p_0``.

    The tables that only the backup needs (no collision in ``terminate`` mode, the reward
    when it is an array) are built on first use: loading a cached solution never needs them.
    """

    def __init__(self, model: GridTables) -> None:
        self.model = model
        self._nocoll: list[np.ndarray] | None = None
        self._reward: list[np.ndarray] | None = None

    # ------------------------------------------------------------------ the slices' layout

    def chunks(self) -> Iterator[tuple[int, int]]:
        """The slices' bounds ``(lo, hi)`` along ``p_0``, in order."""
        c, chunk = self.model.n_cells, self.model.chunk
        for lo in range(0, c, chunk):
            yield lo, min(c, lo + chunk)

    def slice_shape(self, lo: int, hi: int) -> tuple[int, ...]:
        """Shape of the slice ``p_0 ∈ [lo, hi)`` of the full tensor."""
        m = self.model
        return (hi - lo, m.n_actions) + (m.n_cells, m.n_actions) * (m.n - 1) + (m.n_cells,)

    def place(self, table: np.ndarray, axes: tuple[int, ...], lo: int, hi: int) -> np.ndarray:
        """``table`` reshaped to broadcast over a slice ``[lo, hi)`` of the full tensor;
        ``axes`` says where each axis of ``table`` goes (in increasing order)."""
        shape = [1] * (2 * self.model.n + 1)
        for axis, size in zip(axes, table.shape, strict=True):
            shape[axis] = size
        out = table.reshape(shape)
        return out[lo:hi] if axes[0] == 0 else out

    def _trailing(self, shape: tuple[int, ...]) -> tuple[int, ...]:
        """``shape`` widened to the last pursuer's ``(cell, action)`` axes.

        Broadcasting a factor whose innermost axis is only ``e`` makes numpy loop over runs
        of ``C`` elements; widening it to ``(p_{N-1}, a_{N-1}, e)`` makes the runs long.
        """
        if self.model.n < 2:
            return shape
        return (*shape[:-3], self.model.n_cells, self.model.n_actions, shape[-1])

    # ------------------------------------------------------------------ the reward

    def _reward_chunks(self) -> list[np.ndarray]:
        """Expected immediate reward per (state, joint action) slice."""
        m = self.model
        rw = m.scenario.rewards
        out = []
        capture = None
        if rw.capture:
            ones = np.ones(m.shape)
            capture = [g.copy() for _, _, g in self.expect(ones, collisions=False)]
        for k, (lo, hi) in enumerate(self.chunks()):
            r = np.full(self.slice_shape(lo, hi), rw.step)
            for i in range(m.n):
                r += rw.wall * self.place(m.walls, (2 * i, 2 * i + 1), lo, hi)
                for j in range(i + 1, m.n):
                    axes = (2 * i, 2 * i + 1, 2 * j, 2 * j + 1)
                    r += m.collision_reward * self.place(m.pair_collide, axes, lo, hi)
            if capture is not None:
                r += rw.capture * (1.0 - capture[k])
            out.append(r)
        return out

    def reward(self, k: int) -> np.ndarray | float:
        """Expected immediate reward of slice number ``k`` (an array, or the step reward)."""
        if not self.model.reward_varies:
            return self.model.scenario.rewards.step
        if self._reward is None:
            self._reward = self._reward_chunks()
        return self._reward[k]

    # ------------------------------------------------------------------ the expectation

    def _pre(self, u: np.ndarray, b: int) -> np.ndarray:
        """Pursuers ``1 … N-1`` and the evader's move ``b`` applied to ``u``: all but ``p_0``."""
        m = self.model
        x = np.take(u, m.emove[:, b], axis=m.n)
        for i in range(m.n - 1, 0, -1):
            x = np.take(x, m.pmove, axis=i)
            shape = (m.n_cells, m.n_actions) + (1, 1) * (m.n - 1 - i) + (m.n_cells,)
            factor = m.free[:, :, :, b].reshape(shape)
            x *= np.broadcast_to(factor, self._trailing(shape)).copy()
        return x

    def _factors(self, lo: int, hi: int) -> list[np.ndarray]:
        """Per evader move, the ``p_0`` no-capture factor times ``P(b | s)`` for a slice."""
        m = self.model
        c, n = m.n_cells, m.n
        shape = (hi - lo, m.n_actions) + (1, 1) * (n - 1) + (c,)
        out = []
        for b in range(m.n_moves):
            factor = m.free[lo:hi, :, :, b].reshape(shape)
            if m.weights is not None:
                w = m.weights[:, b].reshape((c,) + (1, c) * n)[lo:hi]
                factor = factor * w
            elif m.n_moves > 1:
                factor = factor / m.n_moves
            full = np.broadcast_shapes(factor.shape, self._trailing(shape))
            out.append(np.ascontiguousarray(np.broadcast_to(factor, full)))
        return out

    def _nocoll_chunk(self, lo: int, hi: int) -> np.ndarray:
        """No pursuer pair collides (``terminate`` mode: the episode goes on), as bool."""
        out = np.ones(self.slice_shape(lo, hi), dtype=bool)
        for i in range(self.model.n):
            for j in range(i + 1, self.model.n):
                axes = (2 * i, 2 * i + 1, 2 * j, 2 * j + 1)
                out &= self.place(self.model.pair_collide, axes, lo, hi) == 0
        return out

    def expect(
        self, u: np.ndarray, collisions: bool = True
    ) -> Iterator[tuple[int, int, np.ndarray]]:
        """See :meth:`~.model.GridModel.expect`."""
        m = self.model
        pre = [self._pre(u, b) for b in range(m.n_moves)]
        acc = tmp = None
        for k, (lo, hi) in enumerate(self.chunks()):
            shape = self.slice_shape(lo, hi)
            if acc is None or acc.shape != shape:
                acc, tmp = np.empty(shape), np.empty(shape)
            for b, (x, factor) in enumerate(zip(pre, self._factors(lo, hi), strict=True)):
                out = acc if b == 0 else tmp
                np.take(x, m.pmove[lo:hi], axis=0, out=out, mode="clip")
                out *= factor
                if b:
                    acc += tmp
            if collisions and m.terminate:
                if self._nocoll is None:
                    self._nocoll = [self._nocoll_chunk(*bounds) for bounds in self.chunks()]
                acc *= self._nocoll[k]
            yield lo, hi, acc
