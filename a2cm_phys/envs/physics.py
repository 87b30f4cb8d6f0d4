"""Physics mode (SPEC §3): the pursuit game in pymunk, one :class:`pymunk.Space` per game.

The worlds (walls, bodies, the agents' velocity servos, contact tracking) are
:mod:`.world`'s; this core plays the game in them. One env step is one control period,
``physics.dt`` seconds of simulated time (1 s with discrete moves, 0.1 s by default with
continuous control), in ``physics.substeps`` fixed substeps. A discrete action sets its
servo to ``max_speed`` along its axis; a continuous command (clipped to the unit disc) sets
it to that fraction of ``max_speed``. The evader is a policy given to the core
(:class:`~.core.EvaderPolicy`; by default the scenario's scripted one) whose command drives
its servo the same way. The only Python work per substep is one call of chipmunk's step
function; per step, every servo of every game is steered by one numpy scatter and every
body read by one gather, in chipmunk's memory (see :data:`~.chipmunk.DIRECT_CALLS`).
Contact callbacks run only when shapes begin or stop touching and feed a
:class:`~.contacts.ContactTracker`, which turns them into the step's events (debounced: see
:mod:`.contacts`); the penalties are :func:`~.contacts.score_events`. Actions and the
evader's commands are applied at the start of a step; since pymunk moves bodies before it
solves velocities, an agent starting from rest covers ``max_speed · dt · (1 − 1/substeps)``
in its first step and exactly ``max_speed · dt`` per step once at speed.

With ``physics.drive = "differential"`` the pursuers have headings (``(B, N, 2)`` ``(cos θ,
sin θ)``, appended to the observation) and are steered substep by substep (:mod:`.drive`,
:meth:`~.drive_worlds.DriveWorlds.drive`); every reset starts them at heading 0 (+x). With obstacles
(:mod:`.obstacles`), a step's outcome also counts the wall contacts that were with one.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from itertools import combinations

import numpy as np

from ..config import Scenario
from .contacts import count_events, count_obstacle_contacts
from .core import (
    ACTION_DELTAS,
    EvaderPolicy,
    StepOutcome,
    agent_names,
    clip_to_disc,
    default_start,
    parse_positions,
    settle,
)
from .drive import DrivePlan
from .drive_worlds import DriveWorlds
from .evaders import make_evader
from .evaders.learned import refuse_evader_actions
from .obstacles import check_thickness, obstacle_overlaps
from .starts import random_starts
from .worlds import Worlds


def start_positions(scenario: Scenario) -> np.ndarray:
    """Default start ``(N + 1, 2)`` in metres: the grid mode's start cells' centres."""
    return default_start(scenario.size, scenario.pursuers).astype(np.float64) + 0.5


def observation(
    scenario: Scenario, state: np.ndarray, headings: np.ndarray | None = None
) -> np.ndarray:
    """Observations ``(B, state_dim)`` float32 of a state ``(B, 2, N + 1, 2)`` (positions,
    velocities): all positions / ``size``, then all velocities / ``max_speed`` (SPEC §5),
    then with differential drive the pursuers' ``headings`` ``(B, N, 2)`` ``(cos θ, sin θ)``."""
    scale = np.array([scenario.size, scenario.physics.max_speed], dtype=np.float64)
    obs = (state / scale[:, None, None]).astype(np.float32).reshape(len(state), -1)
    if headings is None:
        return obs
    return np.concatenate((obs, headings.astype(np.float32).reshape(len(state), -1)), axis=1)


def rest_headings(scenario: Scenario, num_envs: int) -> np.ndarray | None:
    """Every pursuer's heading at a reset, ``(B, N, 2)`` ``(cos θ, sin θ) = (1, 0)``, with
    differential drive; ``None`` with holonomic pursuers (they have none)."""
    if scenario.physics.drive != "differential":
        return None
    headings = np.zeros((num_envs, scenario.pursuers, 2))
    headings[..., 0] = 1.0
    return headings


def placed_positions(scenario: Scenario, placed: Mapping[str, Sequence[float]]) -> np.ndarray:
    """Validate ``reset(options={"positions": placed})`` for physics mode: ``(N + 1, 2)`` metres.

    Agents not named keep their default start. Every body must lie inside the arena, no
    two may overlap and none may overlap an obstacle (touching is fine; pursuers as
    unrotated boxes); a ``ValueError`` names the agent(s) at fault.
    """
    ph, size, n = scenario.physics, scenario.size, scenario.pursuers
    names = agent_names(scenario)
    ext = np.array([ph.box_side / 2] * n + [ph.evader_radius])  # centre to edge
    xy = parse_positions(scenario, placed, float(ext.min()), size - float(ext.min()))
    for i, name in enumerate(names):
        if np.any(xy[i] < ext[i]) or np.any(xy[i] > size - ext[i]):
            raise ValueError(
                f"positions[{name!r}] = {tuple(xy[i].tolist())} puts {name} into the wall "
                f"(each coordinate in [{ext[i]:g}, {size - ext[i]:g}])"
            )
    for i, j in combinations(range(n + 1), 2):
        d = np.abs(xy[i] - xy[j])
        # Two axis-aligned boxes, or a box and the disc (its centre nearer than its radius).
        box_gap = np.hypot(*np.maximum(d - ext[i], 0.0))
        if (d.max() < 2 * ext[i]) if j < n else (box_gap < ext[j]):
            raise ValueError(
                f"positions: {names[i]} at {tuple(xy[i].tolist())} and "
                f"{names[j]} at {tuple(xy[j].tolist())} overlap"
            )
    blocked = obstacle_overlaps(scenario, xy)
    if blocked.any():
        i = int(np.argmax(blocked))
        raise ValueError(
            f"positions[{names[i]!r}] = {tuple(xy[i].tolist())} puts {names[i]} into an obstacle"
        )
    return xy


class StateViews:
    """The ``Core`` views of a physics state array ``_state`` of shape ``(B, 2, N + 1, 2)``
    (positions, then velocities) and, with differential drive, of the pursuers' headings
    ``_headings`` ``(B, N, 2)`` (``None`` otherwise), shared by :class:`PhysicsCore` and the
    process core."""

    scenario: Scenario
    _state: np.ndarray
    _headings: np.ndarray | None

    def observe(self) -> np.ndarray:
        """``(B, state_dim)`` float32: all positions / ``size``, then velocities /
        ``max_speed``, then with differential drive the pursuers' ``(cos θ, sin θ)``."""
        return observation(self.scenario, self._state, self._headings)

    def headings(self) -> np.ndarray | None:
        """The pursuers' headings ``(B, N, 2)`` as ``(cos θ, sin θ)`` with differential
        drive, else ``None``."""
        return None if self._headings is None else self._headings.copy()

    def positions(self) -> np.ndarray:
        """Agent centres ``(B, N + 1, 2)`` in metres: pursuers, then the evader."""
        return self._state[:, 0].copy()

    def velocities(self) -> np.ndarray:
        """Agent velocities ``(B, N + 1, 2)`` in m/s."""
        return self._state[:, 1].copy()


class PhysicsCore(StateViews):
    """``num_envs`` independent physics games of one scenario (implements ``core.Core``).

    ``evader`` is the evader's policy (default: the scenario's, see
    :func:`~.evaders.make_evader`; with ``evader = "learned"`` its actions come with each
    :meth:`step`)."""

    def __init__(
        self, scenario: Scenario, num_envs: int = 1, evader: EvaderPolicy | None = None
    ) -> None:
        if scenario.mode != "physics":
            raise ValueError(f"PhysicsCore needs a physics scenario, got mode={scenario.mode!r}")
        ph, n = scenario.physics, scenario.pursuers
        ph.check_substeps()  # a ValueError naming physics.substeps
        check_thickness(scenario)  # one naming the obstacle
        self.scenario = scenario
        self.num_envs = num_envs
        self.t = np.zeros(num_envs, dtype=np.int64)
        self.episode_seed = np.zeros(num_envs, dtype=np.uint64)
        self._start = start_positions(scenario)
        radius = float(ph.evader_radius)  # the evader's centre stays this far from walls
        self._evader = evader or make_evader(scenario, num_envs, radius, scenario.size - radius)
        self._give = getattr(self._evader, "give", None)  # a learned evader's mailbox
        self._continuous = scenario.continuous
        self._velocities = (ACTION_DELTAS * ph.max_speed).astype(np.float64)  # (moves, 2)
        worlds = DriveWorlds if scenario.differential else Worlds
        self._worlds = worlds(scenario, num_envs, self._start)
        self._state = np.zeros((num_envs, 2, n + 1, 2))  # [game, position|velocity, agent, xy]
        self._state[:, 0] = self._start
        self._headings = rest_headings(scenario, num_envs)
        self._obstacles = bool(scenario.obstacles)

    # ------------------------------------------------------------------ reset

    def reset(
        self,
        envs: np.ndarray,
        seeds: np.ndarray,
        positions: Sequence[Mapping[str, Sequence[float]] | None] | None = None,
    ) -> None:
        """Start new episodes in games ``envs``: rebuild their spaces
        (:meth:`~.world.World.rebuild`), at the scenario's start (random starts drawn from
        ``seeds``, :mod:`.starts`) or at explicit ``positions``
        (one mapping or ``None`` per game, metres)."""
        envs = np.atleast_1d(np.asarray(envs, dtype=np.int64))
        placed = list(positions or ())
        starts: list[np.ndarray | None] = [None] * len(envs)
        if self.scenario.start.random:
            starts = list(random_starts(self.scenario, seeds))
        for k, where in enumerate(placed[: len(envs)]):
            if where:  # validate everything before touching any game
                starts[k] = placed_positions(self.scenario, where)
        self._worlds.restart(envs.tolist(), starts)
        for env, xy in zip(envs.tolist(), starts, strict=True):
            self._state[env, 0], self._state[env, 1] = self._start if xy is None else xy, 0.0
        if self._headings is not None:
            self._headings[envs] = (1.0, 0.0)
        self.t[envs] = 0
        self.episode_seed[envs] = seeds
        self._evader.restart(envs, self.episode_seed[envs])

    def build_spare(self) -> int:
        """Rebuild one world at the default start for a later :meth:`reset` to take, and
        return how many are waiting. Rebuilding is most of a reset's cost; a caller with
        idle time (a worker process waiting for its next request) can spend it here. A
        spare is rebuilt exactly as ``reset`` would rebuild it and never stepped, so using
        one changes nothing but when the work is done. Spares are made from the worlds
        that earlier resets replaced, or built new while there are none."""
        return self._worlds.build_spare()

    @property
    def spare_worlds(self) -> int:
        """How many worlds :meth:`build_spare` has prepared that no reset has taken yet."""
        return self._worlds.spare_worlds

    # ------------------------------------------------------------------ step

    def step(self, actions: np.ndarray, evader_actions: np.ndarray | None = None) -> StepOutcome:
        """Advance every game one control period with the pursuers' ``(B, N)`` actions, or
        their ``(B, N, 2)`` velocity commands with continuous control (``(forward, turn)``
        with differential drive); ``evader_actions`` (``(B,)`` or ``(B, 2)``) are a learned
        evader's, required then and refused otherwise."""
        if self._give is not None:
            self._give(evader_actions)
        elif evader_actions is not None:
            raise refuse_evader_actions(self.scenario)
        n = self.scenario.pursuers
        pos = self._state[:, 0]
        evader = self._evader.moves(self.episode_seed, self.t, pos[:, n], pos[:, :n])
        self.t += 1
        if self._headings is not None:
            if self._continuous:
                evader_velocity = clip_to_disc(evader) * self.scenario.physics.max_speed
            else:
                evader_velocity = self._velocities[evader]
            plan = DrivePlan(self.scenario, actions)
            steps = self.t.tolist()
            events = self._worlds.drive(plan, evader_velocity, steps, self._state, self._headings)
            return self._score(events, evader)
        if self._continuous:
            commands = np.concatenate((actions, evader[:, None]), axis=1)
            velocities = clip_to_disc(commands) * self.scenario.physics.max_speed
        else:
            velocities = self._velocities[np.concatenate((actions, evader[:, None]), axis=1)]
        events = self._worlds.advance(velocities, self.t.tolist(), self._state)
        return self._score(events, evader)

    def _score(self, events: list[list], evader: np.ndarray) -> StepOutcome:
        b = self.num_envs
        captured = np.zeros(b, dtype=bool)
        collisions = np.zeros(b, dtype=np.int64)
        walls = np.zeros(b, dtype=np.int64)
        obstacles = np.zeros(b, dtype=np.int64) if self._obstacles else None
        for g, game_events in enumerate(events):
            if game_events:  # most steps of most games have no new contact
                captured[g], collisions[g], walls[g] = count_events(game_events)
                if obstacles is not None:
                    obstacles[g] = count_obstacle_contacts(game_events)
        return settle(self.scenario, self.t, captured, collisions, walls, evader, events, obstacles)

    # ------------------------------------------------------------------ views

    def kinetic_energy(self) -> np.ndarray:
        """Total kinetic energy (J) of each game's agents, ``(B,)``."""
        return 0.5 * self.scenario.physics.mass * (self._state[:, 1] ** 2).sum(axis=(1, 2))
