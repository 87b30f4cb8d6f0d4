"""What a :class:`~.vector.VectorEnv` counts of the episode running in each game
(:class:`EpisodeTallies`), the summary of a finished one (:class:`EpisodeSummary`), and the
summaries of those a step or a rollout finished, column by column (:class:`EpisodeBatch`)."""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from typing import Any, NamedTuple, overload

import numpy as np

from .core import StepOutcome


class EpisodeSummary(NamedTuple):
    """One finished episode of a vector env (``ret``: the pursuers' team return;
    ``evader_ret``: a learned evader's return, ``None`` with a scripted evader). A named
    tuple: the main job makes some 200,000 of them, and a frozen dataclass's fields cost
    several times as much to set."""

    env: int
    seed: int
    length: int
    ret: float
    captured: bool
    truncated: bool
    collision_terminated: bool
    collisions: int
    wall_contacts: int
    evader_ret: float | None = None


_FIELDS = EpisodeSummary._fields


class EpisodeBatch(Sequence[EpisodeSummary]):
    """The episodes a vector step (or a rollout) finished, in order, as one array per field
    of :class:`EpisodeSummary` (``evader_ret``: ``None`` with a scripted evader).

    A sequence of :class:`EpisodeSummary`, made only when an episode is read as one; what
    counts or logs episodes by the hundred thousand (the trainer's tallies, the episode log)
    reads the columns instead."""

    __slots__ = _FIELDS

    def __init__(self, **columns: np.ndarray | None) -> None:
        for name in _FIELDS:
            setattr(self, name, columns[name])

    @classmethod
    def empty(cls, learned_evader: bool = False) -> EpisodeBatch:
        """No episodes (with ``learned_evader``, an empty ``evader_ret`` column)."""
        kinds = (np.int64, np.uint64, np.int64, float, bool, bool, bool, np.int64, np.int64)
        cols = {k: np.zeros(0, dtype=d) for k, d in zip(_FIELDS, kinds, strict=False)}
        return cls(**cols, evader_ret=np.zeros(0) if learned_evader else None)

    @classmethod
    def concat(cls, batches: Sequence[EpisodeBatch]) -> EpisodeBatch:
        """The episodes of ``batches`` (at least one), one after the other."""
        if len(batches) == 1:
            return batches[0]
        cols = {k: np.concatenate([getattr(b, k) for b in batches]) for k in _FIELDS[:-1]}
        learned = batches[0].evader_ret is not None
        evader = np.concatenate([b.evader_ret for b in batches]) if learned else None
        return cls(**cols, evader_ret=evader)

    def __len__(self) -> int:
        return len(self.env)

    @overload
    def __getitem__(self, i: int) -> EpisodeSummary: ...

    @overload
    def __getitem__(self, i: slice) -> list[EpisodeSummary]: ...

    def __getitem__(self, i: int | slice) -> EpisodeSummary | list[EpisodeSummary]:
        return list(self)[i]

    def __iter__(self) -> Iterator[EpisodeSummary]:
        # whole columns to Python numbers at once: the same values as int()/float()
        cols = [getattr(self, k).tolist() for k in _FIELDS[:-1]]
        learned = self.evader_ret
        cols.append(learned.tolist() if learned is not None else [None] * len(self))
        return map(EpisodeSummary._make, zip(*cols, strict=True))

    def __eq__(self, other: object) -> bool:
        """Equal to another batch or a list of the same summaries, in the same order."""
        if isinstance(other, EpisodeBatch | list):
            return list(self) == list(other)
        return NotImplemented

    __hash__ = None  # type: ignore[assignment]  # a mutable view of arrays

    def __repr__(self) -> str:
        return f"EpisodeBatch({list(self)!r})"


class EpisodeTallies:
    """Running totals of the episode in progress in each of ``num_envs`` games: the
    pursuers' return, a learned evader's return, collisions and wall contacts."""

    def __init__(self, num_envs: int) -> None:
        self.ret = np.zeros(num_envs)
        self.evader_ret = np.zeros(num_envs)
        self.collisions = np.zeros(num_envs, dtype=np.int64)
        self.walls = np.zeros(num_envs, dtype=np.int64)

    def restart(self, envs: np.ndarray) -> None:
        """Zero the totals of games ``envs``, whose new episodes start now."""
        self.ret[envs] = 0.0
        self.evader_ret[envs] = 0.0
        self.collisions[envs] = 0
        self.walls[envs] = 0

    def add(self, out: StepOutcome, evader_rewards: np.ndarray | None) -> None:
        """Count one step of every game (``evader_rewards``: a learned evader's, or ``None``)."""
        self.ret += out.reward
        if evader_rewards is not None:
            self.evader_ret += evader_rewards
        self.collisions += out.collisions
        self.walls += out.wall_contacts

    def summaries(
        self,
        envs: np.ndarray,
        seeds: np.ndarray,
        lengths: np.ndarray,
        out: StepOutcome,
        learned_evader: bool,
    ) -> EpisodeBatch:
        """The summaries of the episodes that ``out`` ended in games ``envs``, whose episode
        ``seeds`` and ``lengths`` (per game) the caller took before stepping."""
        i = np.asarray(envs, dtype=np.int64)
        captured = np.asarray(out.captured, dtype=bool)[i]
        return EpisodeBatch(
            env=i,
            seed=np.asarray(seeds)[i],
            length=np.asarray(lengths, dtype=np.int64)[i],
            ret=self.ret[i],
            captured=captured,
            truncated=np.asarray(out.truncated, dtype=bool)[i],
            collision_terminated=np.asarray(out.terminated, dtype=bool)[i] & ~captured,
            collisions=self.collisions[i],
            wall_contacts=self.walls[i],
            evader_ret=self.evader_ret[i] if learned_evader else None,
        )

    def state(self) -> dict[str, np.ndarray]:
        """A copy of the totals, under the keys of a vector env's state."""
        return {
            "return": self.ret.copy(),
            "evader_return": self.evader_ret.copy(),
            "collisions": self.collisions.copy(),
            "walls": self.walls.copy(),
        }

    def load_state(self, state: Mapping[str, Any]) -> None:
        """Restore what :meth:`state` returned (an older state without a learned evader's
        return counts it from 0)."""
        self.ret[:] = state["return"]
        self.evader_ret[:] = state.get("evader_return", 0.0)
        self.collisions[:] = state["collisions"]
        self.walls[:] = state["walls"]
