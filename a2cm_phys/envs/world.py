"""The pymunk world of one physics game: its space, bodies, shapes, servos and contact
tracking (:class:`World`); the worlds of a batch of games stepped together are
:mod:`.worlds`'.

Walls are four static boxes outside ``[0, size]²`` (inner edges on the boundary), the
scenario's obstacles static boxes and discs inside it (:mod:`.obstacles`), pursuers
dynamic square boxes, the evader a dynamic disc, all with rotation locked but for
differential-drive pursuers (``physics.drive = "differential"``), whose rotation is free.
Such a pursuer is turned by a torque-limited motor: before every substep it is given the
torque that brings its angular velocity to the commanded turn rate within the substep, at
most :func:`turn_torque` (:mod:`.drive`); chipmunk applies it before solving the contacts,
which may then stop the turn, so a box is never turned into a wall. It also has a *rail*:
a kinematic body outside the space like the control bodies, placed on the pursuer and
turned to its heading before every substep, and a :class:`pymunk.PinJoint` (``max_bias =
0``, unlimited force) from a point :data:`ACROSS` metres to the rail's left to the
pursuer's centre. The rail does not move, and the pin holds the rate of change of that
distance at zero: it forbids the pursuer's velocity across its heading, inside the
solver, together with the contacts (a one-axis joint, cheaper than a groove). Each agent is
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

from collections.abc import Callable
from enum import IntEnum
from itertools import combinations
from typing import Any, NamedTuple

import numpy as np
import pymunk

from ..config import Scenario
from .chipmunk import (
    accessor,
    body_addresses,
    contact_callbacks,
    drive_addresses,
    handle_contacts,
    stepper,
    unhook,
)
from .contacts import (
    AGENT_OBSTACLE,
    AGENT_WALL,
    PURSUER_EVADER,
    PURSUER_PURSUER,
    ContactTracker,
    Pair,
)
from .core import agent_names
from .obstacles import obstacle_shape


class CollisionType(IntEnum):
    """pymunk collision types of the shapes. Our one contact handler is a wildcard that tells
    shapes apart by identity; the types say what a shape is, to pymunk's debug tools and to
    handlers a user adds for a pair of them."""

    PURSUER = 1
    EVADER = 2
    WALL = 3
    OBSTACLE = 4


COLLISION_SLOP = 0.01
"""Allowed overlap (m) before the solver pushes shapes apart; pymunk's default, 0.1, is sized
for pixels and would let 0.6 m boxes sink 10 cm into each other."""


def pair_table(scenario: Scenario) -> list[list[Pair]]:
    """``table[i][j]``: the contact pair of shapes tagged ``i`` and ``j`` (agents ``0 … N``,
    ``N + 1`` the wall, ``N + 2`` any obstacle), in canonical order: lower pursuer first,
    agents before the wall and obstacles."""
    names = [*agent_names(scenario), "wall", "obstacle"]
    n = scenario.pursuers
    # The diagonal (a shape with itself) never touches, nor do two static shapes: those
    # pairs are not handled.
    table: list[list[Pair]] = [[("", "", "")] * (n + 3) for _ in range(n + 3)]
    for i, j in combinations(range(n + 2), 2):
        kind = PURSUER_PURSUER if j < n else PURSUER_EVADER if j == n else AGENT_WALL
        table[i][j] = table[j][i] = (kind, names[i], names[j])
    for i in range(n + 1):
        table[i][n + 2] = table[n + 2][i] = (AGENT_OBSTACLE, names[i], "obstacle")
    return table


ACROSS = 1e3
"""How far (m) across its heading a pursuer's pin is anchored on its rail: so far that the
pursuer's motion within a substep (a few centimetres) turns the pin's line by some 1e-5
rad at most, while the anchor's rounding stays near 1e-13 m."""


class Turning(NamedTuple):
    """A differential-drive pursuer's per-body calls (:func:`~.chipmunk.accessor`): what
    :class:`~.worlds.Worlds` reads and writes each substep where memory cannot be reached,
    and what :meth:`World.rebuild` resets."""

    velocity: Callable[[], Any]
    rotation: Callable[[], Any]
    position: Callable[[], Any]
    angle: Callable[[], float]
    spin: Callable[[], float]
    set_velocity: Callable[[Any], None]
    steer: Callable[[Any], None]
    set_torque: Callable[[float], None]
    turn_rail: Callable[[float], None]
    place_rail: Callable[[Any], None]
    set_angle: Callable[[float], None]
    set_spin: Callable[[float], None]


def turn_torque(scenario: Scenario) -> float:
    """The turning motor's torque limit (N·m) of a differential-drive pursuer: the force
    limit ``max_force`` at the box's edge, half a side from its centre."""
    return scenario.physics.max_force * scenario.physics.box_side / 2


class World:
    """One game: its bodies, shapes, servos and contact tracker, and the space they live in.

    The pymunk objects are built once; the space is not. :meth:`rebuild` (called by every
    reset) moves them, at rest at their start, into a brand-new :class:`pymunk.Space` with
    new servo joints. A new chipmunk space remembers nothing: no contact cache, no warm-start
    impulses, fresh spatial indexes, and shape ids counted from zero in the same insertion
    order, so an episode does not depend on the ones before it (bit-identity with a world
    that was never used is tested). What the reused objects carry is reset explicitly:
    positions and velocities, and chipmunk's position-correction velocity, which is cleared
    by integrating positions over ``dt = 0``. Forces need nothing (none is ever applied), nor
    do angles and spins where rotation is locked; a differential-drive pursuer's heading,
    spin and commanded turn are set back to 0, and its turning servo is new too. Rebuilding
    this way costs a third to a half of building every object anew and collecting the old
    ones, which is mostly pymunk's per-object Python bookkeeping (measured in
    ``BENCHMARKS.md``).

    Shapes keep pymunk's default friction and elasticity, both 0: agents slide along walls
    and each other without bouncing, and the servo plays the part of floor friction.

    Over the layout test's size limit since issue 46 (``KEPT_LARGE``): to be split."""

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
        "drive_addresses",
        "pins",
        "probes",
        "rails",
        "servos",
        "space",
        "steering",
        "step",
        "tracker",
        "turning",
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
        for obstacle in scenario.obstacles:  # static like the walls, added with them
            block = obstacle_shape(obstacle, self._static)
            block.collision_type = CollisionType.OBSTACLE
            tags[block] = n + 2
            self._walls.append(block)
        differential = ph.drive == "differential"
        turning_moment = pymunk.moment_for_box(ph.mass, (ph.box_side, ph.box_side))
        self.bodies: list[pymunk.Body] = []
        self._shapes: list[pymunk.Shape] = []
        self.controls: list[pymunk.Body] = []
        for i in range(n + 1):
            turns = differential and i < n
            body = pymunk.Body(ph.mass, turning_moment if turns else float("inf"))
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
        self.drive_addresses = None
        self.rails: list[pymunk.Body] = []
        self.turning: list[Turning] = []  # differential drive: each pursuer's calls
        if differential:
            self.rails = [pymunk.Body(body_type=pymunk.Body.KINEMATIC) for _ in range(n)]
            pursuers = self.bodies[:n], self.controls[:n], self.rails
            self.drive_addresses = drive_addresses(self.bodies[:n], self.rails)
            for body, control, rail in zip(*pursuers, strict=True):
                self.turning.append(
                    Turning(
                        accessor(body, "velocity", write=False),
                        accessor(body, "rotation_vector", write=False),
                        accessor(body, "position", write=False),
                        accessor(body, "angle", write=False),
                        accessor(body, "angular_velocity", write=False),
                        accessor(body, "velocity", write=True),
                        accessor(control, "velocity", write=True),
                        accessor(body, "torque", write=True),
                        accessor(rail, "angle", write=True),
                        accessor(rail, "position", write=True),
                        accessor(body, "angle", write=True),
                        accessor(body, "angular_velocity", write=True),
                    )
                )
        self.tracker = ContactTracker()
        self._callbacks = contact_callbacks(self.tracker, table, tags)
        self._hooked: Any = None  # the space's handler, when it calls C callbacks
        self.space: pymunk.Space | None = None
        self.servos: list[pymunk.PivotJoint] = []
        self.pins: list[pymunk.PinJoint] = []
        self.rebuild(xy)

    def rebuild(self, xy: np.ndarray) -> None:
        """A new space with every agent at rest at ``xy`` (``(N + 1, 2)`` metres)."""
        old = self.space
        unhook(self._hooked)  # the removals below need not reach the tracker: it is cleared
        if old is not None:  # release the objects (pymunk's separate callbacks still fire)
            joints = (*self.servos, *self.pins)
            old.remove(*self._walls, *self._shapes, *joints, *self.bodies)
            old.remove(self._static)
        for io in self.turning:  # before the shapes enter the space, which caches their pose
            io.set_angle(0.0)  # heading 0 (+x, the transform follows), not spinning
            io.set_spin(0.0)
            io.set_torque(0.0)
            io.turn_rail(0.0)
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
        self.pins = []
        k = len(self.rails)  # the differential-drive pursuers (none: holonomic)
        for body, rail, io in zip(self.bodies[:k], self.rails, self.turning, strict=True):
            io.place_rail(tuple(body.position))  # where every step's first substep puts it
            # Blind to the pin's length (max_bias = 0): it only stops sideways motion.
            pin = pymunk.PinJoint(rail, body, (0.0, ACROSS), (0.0, 0.0))
            pin.max_bias = 0.0
            space.add(pin)
            self.pins.append(pin)
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
