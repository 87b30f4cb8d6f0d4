"""Physics mode (SPEC §3): the pursuit game in pymunk, one :class:`pymunk.Space` per game.

Walls are four static boxes outside ``[0, size]²`` (inner edges on the boundary), pursuers
dynamic square boxes, the evader a dynamic disc, all with rotation locked. Each agent is
driven by a *velocity servo* (pymunk's tank-example idiom): a kinematic control body given
the commanded velocity, pinned to the agent by a :class:`pymunk.PivotJoint` with
``max_bias = 0`` (no position correction: it only matches velocities) and ``max_force =
physics.max_force``. The joint pulls the agent up to speed and holds it there like floor
friction, while the contact solver, which is not force-limited, stops agents at walls and
lets them push and be pushed: the controller never moves a body itself. The control bodies
are not added to the space: with its anchors at the centres and no position correction the
joint reads only their velocity, so chipmunk has nothing to integrate for them (bit-identical
to adding them, which costs a quarter more objects to move at every reset).

One env step is one control period, ``physics.dt`` seconds of simulated time (1 s with
discrete moves, 0.1 s by default with continuous control), in ``physics.substeps`` fixed
substeps. A discrete action sets its servo to ``max_speed`` along its axis; a continuous
command (clipped to the unit disc) sets it to that fraction of ``max_speed``. The evader
is a policy given to the core (:class:`~.core.EvaderPolicy`; by default the scenario's
scripted one) whose command drives its servo the same way. The only Python work per
substep is one call of chipmunk's step function; per step, every servo of every game is
steered by one numpy scatter and every body read by one gather, in chipmunk's memory (see
:data:`DIRECT_CALLS`). Contact callbacks
(:meth:`pymunk.Space.on_collision`) run only when shapes begin or stop touching and feed
a :class:`~.contacts.ContactTracker`, which turns them into the step's events (debounced:
see :mod:`.contacts`); the penalties are :func:`~.contacts.score_events`. Actions and the
evader's commands are applied at the start of a step; since pymunk moves bodies before it
solves velocities, an agent starting from rest covers ``max_speed · dt · (1 − 1/substeps)``
in its first step and exactly ``max_speed · dt`` per step once at speed.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from enum import IntEnum
from functools import cache, partial
from itertools import combinations
from typing import Any

import numpy as np
import pymunk

from ..config import Scenario
from .contacts import (
    AGENT_WALL,
    PURSUER_EVADER,
    PURSUER_PURSUER,
    ContactTracker,
    Pair,
    count_events,
)
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
from .evaders import make_evader
from .evaders.learned import refuse_evader_actions


class CollisionType(IntEnum):
    """pymunk collision types of the shapes. Our one contact handler is a wildcard that tells
    shapes apart by identity; the types say what a shape is, to pymunk's debug tools and to
    handlers a user adds for a pair of them."""

    PURSUER = 1
    EVADER = 2
    WALL = 3


COLLISION_SLOP = 0.01
"""Allowed overlap (m) before the solver pushes shapes apart; pymunk's default, 0.1, is sized
for pixels and would let 0.6 m boxes sink 10 cm into each other."""

DIRECT_CALLS = True
"""Make the frequent operations go straight to chipmunk when this pymunk allows it, instead
of through pymunk's Python wrappers of the same calls:

- stepping a space, placing a body at a reset: chipmunk's C functions;
- steering the servos and reading the bodies: one numpy scatter and one gather per step
  over every game, in chipmunk's memory (:class:`_Memory`; the offsets of ``cpBody``'s
  position and velocity are checked once against chipmunk's getters and setters,
  :func:`_body_layout`, else each body is read and steered by a C call);
- contacts: C callbacks set in chipmunk's own handler (:func:`_handle_contacts`), which
  find their two shapes with ``cpArbiterGetShapes``, without pymunk's dispatcher.

The wrappers add bookkeeping for objects added or removed from callbacks, which ours never
do, and Python attribute machinery and allocations: they cost as much as the simulation
itself. Trajectories are the same bit for bit (tested with this off). Creating pymunk objects
and adding them to or removing them from spaces always goes through pymunk's API."""


def _pair_table(scenario: Scenario) -> list[list[Pair]]:
    """``table[i][j]``: the contact pair of shapes tagged ``i`` and ``j`` (agents ``0 … N``,
    ``N + 1`` the wall), in canonical order: lower pursuer first, agents before the wall."""
    names = [*agent_names(scenario), "wall"]
    n = scenario.pursuers
    # The diagonal (a shape with itself) never touches; wall–wall pairs are not handled.
    table: list[list[Pair]] = [[("", "", "")] * (n + 2) for _ in range(n + 2)]
    for i, j in combinations(range(n + 2), 2):
        kind = PURSUER_PURSUER if j < n else PURSUER_EVADER if j == n else AGENT_WALL
        table[i][j] = table[j][i] = (kind, names[i], names[j])
    return table


class World:
    """One game: its bodies, shapes, servos and contact tracker, and the space they live in.

    The pymunk objects are built once; the space is not. :meth:`rebuild` (called by every
    reset) moves them, at rest at their start, into a brand-new :class:`pymunk.Space` with
    new servo joints. A new chipmunk space remembers nothing: no contact cache, no warm-start
    impulses, fresh spatial indexes, and shape ids counted from zero in the same insertion
    order, so an episode does not depend on the ones before it (bit-identity with a world
    that was never used is tested). What the reused objects carry is reset explicitly:
    positions and velocities, and chipmunk's position-correction velocity, which is cleared
    by integrating positions over ``dt = 0``. Forces, angles and spins need nothing: no force
    is ever applied and rotation is locked. Rebuilding this way costs a third to a half of
    building every object anew and collecting the old ones, which is mostly pymunk's
    per-object Python bookkeeping (measured in ``BENCHMARKS.md``).

    Shapes keep pymunk's default friction and elasticity, both 0: agents slide along walls
    and each other without bouncing, and the servo plays the part of floor friction.
    """

    __slots__ = (
        "_callbacks",
        "_hooked",
        "_max_force",
        "_placing",
        "_shapes",
        "_static",
        "_walls",
        "addresses",
        "bodies",
        "controls",
        "cp_space",
        "probes",
        "servos",
        "space",
        "steering",
        "step",
        "tracker",
    )

    def __init__(self, scenario: Scenario, xy: np.ndarray, table: list[list[Pair]]) -> None:
        ph, size, n = scenario.physics, float(scenario.size), scenario.pursuers
        self._static = pymunk.Body(body_type=pymunk.Body.STATIC)
        tags: dict[pymunk.Shape, int] = {}  # shape -> row of the pair table
        self._walls: list[pymunk.Shape] = []
        t = ph.wall_thickness
        for x0, y0, x1, y1 in (
            (-t, -t, 0.0, size + t),  # left
            (size, -t, size + t, size + t),  # right
            (0.0, -t, size, 0.0),  # bottom
            (0.0, size, size, size + t),  # top
        ):
            wall = pymunk.Poly(self._static, [(x0, y0), (x1, y0), (x1, y1), (x0, y1)])
            wall.collision_type = CollisionType.WALL
            tags[wall] = n + 1
            self._walls.append(wall)
        self.bodies: list[pymunk.Body] = []
        self._shapes: list[pymunk.Shape] = []
        self.controls: list[pymunk.Body] = []
        for i in range(n + 1):
            body = pymunk.Body(ph.mass, float("inf"))
            if i < n:
                shape: pymunk.Shape = pymunk.Poly.create_box(body, (ph.box_side, ph.box_side))
                shape.collision_type = CollisionType.PURSUER
            else:
                shape = pymunk.Circle(body, ph.evader_radius)
                shape.collision_type = CollisionType.EVADER
            tags[shape] = i
            self.bodies.append(body)
            self._shapes.append(shape)
            self.controls.append(pymunk.Body(body_type=pymunk.Body.KINEMATIC))
        self.steering = [_access(control, "velocity", write=True) for control in self.controls]
        # positions of all agents, then their velocities: the layout of the state array
        self.probes = [
            _access(body, attr, write=False)
            for attr in ("position", "velocity")
            for body in self.bodies
        ]
        self._placing = [  # what rebuild sets: each body's position and velocity
            (_access(body, "position", write=True), _access(body, "velocity", write=True))
            for body in self.bodies
        ]
        self.addresses = _addresses(self.bodies, self.controls)
        self._max_force = ph.max_force
        self.tracker = ContactTracker()
        self._callbacks = _callbacks(self.tracker, table, tags)
        self._hooked: Any = None  # the space's handler, when it calls C callbacks
        self.space: pymunk.Space | None = None
        self.servos: list[pymunk.PivotJoint] = []
        self.rebuild(xy)

    def rebuild(self, xy: np.ndarray) -> None:
        """A new space with every agent at rest at ``xy`` (``(N + 1, 2)`` metres)."""
        old = self.space
        _unhook(self._hooked)  # the removals below need not reach the tracker: it is cleared
        if old is not None:  # release the objects (pymunk's separate callbacks still fire)
            old.remove(*self._walls, *self._shapes, *self.servos, *self.bodies)
            old.remove(self._static)
        space = pymunk.Space()
        space.collision_slop = COLLISION_SLOP
        space.add(self._static, *self._walls)
        self.servos = []
        rest = (0.0, 0.0)
        for body, shape, control, steer, (place, set_velocity), xy_i in zip(
            self.bodies,
            self._shapes,
            self.controls,
            self.steering,
            self._placing,
            xy.tolist(),
            strict=True,
        ):
            pymunk.Body.update_position(body, 0.0)  # clears the correction velocity
            place(tuple(xy_i))
            set_velocity(rest)
            steer(rest)
            # max_bias = 0 keeps the joint blind to where the control body is (see the
            # module docstring): it must stay 0 while the controls are outside the space.
            servo = pymunk.PivotJoint(control, body, rest, rest)
            servo.max_bias = 0.0
            servo.max_force = self._max_force
            space.add(body, shape, servo)
            self.servos.append(servo)
        self.tracker.clear()
        # One wildcard handler: the pairs that can touch are exactly the ones we record
        # (pursuer-pursuer, pursuer-evader, agent-wall; static walls never touch each
        # other and there is one evader), and one handler costs a quarter of four.
        self._hooked = _handle_contacts(space, self._callbacks)
        self.space = space
        self.cp_space = getattr(space, "_space", None)  # chipmunk's handle
        self.step: Callable[[float], None] = _stepper(space)

    def __del__(self) -> None:
        _unhook(getattr(self, "_hooked", None))


def _stepper(space: pymunk.Space) -> Callable[[float], None]:
    """A function advancing ``space`` by ``dt`` (:meth:`pymunk.Space.step`, or chipmunk's
    ``cpSpaceStep`` directly: see :data:`DIRECT_CALLS`)."""
    cp_space = getattr(space, "_space", None)
    if DIRECT_CALLS and hasattr(pymunk.cp, "cpSpaceStep") and cp_space is not None:
        return partial(pymunk.cp.cpSpaceStep, cp_space)
    return space.step


def _access(body: pymunk.Body, attr: str, write: bool) -> Callable[..., Any]:
    """A function reading (no argument) or writing (one) ``body.position`` or
    ``body.velocity``: chipmunk's getter or setter called directly on the body's C handle,
    or pymunk's property (see :data:`DIRECT_CALLS`). Read values have ``x`` and ``y``."""
    name = f"cpBody{'Set' if write else 'Get'}{attr.capitalize()}"
    c_function, cp_body = getattr(pymunk.cp, name, None), getattr(body, "_body", None)
    if DIRECT_CALLS and c_function is not None and cp_body is not None:
        return partial(c_function, cp_body)
    return partial(setattr if write else getattr, body, attr)


_POSITION_AT = 168
"""Byte offset in chipmunk's ``cpBody`` of ``transform.tx`` (then ``ty``): the position
``cpBodyGetPosition`` returns (the transform's origin; every body here has its centre of
gravity at its centre and no rotation, so this is ``body->p`` too)."""
_VELOCITY_AT = 80
"""Byte offset in chipmunk's ``cpBody`` of ``v`` (then its ``y``), the velocity that
``cpBodyGetVelocity`` returns and ``cpBodySetVelocity`` sets."""


@cache
def _body_layout() -> bool:
    """Whether this chipmunk's ``cpBody`` keeps positions and velocities at
    :data:`_POSITION_AT` and :data:`_VELOCITY_AT` (``chipmunk_private.h``'s layout, which
    pymunk's cffi declarations leave opaque). Checked once on probe bodies, stepped in a
    space, against chipmunk's getters and setters; a build where it fails keeps the
    per-body calls."""
    ffi = getattr(pymunk, "ffi", None)
    if ffi is None:
        return False
    try:
        body = pymunk.Body(1.0, float("inf"))
        control = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
        space = pymunk.Space()
        servo = pymunk.PivotJoint(control, body, (0.0, 0.0), (0.0, 0.0))
        servo.max_bias = 0.0
        space.add(body, pymunk.Poly.create_box(body, (0.5, 0.5)), servo)
        body.position, body.velocity = (1.25, -3.5), (0.375, 7.0)
        addresses = _raw_addresses([body], [control])
        memory = _Memory(addresses)
        position, velocity, steer = memory.index(addresses)
        memory.view[steer[0]] = (-0.625, 0.25)  # as the core steers
        space.step(0.05)
        got = [memory.view[index[0]].tolist() for index in (position, velocity, steer)]
        return got == [list(body.position), list(body.velocity), list(control.velocity)]
    except Exception:
        return False


def _addresses(bodies: Sequence[pymunk.Body], controls: Sequence[pymunk.Body]) -> np.ndarray | None:
    """Byte addresses ``(3, N + 1, 2)`` of the bodies' positions and velocities and of the
    control bodies' velocities in chipmunk's memory, for :class:`_Memory` (see
    :data:`DIRECT_CALLS`); ``None`` where they cannot be used."""
    if not DIRECT_CALLS or not _body_layout():
        return None
    return _raw_addresses(bodies, controls)


def _raw_addresses(bodies: Sequence[pymunk.Body], controls: Sequence[pymunk.Body]) -> np.ndarray:
    """:func:`_addresses`, unchecked."""
    handles = [b._body for b in (*bodies, *controls)]
    at = np.array([int(pymunk.ffi.cast("uintptr_t", h)) for h in handles], dtype=np.int64)
    n = len(bodies)
    xy = np.array([0, 8], dtype=np.int64)
    return np.stack(
        (
            at[:n, None] + _POSITION_AT + xy,
            at[:n, None] + _VELOCITY_AT + xy,
            at[n:, None] + _VELOCITY_AT + xy,
        )
    )


class _Memory:
    """A float64 numpy view of this process's memory from the lowest to the highest of some
    byte addresses, so that chipmunk's bodies are read and steered with one numpy gather and
    one scatter per step (see :data:`DIRECT_CALLS`). Only the indexed words are ever touched;
    whoever indexes it keeps the bodies alive."""

    __slots__ = ("lo", "view")

    def __init__(self, addresses: np.ndarray) -> None:
        self.lo = int(addresses.min())
        size = int(addresses.max()) + 8 - self.lo
        ffi = pymunk.ffi
        self.view = np.frombuffer(ffi.buffer(ffi.cast("char *", self.lo), size), np.float64)

    def index(self, addresses: np.ndarray) -> np.ndarray:
        """Indices into :attr:`view` of ``addresses`` (8-byte aligned, as doubles are)."""
        return (addresses - self.lo) >> 3


def _callbacks(
    tracker: ContactTracker, table: list[list[Pair]], tags: dict[pymunk.Shape, int]
) -> tuple[Any, Any, bool]:
    """The begin/separate callbacks of one world's spaces, and whether they are chipmunk's
    own (C function pointers for :func:`_handle_contacts`) rather than pymunk's. They only
    record the pair of the arbiter's two shapes into ``tracker``.

    Chipmunk's own (see :data:`DIRECT_CALLS`) are cffi callbacks, made once per world,
    that find the shapes through ``cpArbiterGetShapes`` into buffers made once. pymunk's
    (:meth:`pymunk.Space.on_collision`) go through pymunk's dispatcher, which builds an
    :class:`pymunk.Arbiter` per call, and :attr:`pymunk.Arbiter.shapes`, which allocates
    both buffers and makes two pymunk lookups."""
    ffi, cp = getattr(pymunk, "ffi", None), pymunk.cp
    get_shapes = getattr(cp, "cpArbiterGetShapes", None)
    if (
        DIRECT_CALLS
        and ffi is not None
        and get_shapes is not None
        and hasattr(cp, "cpSpaceAddCollisionHandler")
        and all(hasattr(shape, "_shape") for shape in tags)
    ):
        out_a, out_b = ffi.new("cpShape *[1]"), ffi.new("cpShape *[1]")
        rows = {shape._shape: table[tag] for shape, tag in tags.items()}  # C pointers hash
        cols = {shape._shape: tag for shape, tag in tags.items()}
        began, separated = tracker.begin, tracker.separate

        def begin(arbiter: Any, space: Any, data: Any) -> None:
            get_shapes(arbiter, out_a, out_b)
            began(rows[out_a[0]][cols[out_b[0]]])

        def separate(arbiter: Any, space: Any, data: Any) -> None:
            get_shapes(arbiter, out_a, out_b)
            separated(rows[out_a[0]][cols[out_b[0]]])

        try:
            return (
                ffi.callback("cpCollisionBeginFunc", begin),
                ffi.callback("cpCollisionSeparateFunc", separate),
                True,
            )
        except Exception:  # no C callbacks on this system (e.g. no executable memory)
            pass

    def begin_(arbiter: pymunk.Arbiter, space: pymunk.Space, data: Any) -> None:
        a, b = arbiter.shapes
        tracker.begin(table[tags[a]][tags[b]])

    def separate_(arbiter: pymunk.Arbiter, space: pymunk.Space, data: Any) -> None:
        a, b = arbiter.shapes
        tracker.separate(table[tags[a]][tags[b]])

    return begin_, separate_, False


_WILDCARD = (1 << 64) - 1
"""chipmunk's wildcard collision type (``~(cpCollisionType)0``), as pymunk passes it."""


def _handle_contacts(space: pymunk.Space, callbacks: tuple[Any, Any, bool]) -> Any:
    """Give ``space`` one wildcard contact handler with the ``begin`` and ``separate``
    callbacks of :func:`_callbacks`: set straight into chipmunk's handler when they are C
    callbacks (what pymunk's ``on_collision`` does, without its per-call dispatcher; the
    handler is returned, with chipmunk's default callbacks, for :func:`_unhook`), else
    through :meth:`pymunk.Space.on_collision` (``None`` is returned). Pre- and post-solve
    keep chipmunk's defaults either way."""
    begin, separate, raw = callbacks
    if not raw:
        space.on_collision(begin=begin, separate=separate)
        return None
    handler = pymunk.cp.cpSpaceAddCollisionHandler(space._space, _WILDCARD, _WILDCARD)
    defaults = handler.beginFunc, handler.separateFunc
    handler.beginFunc, handler.separateFunc = begin, separate
    return handler, defaults


def _unhook(hooked: Any) -> None:
    """Give a handler of :func:`_handle_contacts` back chipmunk's default callbacks, so that
    its space never calls C callbacks that may be freed before it (pymunk removes the
    shapes of a space it frees, which calls ``separate``)."""
    if hooked is not None:
        handler, (begin, separate) = hooked
        handler.beginFunc, handler.separateFunc = begin, separate


def start_positions(scenario: Scenario) -> np.ndarray:
    """Default start ``(N + 1, 2)`` in metres: the grid mode's start cells' centres."""
    return default_start(scenario.size, scenario.pursuers).astype(np.float64) + 0.5


def observation(scenario: Scenario, state: np.ndarray) -> np.ndarray:
    """Observations ``(B, 4 (N + 1))`` float32 of a state ``(B, 2, N + 1, 2)`` (positions,
    velocities): all positions / ``size``, then all velocities / ``max_speed`` (SPEC §5)."""
    scale = np.array([scenario.size, scenario.physics.max_speed], dtype=np.float64)
    return (state / scale[:, None, None]).astype(np.float32).reshape(len(state), -1)


def placed_positions(scenario: Scenario, placed: Mapping[str, Sequence[float]]) -> np.ndarray:
    """Validate ``reset(options={"positions": placed})`` for physics mode: ``(N + 1, 2)`` metres.

    Agents not named keep their default start. Every body must lie inside the arena and
    no two may overlap (touching is fine); a ``ValueError`` names the agent(s) at fault.
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
    return xy


class StateViews:
    """The ``Core`` views of a physics state array ``_state`` of shape ``(B, 2, N + 1, 2)``
    (positions, then velocities), shared by :class:`PhysicsCore` and the process core."""

    scenario: Scenario
    _state: np.ndarray

    def observe(self) -> np.ndarray:
        """``(B, 4 (N + 1))`` float32: all positions / ``size``, then velocities / ``max_speed``."""
        return observation(self.scenario, self._state)

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
        self.scenario = scenario
        self.num_envs = num_envs
        self.t = np.zeros(num_envs, dtype=np.int64)
        self.episode_seed = np.zeros(num_envs, dtype=np.uint64)
        self._table = _pair_table(scenario)
        self._start = start_positions(scenario)
        radius = float(ph.evader_radius)  # the evader's centre stays this far from walls
        self._evader = evader or make_evader(scenario, num_envs, radius, scenario.size - radius)
        self._give = getattr(self._evader, "give", None)  # a learned evader's mailbox
        self._continuous = scenario.continuous
        self._dt = ph.dt / ph.substeps
        self._velocities = (ACTION_DELTAS * ph.max_speed).astype(np.float64)  # (moves, 2)
        self._worlds = [World(scenario, self._start, self._table) for _ in range(num_envs)]
        self._spares: list[World] = []  # worlds rebuilt at the default start in advance
        self._retired: list[World] = []  # worlds replaced by spares, to be rebuilt as spares
        self._state = np.zeros((num_envs, 2, n + 1, 2))  # [game, position|velocity, agent, xy]
        self._state[:, 0] = self._start
        # Direct access to the bodies' memory (DIRECT_CALLS): each game's addresses, and
        # the view and indices that :meth:`_map` makes of them.
        self._addresses: np.ndarray | None = None
        self._cp_step = getattr(pymunk.cp, "cpSpaceStep", None)
        if self._cp_step is not None and all(
            world.addresses is not None and world.cp_space is not None for world in self._worlds
        ):
            self._addresses = np.stack([world.addresses for world in self._worlds])
            self._map()

    def _map(self) -> None:
        """(Re)make the memory view over every game's bodies and its read/write indices."""
        assert self._addresses is not None
        memory = _Memory(self._addresses)
        index = memory.index(self._addresses)
        self._memory = memory.view
        self._read = index[:, :2]  # (B, position|velocity, agent, xy): the state's layout
        self._write = index[:, 2]  # (B, agent, xy): the control bodies' velocities

    # ------------------------------------------------------------------ reset

    def reset(
        self,
        envs: np.ndarray,
        seeds: np.ndarray,
        positions: Sequence[Mapping[str, Sequence[float]] | None] | None = None,
    ) -> None:
        """Start new episodes in games ``envs``: rebuild their spaces (:meth:`World.rebuild`),
        at the default start or at explicit ``positions`` (one mapping or ``None`` per game,
        metres)."""
        envs = np.atleast_1d(np.asarray(envs, dtype=np.int64))
        placed = list(positions or ())
        starts = [self._start] * len(envs)
        for k, where in enumerate(placed[: len(envs)]):
            if where:  # validate everything before touching any game
                starts[k] = placed_positions(self.scenario, where)
        swapped = False
        for env, xy in zip(envs.tolist(), starts, strict=True):
            if xy is self._start and self._spares:
                self._retired.append(self._worlds[env])
                world = self._worlds[env] = self._spares.pop()
                if self._addresses is not None:
                    self._addresses[env] = world.addresses
                    swapped = True
            else:
                self._worlds[env].rebuild(xy)
            self._state[env, 0], self._state[env, 1] = xy, 0.0
        if swapped:
            self._map()
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
        if self._retired:
            world = self._retired.pop()
            world.rebuild(self._start)
        else:
            world = World(self.scenario, self._start, self._table)
        self._spares.append(world)
        return len(self._spares)

    @property
    def spare_worlds(self) -> int:
        """How many worlds :meth:`build_spare` has prepared that no reset has taken yet."""
        return len(self._spares)

    # ------------------------------------------------------------------ step

    def step(self, actions: np.ndarray, evader_actions: np.ndarray | None = None) -> StepOutcome:
        """Advance every game one control period with the pursuers' ``(B, N)`` actions, or
        their ``(B, N, 2)`` velocity commands with continuous control; ``evader_actions``
        (``(B,)`` or ``(B, 2)``) are a learned evader's, required then and refused otherwise."""
        if self._give is not None:
            self._give(evader_actions)
        elif evader_actions is not None:
            raise refuse_evader_actions(self.scenario)
        n = self.scenario.pursuers
        pos = self._state[:, 0]
        evader = self._evader.moves(self.episode_seed, self.t, pos[:, n], pos[:, :n])
        self.t += 1
        if self._continuous:
            commands = np.concatenate((actions, evader[:, None]), axis=1)
            velocities = clip_to_disc(commands) * self.scenario.physics.max_speed
        else:
            velocities = self._velocities[np.concatenate((actions, evader[:, None]), axis=1)]
        return self._advance(velocities, evader)

    def _advance(self, velocities: np.ndarray, evader: np.ndarray) -> StepOutcome:
        """Step every game with the servo ``velocities`` ``(B, N + 1, 2)``: through the
        bodies' memory where it was found (one scatter steers every control body, one
        gather reads every body), else per body through pymunk. The same numbers either
        way: setting a kinematic body's velocity is only the store (chipmunk wakes dynamic
        bodies alone), and games are independent, so steering all before stepping any
        changes nothing."""
        dt, substeps = self._dt, range(self.scenario.physics.substeps)
        events = []
        if self._addresses is not None:
            self._memory[self._write] = velocities
            space_step = self._cp_step
            for world, step in zip(self._worlds, self.t.tolist(), strict=True):
                space = world.cp_space
                for _ in substeps:
                    space_step(space, dt)
                events.append(world.tracker.end_step(step))
            self._state[:] = self._memory[self._read]
            return self._score(events, evader)
        state = []
        for world, row, step in zip(
            self._worlds, velocities.tolist(), self.t.tolist(), strict=True
        ):
            for steer, v in zip(world.steering, row, strict=True):
                steer(v)
            world_step = world.step
            for _ in substeps:
                world_step(dt)
            events.append(world.tracker.end_step(step))
            for probe in world.probes:
                v = probe()
                state += v.x, v.y
        self._state[:] = np.array(state).reshape(self._state.shape)
        return self._score(events, evader)

    def _score(self, events: list[list], evader: np.ndarray) -> StepOutcome:
        b = self.num_envs
        captured = np.zeros(b, dtype=bool)
        collisions = np.zeros(b, dtype=np.int64)
        walls = np.zeros(b, dtype=np.int64)
        for g, game_events in enumerate(events):
            if game_events:  # most steps of most games have no new contact
                captured[g], collisions[g], walls[g] = count_events(game_events)
        return settle(self.scenario, self.t, captured, collisions, walls, evader, events)

    # ------------------------------------------------------------------ views

    def kinetic_energy(self) -> np.ndarray:
        """Total kinetic energy (J) of each game's agents, ``(B,)``."""
        return 0.5 * self.scenario.physics.mass * (self._state[:, 1] ** 2).sum(axis=(1, 2))
