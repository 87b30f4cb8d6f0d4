"""The learning curve as Foxglove's Plot panel reads it: a ``/plot/episodes`` point per
``every`` episodes (means, see :data:`.schemas.EPISODE_POINT_SCHEMA`), and a
``/plot/update`` point per update (:func:`update_point`).

Points are grouped by episode id (``[0, every)``, ``[every, 2 · every)``, …) and made in
bulk with numpy, one text template per message: the log writes them beside its summary
blocks, the live view beside its stream. A group is written when its last episode has
finished; the group still open when writing stops is written as it is (:meth:`rest`).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np
import orjson

from ..config import Scenario

if TYPE_CHECKING:
    from ..envs.tallies import EpisodeBatch

_COLUMNS = (
    "length",
    "return",
    "captured",
    "collision_terminated",
    "truncated",
    "collisions",
    "wall_contacts",
    "evader_return",
)


class EpisodeCurve:
    """Points of ``every`` episodes of ``scenario`` (with ``learned``: the evader's return
    too), fed with :meth:`add`; each point is ``(log_time_ns, json_bytes)``, timed at the end
    of its last episode."""

    def __init__(self, scenario: Scenario, every: int, learned: bool) -> None:
        if every < 1:
            raise ValueError("every must be >= 1")
        self.every, self.learned = every, learned
        rewards, mode = scenario.rewards, scenario.collisions.mode
        self._weight = rewards.collision if mode != "off" else 0.0
        self._width = len(_COLUMNS) - (0 if learned else 1)
        self._ids = np.zeros(0, dtype=np.int64)
        self._t1 = np.zeros(0, dtype=np.int64)
        self._rows = np.zeros((0, self._width))

    def add(
        self, ids: np.ndarray, t1_ns: np.ndarray, **columns: np.ndarray
    ) -> list[tuple[int, bytes]]:
        """Take finished episodes (consecutive ids, in order; ``t1_ns`` their end times;
        ``columns`` keyed as :data:`_COLUMNS`: ``length``, ``return``, the three endings,
        ``collisions``, ``wall_contacts``, and ``evader_return`` if learned); the points of
        the groups they complete."""
        if not len(ids):
            return []
        rows = np.column_stack(
            [np.asarray(columns[k], dtype=np.float64) for k in _COLUMNS[: self._width]]
        )
        self._ids = np.concatenate([self._ids, np.asarray(ids, dtype=np.int64)])
        self._t1 = np.concatenate([self._t1, np.asarray(t1_ns, dtype=np.int64)])
        self._rows = np.concatenate([self._rows, rows])
        last_complete = self._ids[-1] % self.every == self.every - 1
        groups = self._ids // self.every
        ends = np.flatnonzero(np.diff(groups)) + 1  # where each later group starts
        cut = len(self._ids) if last_complete else (ends[-1] if len(ends) else 0)
        return self._take(cut)

    def rest(self) -> list[tuple[int, bytes]]:
        """The points of the episodes still waiting (a group not yet complete)."""
        return self._take(len(self._ids))

    def _take(self, cut: int) -> list[tuple[int, bytes]]:
        """The points of the first ``cut`` waiting episodes, which are then dropped."""
        if cut == 0:
            return []
        ids, t1, rows = self._ids[:cut], self._t1[:cut], self._rows[:cut]
        self._ids, self._t1, self._rows = self._ids[cut:], self._t1[cut:], self._rows[cut:]
        groups = ids // self.every
        starts = np.concatenate([[0], np.flatnonzero(np.diff(groups)) + 1])
        counts = np.diff(np.append(starts, len(ids)))
        sums = np.add.reduceat(rows, starts, axis=0)
        means = sums / counts[:, None]
        caught = rows[:, 0] * rows[:, 2]  # lengths of the captured episodes
        capture_steps = np.add.reduceat(caught, starts) / np.maximum(sums[:, 2], 1)
        last = starts + counts - 1
        return [
            (int(t1[j]), self._text(int(ids[j]), int(n), m, float(c) if s[2] else None))
            for j, n, m, c, s in zip(last, counts, means, capture_steps, sums, strict=True)
        ]

    def _text(self, episode: int, n: int, m: np.ndarray, capture_steps: float | None) -> bytes:
        length, ret, captured, collided, truncated, collisions, walls = m[:7].tolist()
        penalty = self._weight * collisions
        doc: dict[str, Any] = {"episode": episode, "episodes": n, "length": length}
        if capture_steps is not None:
            doc["capture_steps"] = capture_steps
        doc.update({"return": ret, "return_time": ret - penalty, "return_collision": penalty})
        if self.learned:
            doc["evader_return"] = float(m[7])
        doc.update(
            captured=captured,
            collision_terminated=collided,
            truncated=truncated,
            collisions=collisions,
            wall_contacts=walls,
        )
        return orjson.dumps(doc)


def episode_columns(eps: EpisodeBatch, learned: bool) -> dict[str, np.ndarray]:
    """The columns of finished episodes ``eps`` as :meth:`EpisodeCurve.add` takes them (with
    ``learned``: the evader's return too)."""
    columns = {
        "length": eps.length,
        "return": eps.ret,
        "captured": eps.captured,
        "collision_terminated": eps.collision_terminated,
        "truncated": eps.truncated,
        "collisions": eps.collisions,
        "wall_contacts": eps.wall_contacts,
    }
    if learned:
        columns["evader_return"] = eps.evader_ret
    return columns


def update_point(doc: dict[str, Any]) -> bytes:
    """The ``/plot/update`` message of an update's ``/train/update`` document: its
    counters and finite numeric metrics (booleans, strings and nulls left out)."""
    out = {
        k: v
        for k, v in doc.items()
        if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
    }
    return orjson.dumps(out)
