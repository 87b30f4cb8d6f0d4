"""The pymunk world of one physics game: its space, bodies, shapes, servos and contact
tracking (:class:`World`); the worlds of a batch of games stepped together are
:mod:`.worlds`'.

Walls are four static boxes outside ``[0, size]²`` (inner edges on the boundary), the
scenario's obstacles static boxes and discs inside it (:mod:`.obstacles`), pursuers
dynamic square boxes, the evader a dynamic disc, all with rotation locked but for
differential-drive pursuers (``physics.drive = "differential"``), whose rotation is free.
Such a pursuer is turned by a torque-limited motor: before every substep it is given the
torque that brings its angular velocity to the commanded turn rate within the substep, at
most :func:`~.rails.turn_torque` (:mod:`.drive`); chipmunk applies it before solving the contacts,
which may then stop the turn, so a box is never turned into a wall. It also has a *rail*
(:mod:`.rails`) that forbids its velocity across its heading inside the solver. Each agent is
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
from typing import Any

import numpy as np
import pymunk

from ..config import Scenario
from .chipmunk import (
    accessor,
    body_addresses,
    contact_callbacks,
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
from .rails import Rails


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


def static_shapes(scenario: Scenario, static: pymunk.Body) -> list[pymunk.Shape]:
    """The arena's static shapes on ``static``: the four walls, boxes ``wall_thickness``
    thick outside ``[0, size]²``, then the scenario's obstacles."""
    size, t = float(scenario.size), scenario.physics.wall_thickness
    shapes: list[pymunk.Shape] = []
    for x0, y0, x1, y1 in (
        (-t, -t, 0.0, size + t),  # left
        (size, -t, size + t, size + t),  # right
        (0.0, -t, size, 0.0),  # bottom
        (0.0, size, size, size + t),  # top
    ):
        wall = pymunk.Poly(static, [(x0, y0), (x1, y0), (x1, y1), (x0, y1)])
        wall.collision_type = CollisionType.WALL
        shapes.append(wall)
    for obstacle in scenario.obstacles:  # static like the walls, added with them
        block = obstacle_shape(obstacle, static)
        block.collision_type = CollisionType.OBSTACLE
        shapes.append(block)
    return shapes


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

    With differential drive ``rails`` holds the pursuers' rails (:class:`~.rails.Rails`),
    ``turning`` their calls and ``drive_addresses`` their memory addresses (else ``None``,
    ``[]`` and ``None``)."""

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
        ph, n = scenario.physics, scenario.pursuers
        self._static = pymunk.Body(body_type=pymunk.Body.STATIC)
        self._walls = static_shapes(scenario, self._static)
        tags = {  # shape -> row of the pair table
            shape: n + 1 if shape.collision_type == CollisionType.WALL else n + 2
            for shape in self._walls
        }
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
        self.rails = Rails(self.bodies[:n], self.controls[:n]) if differential else None
        self.turning = [] if self.rails is None else self.rails.turning
        self.drive_addresses = None if self.rails is None else self.rails.addresses
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
        rails = self.rails
        if old is not None:  # release the objects (pymunk's separate callbacks still fire)
            joints = (*self.servos, *(() if rails is None else rails.pins))
            old.remove(*self._walls, *self._shapes, *joints, *self.bodies)
            old.remove(self._static)
        if rails is not None:
            rails.rest()
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
        if rails is not None:
            rails.attach(space, self.bodies[: len(rails.bodies)])
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
