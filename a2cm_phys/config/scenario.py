"""The scenario: one pursuit game as frozen, typed data (arena, agents, evader, time limit,
rewards, collisions, physics, sensing), validated when built."""

from __future__ import annotations

import dataclasses
import math
import typing
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from .arena import Obstacle, blocked_cells, check_obstacles
from .parse import InvalidKey, check_limits

Mode = Literal["grid", "physics"]
EvaderPolicy = Literal["random", "flee", "static", "learned"]  # learned: an agent (SPEC §1b)
EvaderReward = Literal["zero_sum", "survival"]
CollisionMode = Literal["off", "terminate", "penalize"]
Control = Literal["discrete", "continuous"]
StartKind = Literal["fixed", "random"]
Drive = Literal["holonomic", "differential"]

OMIT_DEFAULT = {"omit_default": True}
"""Field metadata of keys added after logs were first written: :func:`~.parse.to_dict` leaves
such a key out while it holds its default, so a scenario that does not use it is written
(config, log metadata, cache keys) exactly as before the key existed."""

SCRIPTED_EVADERS: tuple[str, ...] = tuple(
    e for e in typing.get_args(EvaderPolicy) if e != "learned"
)
"""The evaders the core plays by a fixed rule (a learned one is an agent of its own)."""

DEFAULT_DT = {"discrete": 1.0, "continuous": 0.1}
"""The control period ``physics.dt`` (s) of each control type when a scenario omits it."""


@dataclass(frozen=True)
class Rewards:
    """Team reward terms (SPEC §4); the reward is logged raw, learners may scale it.

    A contact with an obstacle is a wall contact (``wall``) that also costs ``obstacle``
    (physics mode; on a grid a move into a blocked cell is a wall bump, priced by ``wall``).

    ``evader`` is a learned evader's reward (SPEC §1b): ``zero_sum``, minus the team reward,
    or ``survival``, +1 for every step that does not end in its capture (its return is the
    number of steps it survived). Scripted evaders have no reward.
    """

    step: float = -1.0
    collision: float = 0.0
    capture: float = 0.0
    wall: float = 0.0
    evader: EvaderReward = "zero_sum"
    obstacle: float = field(default=0.0, metadata=OMIT_DEFAULT)  # per contact with an obstacle


@dataclass(frozen=True)
class Collisions:
    """How pursuer–pursuer collisions count: ``off``, ``terminate`` or ``penalize``."""

    mode: CollisionMode = "off"


@dataclass(frozen=True)
class Physics:
    """Physical parameters of physics mode (SPEC §3); one grid cell is one metre.

    ``drive = "differential"``: every pursuer is a body with a heading that moves only
    along it, commanded by (forward speed, turn rate) as fractions of ``max_speed`` and
    ``max_turn_rate`` (rad/s); the evader stays holonomic."""

    box_side: float = 0.6
    evader_radius: float = 0.3
    mass: float = 1.0
    max_speed: float = 1.0
    dt: float | None = None  # control period (s); None: DEFAULT_DT of the scenario's control
    substeps: int = 10  # fixed solver steps per control period
    wall_thickness: float = 1.0
    max_force: float = 50.0
    # how pursuers move: "holonomic" (any direction) or "differential" (turn, then drive)
    drive: Drive = field(default="holonomic", metadata=OMIT_DEFAULT)
    max_turn_rate: float = field(default=math.pi, metadata=OMIT_DEFAULT)  # rad/s

    def validate(self) -> None:
        """Raise ``ValueError`` naming the key of the first impossible value."""
        for key in (
            "box_side",
            "evader_radius",
            "mass",
            "max_speed",
            "wall_thickness",
            "max_force",
            "max_turn_rate",
        ):
            if not getattr(self, key) > 0:
                raise InvalidKey(f"physics.{key}", f"must be > 0, got {getattr(self, key)!r}")
        if self.box_side >= 1.0:
            raise InvalidKey("physics.box_side", f"must be < 1 (one cell), got {self.box_side!r}")
        if self.evader_radius >= 0.5:
            raise InvalidKey("physics.evader_radius", f"must be < 0.5, got {self.evader_radius!r}")
        if self.dt is not None and not self.dt > 0:
            raise InvalidKey("physics.dt", f"must be > 0, got {self.dt!r}")
        if self.substeps < 1:
            raise InvalidKey("physics.substeps", f"must be >= 1, got {self.substeps!r}")

    def check_substeps(self) -> None:
        """Refuse substeps so long that two bodies closing at ``2 × max_speed`` could pass
        through the smallest body in one substep (``2 · max_speed · dt / substeps``)."""
        smallest = min(self.box_side, 2 * self.evader_radius)
        dt = 1.0 if self.dt is None else self.dt
        reach = 2 * self.max_speed * dt / self.substeps
        if reach >= smallest:
            raise InvalidKey(
                "physics.substeps",
                f"physics.substeps = {self.substeps} is too few: two agents closing at "
                f"2 × max_speed would move {reach:g} m per substep (dt = {dt:g} s), enough "
                f"to pass through a {smallest:g} m body; use more than "
                f"{int(2 * self.max_speed * dt / smallest)} substeps",
            )


@dataclass(frozen=True)
class Sensing:
    """What each agent senses (SPEC §6b). ``radius = None`` (the default): every agent
    observes the global state, as in the paper. Otherwise an agent senses the bodies within
    ``radius`` of itself: on grids the Chebyshev distance in cells (``radius = 1`` is the
    3×3 block around it), in physics the distance in metres between centres, both inclusive.
    ``share``: the pursuers pool their sightings (one radio), so each knows every teammate's
    position and the evader whenever any of them senses it; ``false``: each knows only what
    it senses itself. A learned evader senses the pursuers within the same radius, alone.

    Physics mode only: ``rays = R`` (0: none; needs ``radius``) gives every agent a range
    sensor, the distances to the first shape along ``R`` evenly spaced rays from its
    heading out to ``range`` metres, appended to its observation; ``occlusion = true`` lets
    obstacles hide bodies from ``radius`` sensing."""

    radius: float | None = None
    share: bool = False
    rays: int = field(default=0, metadata=OMIT_DEFAULT)  # range-sensor rays per agent
    range: float = field(default=3.0, metadata=OMIT_DEFAULT)  # metres a ray reaches
    occlusion: bool = field(default=False, metadata=OMIT_DEFAULT)  # obstacles hide bodies

    def validate(self) -> None:
        """Raise ``ValueError`` naming the key of an impossible value."""
        if self.radius is not None and not self.radius > 0:
            raise InvalidKey("sensing.radius", f"must be > 0 when given, got {self.radius!r}")
        if self.rays < 0:
            raise InvalidKey("sensing.rays", f"must be >= 0, got {self.rays!r}")
        if not self.range > 0:
            raise InvalidKey("sensing.range", f"must be > 0, got {self.range!r}")
        if self.rays and self.radius is None:
            raise InvalidKey(
                "sensing.rays",
                "needs sensing.radius (the readings join each agent's own observation; a "
                "radius of the arena's diagonal senses every body)",
            )

    @property
    def on(self) -> bool:
        """Whether agents observe less than the global state."""
        return self.radius is not None


@dataclass(frozen=True)
class Start:
    """Where episodes start. ``fixed`` (the default, the paper's): pursuers in the corners,
    then along the border, the evader in the centre. ``random``: every agent's cell (grid)
    or position (physics) drawn uniformly from the episode's seed over the valid starts:
    no two agents on one cell (grid) or touching (physics), every body clear of the walls,
    and every pursuer at least ``min_evader_distance`` from the evader (grid: Manhattan
    distance in cells, so the default 2 keeps pursuers off and not next to the evader;
    physics: metres between centres). In physics ``min_pursuer_distance`` also keeps the
    pursuers' centres that far apart (0: their boxes apart, no more; a differential-drive
    pursuer turning in place sweeps a circle of its box's diagonal, ``box_side · √2``).
    ``start = "random"`` is short for ``[start] kind = "random"``."""

    shorthand: typing.ClassVar[str] = "kind"  # a bare string value sets this key
    kind: StartKind = "fixed"
    min_evader_distance: float = 2.0
    min_pursuer_distance: float = field(default=0.0, metadata=OMIT_DEFAULT)  # m, physics

    def validate(self) -> None:
        """Raise ``ValueError`` naming the key of an impossible value."""
        for key in ("min_evader_distance", "min_pursuer_distance"):
            value = getattr(self, key)
            if not value >= 0:
                raise InvalidKey(f"start.{key}", f"must be >= 0, got {value!r}")

    @property
    def random(self) -> bool:
        """Whether starts are drawn from the episode's seed."""
        return self.kind == "random"


@dataclass(frozen=True)
class Scenario:
    """One pursuit game: arena, agents, evader, time limit, rewards and collision mode."""

    name: str = "custom"
    mode: Mode = "grid"
    size: int = 5
    pursuers: int = 3
    actions: int = 4
    control: Control = "discrete"  # physics mode: "continuous" steers with velocity commands
    evader: EvaderPolicy = "random"
    max_steps: int = 1000
    rewards: Rewards = field(default_factory=Rewards)
    collisions: Collisions = field(default_factory=Collisions)
    physics: Physics = field(default_factory=Physics)
    sensing: Sensing = field(default_factory=Sensing)
    start: Start = field(default_factory=Start)
    obstacles: tuple[Obstacle, ...] = field(default=(), metadata=OMIT_DEFAULT)

    def __post_init__(self) -> None:
        if self.physics.dt is None:  # the control type decides the default period
            physics = dataclasses.replace(self.physics, dt=DEFAULT_DT.get(self.control, 1.0))
            object.__setattr__(self, "physics", physics)

    def validate(self) -> None:
        """Raise ``ValueError`` naming the key of the first impossible value."""
        check_limits(self, SCENARIO_LIMITS)
        if self.size < 2:
            raise InvalidKey("size", f"must be >= 2, got {self.size}")
        border = 4 * (self.size - 1)
        if not 1 <= self.pursuers <= border:
            raise InvalidKey(
                "pursuers",
                f"must be between 1 and {border} (the border cells), got {self.pursuers}",
            )
        if self.pursuers + 1 > self.size * self.size:
            raise InvalidKey("pursuers", "leave no free cell for the evader")
        if self.actions not in (4, 5):
            raise InvalidKey("actions", f"must be 4 (paper) or 5 (adds stay), got {self.actions}")
        if self.max_steps < 1:
            raise InvalidKey("max_steps", f"must be >= 1, got {self.max_steps}")
        self.physics.validate()
        self.sensing.validate()
        self.start.validate()
        if self.obstacles:
            ph = self.physics
            reach = (ph.box_side / 2**0.5, ph.evader_radius) if self.mode == "physics" else None
            check_obstacles(self.obstacles, self.size, self.pursuers, reach, self.start.random)
        if self.start.random:
            _check_start_room(self)
        if self.mode == "physics":
            self.physics.check_substeps()
        else:
            for key, value, default in (
                ("control", self.control, "discrete"),
                ("rewards.obstacle", self.rewards.obstacle, 0.0),
                ("physics.drive", self.physics.drive, "holonomic"),
                ("sensing.rays", self.sensing.rays, 0),
                ("sensing.range", self.sensing.range, 3.0),
                ("sensing.occlusion", self.sensing.occlusion, False),
                ("start.min_pursuer_distance", self.start.min_pursuer_distance, 0.0),
            ):
                if value != default:
                    raise InvalidKey(key, f"{value!r} needs mode = 'physics'")

    def blocked_cells(self) -> np.ndarray:
        """Whether each cell ``x + size · y`` is blocked by an obstacle (its centre covered),
        ``(size²,)`` bool; all ``False`` without obstacles."""
        return blocked_cells(self.size, self.obstacles)

    @property
    def continuous(self) -> bool:
        """Whether pursuers steer with velocity commands (SPEC §3b) rather than discrete moves."""
        return self.control == "continuous"

    @property
    def agents(self) -> list[str]:
        """Names of the learning pursuers, in order."""
        return [f"pursuer_{i}" for i in range(self.pursuers)]

    @property
    def differential(self) -> bool:
        """Whether the pursuers have headings (physics mode, ``physics.drive =
        "differential"``)."""
        return self.mode == "physics" and self.physics.drive == "differential"

    @property
    def position_unit(self) -> float:
        """What the observation divides positions by (SPEC §5): ``size`` metres in physics,
        ``size - 1`` cells on a grid, so that they lie in [0, 1]."""
        return float(self.size if self.mode == "physics" else self.size - 1)

    @property
    def state_dim(self) -> int:
        """Length of the global observation (state) vector (SPEC §5): ``2 (N + 1)`` on grids,
        ``4 (N + 1)`` in physics, plus ``2 N`` (each pursuer's ``cos θ, sin θ``) with
        differential drive."""
        per_agent = 4 if self.mode == "physics" else 2
        return per_agent * (self.pursuers + 1) + (2 * self.pursuers if self.differential else 0)

    @property
    def body_features(self) -> int:
        """Features ``k`` of one body in a sensed observation: 2 on grids (x, y), 4 in
        physics (x, y, vx, vy), 6 with differential drive (then cos θ, sin θ; the evader's
        are 0)."""
        if self.mode != "physics":
            return 2
        return 6 if self.differential else 4

    @property
    def obs_dim(self) -> int:
        """Length of one agent's observation: the global state's (:attr:`state_dim`) with
        sensing off; with sensing on (SPEC §6b) its own ``k`` features, then ``1 + k`` (mask
        bit, features) for each of the ``N`` other bodies, then ``sensing.rays`` range
        readings: ``k + N (1 + k) + rays``, where ``k`` is :attr:`body_features`."""
        if not self.sensing.on:
            return self.state_dim
        k = self.body_features
        return k + self.pursuers * (1 + k) + self.sensing.rays


SCENARIO_LIMITS: dict[str, tuple[int, str]] = {
    "size": (1000, "the arena's tables and pictures grow with size²"),
    "pursuers": (64, "one actor per pursuer, each observing every agent"),
    "max_steps": (1_000_000, "an episode's log is buffered in memory until it ends"),
    "physics.substeps": (
        10_000,
        "each is a solver step of every game, about 5 µs: 10,000 already make one step take 50 ms",
    ),
}
"""Largest values a scenario may ask for, with the reason: beyond them memory runs out, or
a step takes so long that a run seems to hang. A dotted key is a key of a sub-table."""


def _check_start_room(sc: Scenario) -> None:
    """Refuse a ``start.min_evader_distance`` no start can keep: on a grid, exactly (no
    free evader cell with ``pursuers`` free cells that far); in physics, beyond the
    farthest a pursuer's centre can be from the evader's."""
    d, n = sc.start.min_evader_distance, sc.size
    if sc.mode == "grid":
        # an evader in a corner has the most cells that far (along any row or column a
        # border cell is the farthest from most cells): count the cells x + y >= d
        need = max(math.ceil(d), 1)
        room = sum(max(0, n - max(0, need - x)) for x in range(n))
        farthest = f"{sc.pursuers} cells that far from any evader cell"
        if sc.obstacles and room >= sc.pursuers:
            # count the free cells that far from each free evader cell, those nearest a
            # corner first (the likeliest to have room), until one has room
            free = np.flatnonzero(~sc.blocked_cells())
            y, x = np.divmod(free, n)
            corner = np.minimum(x, n - 1 - x) + np.minimum(y, n - 1 - y)
            order = np.argsort(corner, kind="stable")
            step, room = max(1, 2**22 // len(free)), 0
            for lo in range(0, len(free), step):
                e = order[lo : lo + step]
                far = np.abs(x[e, None] - x) + np.abs(y[e, None] - y) >= need
                room = max(room, int(far.sum(axis=1).max()))
                if room >= sc.pursuers:
                    break
            farthest = f"{sc.pursuers} free cells that far from any free evader cell"
    else:
        span = n - sc.physics.box_side / 2 - sc.physics.evader_radius
        room = sc.pursuers if d <= span * 2**0.5 else 0
        farthest = f"a pursuer farther than {span * 2**0.5:.3g} m from the evader"
    if room < sc.pursuers:
        raise InvalidKey(
            "start.min_evader_distance",
            f"{d:g} leaves no valid random start (the {n}x{n} arena has no room for {farthest})",
        )
