"""The pymunk worlds of the physics core: one game's space, bodies, shapes, servos and contact
tracking (:class:`World`), and the worlds of a batch of games stepped together
(:class:`Worlds`).

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

Contact callbacks (:meth:`pymunk.Space.on_collision`) run only when shapes begin or stop
touching and feed each world's :class:`~.contacts.ContactTracker`. The frequent operations
go straight to chipmunk where they can (:data:`~.chipmunk.DIRECT_CALLS`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from enum import IntEnum
from itertools import combinations
from typing import Any

import numpy as np
import pymunk

from ..config import Scenario
from .chipmunk import (
    BodyMemory,
    accessor,
    body_addresses,
    contact_callbacks,
    handle_contacts,
    stepper,
    unhook,
)
from .contacts import AGENT_WALL, PURSUER_EVADER, PURSUER_PURSUER, ContactTracker, Pair
from .core import agent_names


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


def pair_table(scenario: Scenario) -> list[list[Pair]]:
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
        self.steering = [accessor(control, "velocity", write=True) for control in self.controls]
        # positions of all agents, then their velocities: the layout of the state array
        self.probes = [
            accessor(body, attr, write=False)
            for attr in ("position", "velocity")
            for body in self.bodies
        ]
        self._placing = [  # what rebuild sets: each body's position and velocity
            (accessor(body, "position", write=True), accessor(body, "velocity", write=True))
            for body in self.bodies
        ]
        self.addresses = body_addresses(self.bodies, self.controls)
        self._max_force = ph.max_force
        self.tracker = ContactTracker()
        self._callbacks = contact_callbacks(self.tracker, table, tags)
        self._hooked: Any = None  # the space's handler, when it calls C callbacks
        self.space: pymunk.Space | None = None
        self.servos: list[pymunk.PivotJoint] = []
        self.rebuild(xy)

    def rebuild(self, xy: np.ndarray) -> None:
        """A new space with every agent at rest at ``xy`` (``(N + 1, 2)`` metres)."""
        old = self.space
        unhook(self._hooked)  # the removals below need not reach the tracker: it is cleared
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
        self._hooked = handle_contacts(space, self._callbacks)
        self.space = space
        self.cp_space = getattr(space, "_space", None)  # chipmunk's handle
        self.step: Callable[[float], None] = stepper(space)

    def __del__(self) -> None:
        unhook(getattr(self, "_hooked", None))


class Worlds:
    """The worlds of ``num_envs`` physics games of one scenario, stepped together.

    Holds one :class:`World` per game (``worlds[env]``), the worlds rebuilt ahead at the
    default ``start`` for later restarts (spares: :meth:`build_spare`), and, where chipmunk's
    memory can be reached (:data:`~.chipmunk.DIRECT_CALLS`), every game's body addresses
    (``addresses``, ``(B, 3, N + 1, 2)``) and one memory view over them, so that a step
    steers every servo with one numpy scatter and reads every body with one gather."""

    def __init__(self, scenario: Scenario, num_envs: int, start: np.ndarray) -> None:
        ph = scenario.physics
        self._scenario = scenario
        self._start = start
        self._table = pair_table(scenario)
        self._dt = ph.dt / ph.substeps
        self._substeps = range(ph.substeps)
        self.worlds = [World(scenario, start, self._table) for _ in range(num_envs)]
        self._spares: list[World] = []  # worlds rebuilt at the default start in advance
        self._retired: list[World] = []  # worlds replaced by spares, to be rebuilt as spares
        self.addresses: np.ndarray | None = None
        self._cp_step = getattr(pymunk.cp, "cpSpaceStep", None)
        if self._cp_step is not None and all(
            world.addresses is not None and world.cp_space is not None for world in self.worlds
        ):
            self.addresses = np.stack([world.addresses for world in self.worlds])
            self._map()

    def __getitem__(self, env: int) -> World:
        return self.worlds[env]

    def __iter__(self) -> Iterator[World]:
        return iter(self.worlds)

    def __len__(self) -> int:
        return len(self.worlds)

    def _map(self) -> None:
        """(Re)make the memory view over every game's bodies and its read/write indices."""
        assert self.addresses is not None
        memory = BodyMemory(self.addresses)
        index = memory.index(self.addresses)
        self._memory = memory.view
        self._read = index[:, :2]  # (B, position|velocity, agent, xy): the state's layout
        self._write = index[:, 2]  # (B, agent, xy): the control bodies' velocities

    def restart(self, envs: Sequence[int], starts: Sequence[np.ndarray | None]) -> None:
        """Put every agent of games ``envs`` at rest in a new space (:meth:`World.rebuild`),
        at the positions ``starts`` gives each (``None``: the default start, where a spare
        world is taken instead when one is waiting)."""
        swapped = False
        for env, xy in zip(envs, starts, strict=True):
            if xy is None and self._spares:
                self._retired.append(self.worlds[env])
                world = self.worlds[env] = self._spares.pop()
                if self.addresses is not None:
                    self.addresses[env] = world.addresses
                    swapped = True
            else:
                self.worlds[env].rebuild(self._start if xy is None else xy)
        if swapped:
            self._map()

    def build_spare(self) -> int:
        """Rebuild one world at the default start for a later :meth:`restart` to take, and
        return how many are waiting (see :meth:`~.physics.PhysicsCore.build_spare`)."""
        if self._retired:
            world = self._retired.pop()
            world.rebuild(self._start)
        else:
            world = World(self._scenario, self._start, self._table)
        self._spares.append(world)
        return len(self._spares)

    @property
    def spare_worlds(self) -> int:
        """How many worlds :meth:`build_spare` has prepared that no restart has taken yet."""
        return len(self._spares)

    def advance(self, velocities: np.ndarray, steps: list[int], state: np.ndarray) -> list[list]:
        """Step every game one control period with the servo ``velocities`` ``(B, N + 1, 2)``,
        write the bodies' positions and velocities to ``state`` ``(B, 2, N + 1, 2)`` and
        return each game's contact events, ``steps`` being the games' step numbers.

        Through the bodies' memory where it was found (one scatter steers every control
        body, one gather reads every body), else per body through pymunk. The same numbers
        either way: setting a kinematic body's velocity is only the store (chipmunk wakes
        dynamic bodies alone), and games are independent, so steering all before stepping
        any changes nothing."""
        dt, substeps = self._dt, self._substeps
        events = []
        if self.addresses is not None:
            self._memory[self._write] = velocities
            space_step = self._cp_step
            for world, step in zip(self.worlds, steps, strict=True):
                space = world.cp_space
                for _ in substeps:
                    space_step(space, dt)
                events.append(world.tracker.end_step(step))
            state[:] = self._memory[self._read]
            return events
        flat = []
        for world, row, step in zip(self.worlds, velocities.tolist(), steps, strict=True):
            for steer, v in zip(world.steering, row, strict=True):
                steer(v)
            world_step = world.step
            for _ in substeps:
                world_step(dt)
            events.append(world.tracker.end_step(step))
            for probe in world.probes:
                v = probe()
                flat += v.x, v.y
        state[:] = np.array(flat).reshape(state.shape)
        return events
