"""Contact events → penalties (SPEC §3), and the debouncing that turns pymunk's raw
begin/separate callbacks into those events.

Two parts, both free of pymunk so they can be tested on hand-made input:

- :func:`score_events` is the *pure* mapping from one step's events and the scenario's
  rewards and collision mode to the step's reward, termination and counts.
- :class:`ContactTracker` holds one game's touching pairs and decides which contacts are
  *new* in a step. A pair's contact is new in step ``k`` when the pair began touching in
  step ``k`` and did not touch at any moment of step ``k − 1``. pymunk reports a lasting
  push between several bodies (a jam in a corner, three pursuers squeezing) as a flicker
  of begin/separate callbacks a substep or two apart; counting each begin would turn one
  push into dozens of collisions, and comparing only the end-of-step states would still
  count the flickers that straddle a step boundary. "Touched at any moment of the step" is
  immune to any flicker shorter than a step, needs no tuned threshold, and matches the
  game's time resolution: a separation is an env step in which the pair never touched.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

from ..config import CollisionMode, Rewards
from .core import ends_episode, team_reward

PURSUER_PURSUER = "pursuer_pursuer"
"""Two pursuers touch: one collision for that pair (penalised unless mode is ``off``)."""
PURSUER_EVADER = "pursuer_evader"
"""A pursuer touches the evader: capture, the episode terminates."""
AGENT_WALL = "agent_wall"
"""An agent (pursuer or evader) touches the arena wall: recorded; pursuers earn ``rewards.wall``."""
AGENT_OBSTACLE = "agent_obstacle"
"""An agent touches a static obstacle (``b`` is ``"obstacle"``, whichever obstacle it is): a
wall contact that also earns ``rewards.obstacle``."""
KINDS = (PURSUER_PURSUER, PURSUER_EVADER, AGENT_WALL, AGENT_OBSTACLE)
"""Every event kind, in the order events are listed within a step."""

Event = tuple[str, str, str, int]
"""``(kind, a, b, step)``: agent names ``a`` and ``b`` (``"wall"`` for the wall, ``"obstacle"``
for any obstacle), step number."""
Pair = tuple[str, str, str]
"""``(kind, a, b)``: a touching pair, the event without its step."""


@dataclass(frozen=True)
class StepScore:
    """What one game's contact events in one step amount to (SPEC §3, §4)."""

    reward: float
    terminated: bool
    captured: bool
    collisions: int
    wall_contacts: int
    obstacle_contacts: int = 0


def score_events(events: Iterable[Event], rewards: Rewards, mode: CollisionMode) -> StepScore:
    """Map one step's contact events of one game to its team reward, termination and counts.

    - ``pursuer_evader`` → captured, terminated;
    - ``pursuer_pursuer`` → one collision per distinct pursuer pair; penalised by
      ``rewards.collision`` in ``terminate`` and ``penalize`` mode (and terminating in
      ``terminate``); in ``off`` mode counted but neither penalised nor terminating;
    - ``agent_wall`` → one wall contact per distinct pursuer, rewarded by ``rewards.wall``
      (the evader's wall contacts are recorded as events but cost the team nothing);
    - ``agent_obstacle`` → a wall contact as ``agent_wall`` (a pursuer touching the wall and
      an obstacle in one step is one wall contact), and one obstacle contact per distinct
      pursuer, rewarded by ``rewards.obstacle`` on top.

    The events are the contacts that *began* in the step (see :class:`ContactTracker`), so a
    contact lasting many steps is scored once, at its begin. Raises ``ValueError`` on an
    unknown kind or mode.
    """
    if mode not in ("off", "terminate", "penalize"):
        raise ValueError(f"unknown collision mode {mode!r}")
    events = list(events)
    captured, collisions, wall_contacts = count_events(events)
    obstacles = count_obstacle_contacts(events)
    reward = team_reward(rewards, mode, captured, collisions, wall_contacts, obstacles)
    terminated = ends_episode(mode, captured, collisions)
    return StepScore(
        float(reward), bool(terminated), captured, collisions, wall_contacts, obstacles
    )


def count_events(events: Iterable[Event]) -> tuple[bool, int, int]:
    """``(captured, collisions, wall_contacts)`` of one game's step: a capture if any
    pursuer touched the evader, one collision per distinct pursuer pair, one wall contact
    per distinct pursuer that touched the wall or an obstacle. Raises ``ValueError`` on an
    unknown kind."""
    captured = False
    pairs: set[tuple[str, str]] = set()
    walls: set[str] = set()
    for kind, a, b, _step in events:
        if kind == PURSUER_EVADER:
            captured = True
        elif kind == PURSUER_PURSUER:
            pairs.add((a, b) if a <= b else (b, a))
        elif kind in (AGENT_WALL, AGENT_OBSTACLE):
            if a != "evader":
                walls.add(a)
        else:
            raise ValueError(f"unknown contact event kind {kind!r} (kinds: {', '.join(KINDS)})")
    return captured, len(pairs), len(walls)


def count_obstacle_contacts(events: Iterable[Event]) -> int:
    """The obstacle contacts of one game's step: one per distinct pursuer with an
    ``agent_obstacle`` event (each is also one of :func:`count_events`' wall contacts)."""
    return len({a for kind, a, _b, _step in events if kind == AGENT_OBSTACLE and a != "evader"})


class ContactTracker:
    """One game's touching pairs, fed by begin/separate callbacks; yields the new contacts.

    ``begin(pair)`` and ``separate(pair)`` are called from pymunk's collision callbacks
    (a pair may touch through several shapes at once, e.g. two wall segments in a corner,
    so touching is a count). ``end_step(step)`` closes an env step and returns the events
    of the pairs that began touching in it after a step without any contact (see the
    module docstring).
    """

    __slots__ = ("_active", "_began", "_changed", "_start_active", "_steady", "_touched_before")

    def __init__(self) -> None:
        self.clear()

    def clear(self) -> None:
        """Forget every contact: the state of a tracker that has seen nothing."""
        self._active: dict[Pair, int] = {}  # pair -> number of touching shape pairs now
        self._began: set[Pair] = set()  # pairs with a begin callback in this step
        self._start_active: set[Pair] = set()  # pairs touching when this step started
        self._touched_before: set[Pair] = set()  # pairs that touched at any time last step
        self._changed = False  # a callback came in this step
        # Whether a step without callbacks would leave everything as it is (it would set
        # _touched_before to _start_active and keep the rest).
        self._steady = True

    def begin(self, pair: Pair) -> None:
        """pymunk reported that ``pair`` started touching (through one more shape pair)."""
        self._active[pair] = self._active.get(pair, 0) + 1
        self._began.add(pair)
        self._changed = True

    def separate(self, pair: Pair) -> None:
        """pymunk reported that ``pair`` stopped touching (through one shape pair)."""
        left = self._active.get(pair, 0) - 1
        if left > 0:
            self._active[pair] = left
        else:
            self._active.pop(pair, None)
        self._changed = True

    def end_step(self, step: int) -> list[Event]:
        """Close step ``step``: the events of the contacts that are new in it, sorted."""
        if not self._changed and self._steady:
            return []  # the common case: no callback, and the same contacts as last step
        began = self._began
        new = sorted(began - self._touched_before, key=_event_order)
        # A pair touched at some moment of this step iff it touched when the step started
        # or began touching during it (a pair touching at the end did one or the other).
        self._touched_before = began | self._start_active
        self._start_active = set(self._active)
        self._began = set()
        self._changed = False
        self._steady = self._touched_before == self._start_active
        return [(*pair, step) for pair in new]

    def touching(self) -> set[Pair]:
        """Pairs touching now (for tests and debugging)."""
        return set(self._active)


def _event_order(pair: Pair) -> tuple[int, str, str]:
    return KINDS.index(pair[0]), pair[1], pair[2]
