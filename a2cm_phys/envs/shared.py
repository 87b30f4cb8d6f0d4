"""The shared memory of a :class:`~.workers.ProcessCore`: the arrays of a batch of physics
games that the parent and its worker processes share (:class:`SharedBatch`), and one
process's step of its slice of games through them (:func:`step_slice`)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import fields
from typing import Any

import numpy as np

from ..config import Scenario
from .core import StepOutcome
from .physics import PhysicsCore

OUTCOME_FIELDS = tuple(f.name for f in fields(StepOutcome) if f.name != "events")
"""The fields of :class:`~.core.StepOutcome` that travel through shared memory (all but
the contact events; ``obstacle_contacts`` only in a scenario with obstacles, see
:attr:`SharedBatch.outcome_fields`)."""

Placement = Mapping[str, Sequence[float]] | None
"""One game's explicit start positions for a reset (agent name to metres), or ``None``."""


class SharedBatch:
    """The arrays of a batch of ``num_envs`` physics games that the parent and its workers
    share, in one block of shared memory. The parent writes the pursuers' actions (and a
    learned evader's, ``evader_actions``) and marks games to reset (``reset``, with their
    ``seed``); the workers clear those marks and write each field of the step outcome but
    the events, and the state (positions, velocities, and with differential drive the
    pursuers' ``headings``). ``views(lo, hi)`` gives numpy views of games ``lo:hi``."""

    def __init__(self, scenario: Scenario, num_envs: int, ctx: Any) -> None:
        n = scenario.pursuers
        # continuous control: float64 (vx, vy) commands for the pursuers and the evader
        command = (np.dtype(np.float64), (2,)) if scenario.continuous else (np.dtype(np.int64), ())
        self.layout: list[tuple[str, np.dtype, tuple[int, ...]]] = [
            ("actions", command[0], (n, *command[1])),
            ("evader_actions", *command),  # read only with a learned evader
            ("seed", np.dtype(np.uint64), ()),
            ("state", np.dtype(np.float64), (2, n + 1, 2)),
            ("reward", np.dtype(np.float64), ()),
            ("collisions", np.dtype(np.int64), ()),
            ("wall_contacts", np.dtype(np.int64), ()),
            ("evader_action", *command),
            ("terminated", np.dtype(np.bool_), ()),
            ("truncated", np.dtype(np.bool_), ()),
            ("captured", np.dtype(np.bool_), ()),
            ("reset", np.dtype(np.bool_), ()),
        ]
        if scenario.obstacles:
            self.layout.append(("obstacle_contacts", np.dtype(np.int64), ()))
        if scenario.differential:
            self.layout.append(("headings", np.dtype(np.float64), (n, 2)))
        names = {name for name, _, _ in self.layout}
        self.outcome_fields = tuple(name for name in OUTCOME_FIELDS if name in names)
        """The outcome's fields this batch carries (a missing one is ``None``)."""
        self.num_envs = num_envs
        size = sum(_bytes(dtype, num_envs, tail) for _, dtype, tail in self.layout)
        self.block = ctx.RawArray("b", size)

    def views(self, lo: int = 0, hi: int | None = None) -> dict[str, np.ndarray]:
        """Numpy views of every field for games ``lo:hi`` (default: all)."""
        out, offset = {}, 0
        for name, dtype, tail in self.layout:
            count = self.num_envs * int(np.prod(tail, dtype=np.int64))
            whole = np.frombuffer(self.block, dtype, count, offset).reshape(-1, *tail)
            out[name] = whole[lo:hi]
            offset += _bytes(dtype, self.num_envs, tail)
        return out


def _bytes(dtype: np.dtype, num_envs: int, tail: tuple[int, ...]) -> int:
    """Bytes of one field, rounded up to 8 so that every field stays aligned."""
    size = dtype.itemsize * num_envs * int(np.prod(tail, dtype=np.int64))
    return -(-size // 8) * 8


def step_slice(
    core: PhysicsCore,
    mine: dict[str, np.ndarray],
    placed: dict[int, Placement] | None,
    learned: bool,
) -> list[list]:
    """Step the games of ``core``, whose shared arrays are ``mine``: first the resets marked
    there (with their ``placed`` positions, by local index), then one step; write the
    outcome and the state to ``mine`` and return the contact events."""
    marked = mine["reset"]
    envs = np.flatnonzero(marked)
    if len(envs):
        where = [placed.get(env) for env in envs.tolist()] if placed else None
        core.reset(envs, mine["seed"][envs], where)
        marked[envs] = False
    outcome = core.step(mine["actions"], mine["evader_actions"] if learned else None)
    for name in OUTCOME_FIELDS:
        if name in mine:
            mine[name][:] = getattr(outcome, name)
    mine["state"][:] = core._state
    if core._headings is not None:
        mine["headings"][:] = core._headings
    return outcome.events
