"""A differential-drive pursuer's rail (:class:`Rails`): what holds it to its heading inside
the solver, and the per-body calls that steer and turn it where chipmunk's memory cannot
be reached.

A rail is a kinematic body outside the space like the control bodies, placed on the
pursuer and turned to its heading before every substep, with a :class:`pymunk.PinJoint`
(``max_bias = 0``, unlimited force) from a point :data:`ACROSS` metres to the rail's left
to the pursuer's centre. The rail does not move, and the pin holds the rate of change of
that distance at zero: it forbids the pursuer's velocity across its heading, inside the
solver, together with the contacts (a one-axis joint, cheaper than a groove). The pursuer
is turned by a torque-limited motor, at most :func:`turn_torque` (:mod:`.drive`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

import pymunk

from ..config import Scenario
from .chipmunk import accessor, drive_addresses

ACROSS = 1e3
"""How far (m) across its heading a pursuer's pin is anchored on its rail: so far that the
pursuer's motion within a substep (a few centimetres) turns the pin's line by some 1e-5
rad at most, while the anchor's rounding stays near 1e-13 m."""


class Turning(NamedTuple):
    """A differential-drive pursuer's per-body calls (:func:`~.chipmunk.accessor`): what
    :class:`~.drive_worlds.DriveWorlds` reads and writes each substep where memory cannot
    be reached, and what :meth:`World.rebuild` resets."""

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


class Rails:
    """The rails of one world's differential-drive pursuers: a kinematic rail body per
    pursuer (``bodies``), each pursuer's calls (``turning``, :class:`Turning`), their
    memory addresses where chipmunk's memory can be reached (``addresses``, see
    :func:`~.chipmunk.drive_addresses`) and the pins of the current space (``pins``)."""

    __slots__ = ("addresses", "bodies", "pins", "turning")

    def __init__(self, pursuers: Sequence[pymunk.Body], controls: Sequence[pymunk.Body]) -> None:
        self.bodies = [pymunk.Body(body_type=pymunk.Body.KINEMATIC) for _ in pursuers]
        self.addresses = drive_addresses(pursuers, self.bodies)
        self.turning: list[Turning] = []
        for body, control, rail in zip(pursuers, controls, self.bodies, strict=True):
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
        self.pins: list[pymunk.PinJoint] = []

    def rest(self) -> None:
        """Every pursuer at heading 0 (+x, the transform follows), not spinning, no torque,
        and its rail unturned: before the shapes enter a new space, which caches their
        pose."""
        for io in self.turning:
            io.set_angle(0.0)
            io.set_spin(0.0)
            io.set_torque(0.0)
            io.turn_rail(0.0)

    def attach(self, space: pymunk.Space, pursuers: Sequence[pymunk.Body]) -> None:
        """Put each rail on its pursuer and pin them together in ``space``."""
        self.pins = []
        for body, rail, io in zip(pursuers, self.bodies, self.turning, strict=True):
            io.place_rail(tuple(body.position))  # where every step's first substep puts it
            # Blind to the pin's length (max_bias = 0): it only stops sideways motion.
            pin = pymunk.PinJoint(rail, body, (0.0, ACROSS), (0.0, 0.0))
            pin.max_bias = 0.0
            space.add(pin)
            self.pins.append(pin)
