"""Differential drive (``physics.drive = "differential"``): how a pursuer with a heading is
steered at every solver substep, and the non-holonomic constraint that keeps it from
sliding sideways.

A differential-drive pursuer (:mod:`.world`) has a velocity servo, whose target is
``forward × (cos θ, sin θ)``, and a turning motor: the torque ``I (ω − w) / h`` that brings
its angular velocity ``w`` to the commanded turn rate ``ω`` in one substep ``h`` (``I`` its
moment of inertia), clipped to :func:`~.rails.turn_torque`. Both are set before *every*
substep (not once per control period), from the pursuer's heading and spin then. (A torque
rather than a gear-joint servo: the same limit and, unresisted, the same rate from the
next substep on, but no joint for each of the solver's iterations to solve; and not the
angular velocity set outright, which would turn a box into a wall before the contact
solver could stop it.) The constraint is enforced twice at every
substep:

- *in* the solver, by the pursuer's pin joint to its rail, placed and turned to its
  heading before the substep (:mod:`.world`): the contact solver and the constraint are
  solved together, so a pursuer driven at an angle into a wall stops there rather than
  sliding along it, and one pushed from the side is held like a wheeled body;
- *after* it, by giving the pursuer its forward speed along its rail (its velocity's
  part along the heading the substep started with, which the solver held it to) along its
  heading now, turned by the substep: :func:`realign`. The sideways part the iterative
  solver leaves is dropped, the forward speed is kept through a turn as a rolling wheel
  keeps it, and no sideways velocity is ever carried into the next substep, during pushes
  and contacts too.

Only chipmunk's position correction of overlaps (its bias velocity, which resolves a few
millimetres of overlap) may still move a body sideways: dropping it would let bodies sink
into whatever is at their side.

- **Continuous** actions are ``(forward, turn)``, each clipped to ``[-1, 1]``: the targets
  are ``forward · max_speed`` along the heading and ``turn · max_turn_rate``, held for the
  control period.
- **Discrete** moves are turn-then-drive primitives. ``up``, ``down``, ``left``, ``right``
  name a target heading (π/2, −π/2, π, 0). A substep's position update comes before its
  velocity update, so the pursuer will turn by ``w · h`` before the motor acts: at each
  substep the heading error ``e`` is that of this predicted heading, wrapped to
  ``[−π, π)``, and the pursuer turns at
  ``ω = clip(e / h, ±max_turn_rate)`` (the rate that closes it in one substep: it reaches
  the heading exactly, without overshoot, when nothing resists) and drives forward at
  ``max_speed`` only while ``|e| ≤`` :data:`ALIGNED`. ``stay`` commands neither.
"""

from __future__ import annotations

import math
from functools import cache

import numpy as np
import pymunk

from ..config import Scenario
from .rails import turn_torque

ALIGNED = 0.05
"""Heading error (rad, about 3°) within which a discrete move drives forward."""

MOVE_HEADINGS = np.array([math.pi / 2, -math.pi / 2, math.pi, 0.0, 0.0])
"""The target heading (rad) of each discrete move: up, down, left, right (stay: unused)."""

STAY = 4


class DrivePlan:
    """The pursuers' commands of one control period in every game, from their actions:
    ``(B, N, 2)`` ``(forward, turn)`` commands with continuous control, else ``(B, N)``
    moves. :meth:`targets` turns them into one substep's servo targets."""

    __slots__ = (
        "_forward",
        "_h",
        "_heading",
        "_max_speed",
        "_max_turn",
        "_moment",
        "_moving",
        "_torque",
        "_turn",
    )

    def __init__(self, scenario: Scenario, actions: np.ndarray) -> None:
        ph = scenario.physics
        self._h, self._moment, self._torque = _constants(scenario)
        self._max_speed, self._max_turn = ph.max_speed, ph.max_turn_rate
        if scenario.continuous:
            command = np.clip(np.asarray(actions, dtype=np.float64), -1.0, 1.0)
            self._forward = command[..., 0] * ph.max_speed
            self._turn = command[..., 1] * ph.max_turn_rate
            self._heading = None
        else:
            moves = np.asarray(actions, dtype=np.int64)
            self._heading = MOVE_HEADINGS[moves]
            self._moving = moves != STAY

    def targets(
        self, rotation: np.ndarray, angle: np.ndarray, spin: np.ndarray, out: np.ndarray
    ) -> None:
        """Write the next substep's commands to ``out`` ``(3, B, N)``: the velocity servo's
        target ``(vx, vy)`` and the torque, from the pursuers' rotations ``(2, B, N)``
        ``(cos θ, sin θ)``, angles ``θ`` and angular velocities ``(B, N)`` as it starts
        (component first, as :meth:`~.drive_worlds.DriveWorlds.drive` reads them)."""
        if self._heading is None:
            forward, rate = self._forward, self._turn
        else:
            ahead = angle + spin * self._h  # after the next position update
            error = np.remainder(self._heading - ahead + math.pi, 2 * math.pi) - math.pi
            forward = np.where(self._moving & (np.abs(error) <= ALIGNED), self._max_speed, 0.0)
            rate = np.clip(error / self._h, -self._max_turn, self._max_turn) * self._moving
        np.multiply(forward, rotation, out=out[:2])
        torque = np.subtract(rate, spin, out=out[2])
        torque *= self._moment
        np.clip(torque, -self._torque, self._torque, out=torque)


@cache
def _constants(scenario: Scenario) -> tuple[float, float, float]:
    """A scenario's substep ``h`` (s), moment of inertia over ``h`` and torque limit."""
    ph = scenario.physics
    h = ph.dt / ph.substeps
    return h, pymunk.moment_for_box(ph.mass, (ph.box_side, ph.box_side)) / h, turn_torque(scenario)


def realign(
    velocity: np.ndarray, before: np.ndarray, after: np.ndarray, out: np.ndarray | None = None
) -> np.ndarray:
    """Velocities ``(2, ...)`` (component first) after a substep, made ``(v · u₀) u₁``:
    their forward speed along the headings ``before`` the substep ``u₀`` (unit ``(cos θ,
    sin θ)``, ``(2, ...)``), along the headings ``after`` it ``u₁`` (written to ``out`` if
    given)."""
    along = velocity[0] * before[0]
    along += velocity[1] * before[1]
    return np.multiply(along, after, out=out)


def lateral_speed(velocity: np.ndarray, rotation: np.ndarray) -> np.ndarray:
    """The speed across the heading ``|v × u|`` of velocities ``(..., 2)`` at headings
    ``(..., 2)`` (zero after :func:`realign`, to rounding; components last, as the core's
    ``velocities()`` and ``headings()`` give them)."""
    return np.abs(velocity[..., 1] * rotation[..., 0] - velocity[..., 0] * rotation[..., 1])
