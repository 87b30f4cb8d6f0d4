"""The recorder's time-major step buffers: one row per vector step, one column per game.

Each vector step is copied in with one slice assignment per field whatever the number of
games; a finished episode is later gathered out of them (see :mod:`.block`). Row 0 holds
the state at the start of recording. Actions are ``(rows, B, N + 1)`` int64 moves, or
``(rows, B, N + 1, 2)`` float64 commands with continuous control (pursuers, then the
evader), the values given to the env, unclipped. With differential drive the pursuers'
headings are kept as the velocities are (``hdg``, ``shdg``: ``(rows, B, N, 2)``, ``(cos θ,
sin θ)``).
"""

from __future__ import annotations

import numpy as np

from ..envs.vector import VecStep, VectorEnv

_FIELDS = (
    *("pos", "spos", "vel", "svel", "hdg", "shdg"),
    *("act", "rew", "erew", "captured", "col", "wall"),
)


class StepBuffers:
    """Buffers of ``rows`` vector steps of ``vec_env`` (see the module docstring).

    ``pos``/``vel`` hold the state after each step (before any auto-reset), ``spos``/``svel``
    the state after the auto-reset of the games that finished in that step (their next
    episode's start); ``erew`` a learned evader's reward (``None`` otherwise); ``vel`` and
    ``svel`` are ``None`` in grid mode.
    """

    def __init__(self, vec_env: VectorEnv, rows: int) -> None:
        core = vec_env.core
        pos, vel = core.positions(), core.velocities()
        b, agents = vec_env.num_envs, vec_env.n_agents + 1
        shape = (rows, b)
        self.rows = rows
        self.pos = np.zeros((*shape, agents, 2), dtype=pos.dtype)
        self.spos = np.zeros_like(self.pos)
        self.vel = None if vel is None else np.zeros((*shape, agents, 2), dtype=vel.dtype)
        self.svel = None if vel is None else np.zeros_like(self.vel)
        hdg = core.headings() if vec_env.scenario.differential else None
        self.hdg = None if hdg is None else np.zeros((*shape, agents - 1, 2))
        self.shdg = None if hdg is None else np.zeros_like(self.hdg)
        continuous = vec_env.scenario.continuous
        self.act = (
            np.zeros((*shape, agents, 2), dtype=np.float64)
            if continuous
            else np.zeros((*shape, agents), dtype=np.int64)
        )
        self.rew = np.zeros(shape, dtype=np.float64)
        self.erew = np.zeros(shape, dtype=np.float64) if vec_env.learned_evader else None
        self.captured = np.zeros(shape, dtype=bool)
        self.col = np.zeros(shape, dtype=np.int64)
        self.wall = np.zeros(shape, dtype=np.int64)
        self.pos[0] = self.spos[0] = pos
        if vel is not None:
            self.vel[0] = self.svel[0] = vel
        if hdg is not None:
            self.hdg[0] = self.shdg[0] = hdg

    @property
    def continuous(self) -> bool:
        """Whether actions are float commands."""
        return self.act.dtype.kind == "f"

    def write(self, r: int, actions: np.ndarray, step: VecStep) -> None:
        """Row ``r``: the step taken with the pursuers' ``actions`` and what it returned."""
        out = step.outcome
        act = self.act[r]
        act[:, :-1] = actions
        act[:, -1] = out.evader_action
        self.pos[r] = step.positions
        self.rew[r] = out.reward
        self.captured[r] = out.captured
        self.col[r] = out.collisions
        self.wall[r] = out.wall_contacts
        if self.vel is not None:
            self.vel[r] = step.velocities
        if self.hdg is not None:
            self.hdg[r] = step.headings
        if self.erew is not None:
            self.erew[r] = step.evader_reward

    def write_starts(self, r: int, vec_env: VectorEnv) -> None:
        """Row ``r`` of the start states: the games as they are after the step's auto-reset."""
        core = vec_env.core
        self.spos[r] = core.positions()
        if self.svel is not None:
            self.svel[r] = core.velocities()
        if self.shdg is not None:
            self.shdg[r] = core.headings()

    def keep(self, first: int, last: int) -> None:
        """Move rows ``first … last`` to the top (older rows are no longer needed)."""
        for name in _FIELDS:
            a = getattr(self, name)
            if a is not None:
                a[: last + 1 - first] = a[first : last + 1]

    def open_rows(self, begin: np.ndarray, row: int) -> dict[str, np.ndarray]:
        """Each game's rows from ``begin[game]`` (its running episode's start) to ``row``,
        game after game, per field, with ``lengths`` (rows per game): what
        :meth:`place_open` puts back."""
        lengths = row + 1 - begin
        rows = np.concatenate([np.arange(b, row + 1) for b in begin.tolist()])
        games = np.repeat(np.arange(len(begin)), lengths)
        out = {name: a[rows, games] for name in _FIELDS if (a := getattr(self, name)) is not None}
        return {**out, "lengths": np.asarray(lengths, dtype=np.int64)}

    def place_open(self, rows: dict[str, np.ndarray]) -> np.ndarray:
        """Put back :meth:`open_rows`, each game's rows ending at the same last row
        (``max(lengths) - 1``); the buffer row of each game's start. The buffers must have
        a row more than that."""
        lengths = rows["lengths"]
        last = int(lengths.max()) - 1
        begin = last + 1 - lengths
        at = np.concatenate([np.arange(b, last + 1) for b in begin.tolist()])
        games = np.repeat(np.arange(len(lengths)), lengths)
        for name in _FIELDS:
            a = getattr(self, name)
            if a is not None:
                a[at, games] = rows[name]
        return begin

    def grow(self) -> None:
        """Double the number of rows (an episode longer than the buffers)."""
        for name in _FIELDS:
            a = getattr(self, name)
            if a is not None:
                setattr(self, name, np.concatenate([a, np.zeros_like(a)]))
        self.rows *= 2
