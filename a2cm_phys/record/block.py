"""A block of finished episodes gathered from the step buffers, all fields at once, and
written as one ``/episodes/trajectories`` message (columnar, see :mod:`.schemas`)."""

from __future__ import annotations

import json

import numpy as np

from ..config import Scenario
from .buffers import StepBuffers
from .jsontext import json_array, json_float_rows, json_number, json_object, json_rows, json_value
from .masks import masks_of, packed
from .runlog import Trajectory


def ranges(starts: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """Concatenated ``arange(s, s + n)`` for each start ``s`` and length ``n``."""
    offsets = np.cumsum(lengths) - lengths
    return np.arange(int(lengths.sum())) - np.repeat(offsets - starts, lengths)


def _take(buffer: np.ndarray, flat: np.ndarray) -> np.ndarray:
    """Rows of a ``(rows, games, …)`` buffer at flat indices ``row · games + game``."""
    return np.take(buffer.reshape(-1, *buffer.shape[2:]), flat, axis=0)


class Block:
    """Episodes gathered from ``buf``: episode ``j`` ran in game ``env[j]`` from buffer row
    ``begin[j]`` (its start state) for ``length[j]`` steps. ``dt`` is the simulated seconds
    per step; ``events`` each episode's contact events (``None`` in grid mode). With a
    sensing ``scenario``, each state's sensing masks are computed from its positions
    (:mod:`.masks`); without one, or without sensing, there are none."""

    def __init__(
        self,
        buf: StepBuffers,
        ids: np.ndarray,
        env: np.ndarray,
        seed: np.ndarray,
        begin: np.ndarray,
        length: np.ndarray,
        events: list[list | None],
        dt: float,
        scenario: Scenario | None = None,
    ) -> None:
        self.ids, self.env, self.seed, self.length, self.events = ids, env, seed, length, events
        self.dt = dt
        # States: each episode's start (from the reset buffer), then the row after each step.
        games = buf.pos.shape[1]
        rows = ranges(begin, length + 1)
        flat = rows * games + np.repeat(env, length + 1)
        starts = np.cumsum(length + 1) - (length + 1)
        self.state_offset = rows - np.repeat(begin, length + 1)  # steps since the start
        first = begin * games + env
        self.pos = _take(buf.pos, flat)
        self.pos[starts] = _take(buf.spos, first)
        self.vel = None
        if buf.vel is not None:
            self.vel = _take(buf.vel, flat)
            self.vel[starts] = _take(buf.svel, first)
        self.hdg = None
        if buf.hdg is not None:
            self.hdg = _take(buf.hdg, flat)
            self.hdg[starts] = _take(buf.shdg, first)
        flat = ranges(begin + 1, length) * games + np.repeat(env, length)
        self.act = _take(buf.act, flat)
        self.rew = _take(buf.rew, flat)
        self.erew = None if buf.erew is None else _take(buf.erew, flat)
        self.captured = _take(buf.captured, flat)
        self.col = _take(buf.col, flat)
        self.wall = _take(buf.wall, flat)
        self.sensed = None if scenario is None else masks_of(scenario, self.pos)

    def json(self, t0: np.ndarray) -> bytes:
        """The ``/episodes/trajectories`` message of these episodes."""
        n = len(self.pos)
        if self.act.ndim == 3:  # continuous commands: exact floats, never via integers
            actions = json_float_rows(self.act.reshape(len(self.act), -1))
        else:
            actions = json_rows(self.act)
        fields = {
            "episode": json_array(self.ids),
            "env": json_array(self.env),
            "seed": json_array(self.seed),
            "length": json_array(self.length),
            "t0": json_array(t0),
            "dt": json_number(self.dt).encode(),
            "time": json_array(self.state_offset * self.dt),
            "positions": json_rows(self.pos.reshape(n, -1)),
            "actions": actions,
            "reward": json_array(self.rew),
            "captured": json_array(self.captured),
            "collisions": json_array(self.col),
            "wall_contacts": json_array(self.wall),
        }
        if self.erew is not None:
            fields["evader_reward"] = json_array(self.erew)
        if self.vel is not None:
            fields["velocities"] = json_rows(self.vel.reshape(n, -1))
        if self.hdg is not None:
            fields["headings"] = json_rows(self.hdg.reshape(n, -1))
        if any(e is not None for e in self.events):
            fields["events"] = json.dumps(
                [e or [] for e in self.events], separators=(",", ":"), default=json_value
            ).encode()
        if self.sensed is not None:
            fields["sensed"] = json_rows(packed(self.sensed))
        return json_object(**fields)

    def trajectory(self, t0: float) -> Trajectory:
        """The first episode of the block as a :class:`Trajectory` (for scene frames)."""
        length = int(self.length[0])
        return Trajectory(
            episode=int(self.ids[0]),
            env=int(self.env[0]),
            seed=int(self.seed[0]),
            t0=t0,
            dt=self.dt,
            positions=self.pos[: length + 1],
            actions=self.act[:length],
            reward=self.rew[:length],
            captured=self.captured[:length],
            collisions=self.col[:length],
            wall_contacts=self.wall[:length],
            velocities=None if self.vel is None else self.vel[: length + 1],
            events=None if self.events[0] is None else [tuple(e) for e in self.events[0]],
            evader_reward=None if self.erew is None else self.erew[:length],
            sensed=None if self.sensed is None else self.sensed[: length + 1],
            headings=None if self.hdg is None else self.hdg[: length + 1],
        )
