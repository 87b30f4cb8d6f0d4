"""Direct calls into chipmunk, the C library beneath pymunk, for the physics core's hot paths.

Each function here hands back chipmunk's own C call when this pymunk exposes it and
:data:`DIRECT_CALLS` is on, else the pymunk API call that does the same: stepping a space,
reading and setting a body's position and velocity, one numpy view over many bodies'
memory (:class:`BodyMemory`), and contact callbacks set straight into chipmunk's handler.
Which path was taken never changes a trajectory, only its cost.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from functools import cache, partial
from typing import Any

import numpy as np
import pymunk

from .contacts import ContactTracker, Pair

DIRECT_CALLS = True
"""Make the frequent operations go straight to chipmunk when this pymunk allows it, instead
of through pymunk's Python wrappers of the same calls:

- stepping a space, placing a body at a reset: chipmunk's C functions;
- steering the servos and reading the bodies: one numpy scatter and one gather per step
  over every game, in chipmunk's memory (:class:`BodyMemory`; the offsets of ``cpBody``'s
  position and velocity are checked once against chipmunk's getters and setters,
  :func:`body_layout`, else each body is read and steered by a C call);
- contacts: C callbacks set in chipmunk's own handler (:func:`handle_contacts`), which
  find their two shapes with ``cpArbiterGetShapes``, without pymunk's dispatcher.

The wrappers add bookkeeping for objects added or removed from callbacks, which ours never
do, and Python attribute machinery and allocations: they cost as much as the simulation
itself. Trajectories are the same bit for bit (tested with this off). Creating pymunk objects
and adding them to or removing them from spaces always goes through pymunk's API."""


def stepper(space: pymunk.Space) -> Callable[[float], None]:
    """A function advancing ``space`` by ``dt`` (:meth:`pymunk.Space.step`, or chipmunk's
    ``cpSpaceStep`` directly: see :data:`DIRECT_CALLS`)."""
    cp_space = getattr(space, "_space", None)
    if DIRECT_CALLS and hasattr(pymunk.cp, "cpSpaceStep") and cp_space is not None:
        return partial(pymunk.cp.cpSpaceStep, cp_space)
    return space.step


_ATTRIBUTES = {
    "position": "Position",
    "velocity": "Velocity",
    "angle": "Angle",
    "angular_velocity": "AngularVelocity",
    "rotation_vector": "Rotation",
    "torque": "Torque",
}
"""pymunk's :class:`~pymunk.Body` attributes that :func:`accessor` reaches, and the names of
chipmunk's getters and setters of each (``cpBodyGet…``, ``cpBodySet…``)."""


def accessor(body: pymunk.Body, attr: str, write: bool) -> Callable[..., Any]:
    """A function reading (no argument) or writing (one) ``body.<attr>``, one of
    :data:`_ATTRIBUTES` (``rotation_vector``, ``(cos θ, sin θ)``, is read only): chipmunk's
    getter or setter called directly on the body's C handle, or pymunk's property (see
    :data:`DIRECT_CALLS`). Read vectors have ``x`` and ``y``."""
    name = f"cpBody{'Set' if write else 'Get'}{_ATTRIBUTES[attr]}"
    c_function, cp_body = getattr(pymunk.cp, name, None), getattr(body, "_body", None)
    if DIRECT_CALLS and c_function is not None and cp_body is not None:
        return partial(c_function, cp_body)
    return partial(setattr if write else getattr, body, attr)


_CENTRE_AT = 64
"""Byte offset in chipmunk's ``cpBody`` of ``p`` (then its ``y``), its centre of gravity:
what joints read as the body's position (``cpBodySetPosition`` sets it and the transform)."""
_POSITION_AT = 168
"""Byte offset in chipmunk's ``cpBody`` of ``transform.tx`` (then ``ty``): the position
``cpBodyGetPosition`` returns (the transform's origin; every body here has its centre of
gravity at its centre and no rotation, so this is ``body->p`` too)."""
_VELOCITY_AT = 80
"""Byte offset in chipmunk's ``cpBody`` of ``v`` (then its ``y``), the velocity that
``cpBodyGetVelocity`` returns and ``cpBodySetVelocity`` sets."""
_ANGLE_AT = 112
"""Byte offset in chipmunk's ``cpBody`` of ``a``, the angle (rad) ``cpBodyGetAngle`` returns,
then of ``w``, the angular velocity ``cpBodyGetAngularVelocity`` returns and
``cpBodySetAngularVelocity`` sets."""
_TORQUE_AT = 128
"""Byte offset in chipmunk's ``cpBody`` of ``t``, the torque ``cpBodySetTorque`` sets (the
next step's velocity update applies it, then sets it back to 0)."""
_ROTATION_AT = 136
"""Byte offset in chipmunk's ``cpBody`` of its transform's ``a``, ``b``, ``c``, ``d``: ``(cos
a, sin a, −sin a, cos a)``, ``(a, b)`` the rotation ``cpBodyGetRotation`` returns (then come
``tx``, ``ty``: :data:`_POSITION_AT`)."""


@cache
def body_layout() -> bool:
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
        memory = BodyMemory(addresses)
        position, velocity, steer = memory.index(addresses)
        memory.view[steer[0]] = (-0.625, 0.25)  # as the core steers
        space.step(0.05)
        got = [memory.view[index[0]].tolist() for index in (position, velocity, steer)]
        return got == [list(body.position), list(body.velocity), list(control.velocity)]
    except Exception:
        return False


def body_addresses(
    bodies: Sequence[pymunk.Body], controls: Sequence[pymunk.Body]
) -> np.ndarray | None:
    """Byte addresses ``(3, N + 1, 2)`` of the bodies' positions and velocities and of the
    control bodies' velocities in chipmunk's memory, for :class:`BodyMemory` (see
    :data:`DIRECT_CALLS`); ``None`` where they cannot be used."""
    if not DIRECT_CALLS or not body_layout():
        return None
    return _raw_addresses(bodies, controls)


def _raw_addresses(bodies: Sequence[pymunk.Body], controls: Sequence[pymunk.Body]) -> np.ndarray:
    """:func:`body_addresses`, unchecked."""
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


DRIVE_COLUMNS = (
    *("pursuer",) * 8,  # transform (a, b, c, d, tx, ty), angle, angular velocity
    "torque",  # the pursuer's torque: what turns it
    *("rail",) * 6,  # its rail's rotation (a, b, c, d) and centre p (x, y)
)
"""What the 15 addresses per pursuer of :func:`drive_addresses` hold: the pursuer body's
transform ``(a, b, c, d, tx, ty) = (cos θ, sin θ, −sin θ, cos θ, x, y)``, its angle ``θ``,
angular velocity and torque; its rail body's rotation and centre, all its pin joint reads
of it (:mod:`.world`), in the order of the pursuer's first six."""


@cache
def rotation_layout() -> bool:
    """Whether this chipmunk's ``cpBody`` keeps angles, angular velocities, torques,
    transforms and centres at :data:`_ANGLE_AT`, :data:`_TORQUE_AT`, :data:`_ROTATION_AT`
    and :data:`_CENTRE_AT` (with :func:`body_layout`'s positions and velocities), checked
    once on a spinning probe body stepped in a space against chipmunk's getters and
    setters: a torque written through memory must turn it as ``cpBodySetTorque`` turns
    its twin, and a rail given the probe's rotation and centre through memory must hold
    what ``cpBodySetAngle`` and ``cpBodySetPosition`` give another. Where it fails,
    differential drive keeps the per-body calls."""
    if not body_layout():
        return False
    try:
        probes, spaces = [], []
        for _ in range(2):
            body = pymunk.Body(1.0, pymunk.moment_for_box(1.0, (0.5, 0.5)))
            space = pymunk.Space()
            space.add(body, pymunk.Poly.create_box(body, (0.5, 0.5)))
            body.position, body.velocity = (1.25, -3.5), (0.375, 7.0)
            body.angle, body.angular_velocity = 0.75, -1.5
            probes.append(body)
            spaces.append(space)
        body, twin = probes
        rail, other = (pymunk.Body(body_type=pymunk.Body.KINEMATIC) for _ in range(2))
        at = _raw_drive_addresses([body], [rail])[0]
        other_at = _raw_drive_addresses([twin], [other])[0]
        memory = BodyMemory(np.concatenate((at, other_at)))
        index, other_index = memory.index(at), memory.index(other_at)
        view = memory.view
        view[index[8]] = 2.5  # as the core turns a pursuer
        twin.torque = 2.5
        for space in spaces:
            space.step(0.05)
        view[index[9:]] = view[index[:6]]  # as the core places and turns a rail
        other.angle, other.position = body.angle, body.position
        (x, y), (cx, cy) = body.rotation_vector, body.position
        got = view[index].tolist()
        want = [x, y, -y, x, cx, cy, body.angle, body.angular_velocity, 0.0]
        turned = body.angular_velocity == twin.angular_velocity != -1.5
        return got[:9] == want and turned and view[other_index[9:]].tolist() == got[9:]
    except Exception:
        return False


def drive_addresses(
    bodies: Sequence[pymunk.Body], rails: Sequence[pymunk.Body]
) -> np.ndarray | None:
    """Byte addresses ``(N, 15)`` for differential drive (:class:`BodyMemory`), per
    pursuer :data:`DRIVE_COLUMNS`, of the pursuers' ``bodies`` and their ``rails``;
    ``None`` where they cannot be used (see :data:`DIRECT_CALLS`, :func:`rotation_layout`)."""
    if not DIRECT_CALLS or not rotation_layout():
        return None
    return _raw_drive_addresses(bodies, rails)


def _raw_drive_addresses(bodies: Sequence[pymunk.Body], rails: Sequence[pymunk.Body]) -> np.ndarray:
    """:func:`drive_addresses`, unchecked."""

    def at(group: Sequence[pymunk.Body]) -> np.ndarray:
        return np.array([int(pymunk.ffi.cast("uintptr_t", b._body)) for b in group])[:, None]

    words = 8 * np.arange(6, dtype=np.int64)
    body, rail = at(bodies), at(rails)
    return np.concatenate(
        (
            body + _ROTATION_AT + words,
            body + _ANGLE_AT + words[:2],
            body + _TORQUE_AT,
            rail + _ROTATION_AT + words[:4],
            rail + _CENTRE_AT + words[:2],
        ),
        axis=1,
    ).astype(np.int64)


class BodyMemory:
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


def contact_callbacks(
    tracker: ContactTracker, table: list[list[Pair]], tags: dict[pymunk.Shape, int]
) -> tuple[Any, Any, bool]:
    """The begin/separate callbacks of one world's spaces, and whether they are chipmunk's
    own (C function pointers for :func:`handle_contacts`) rather than pymunk's. They only
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


def handle_contacts(space: pymunk.Space, callbacks: tuple[Any, Any, bool]) -> Any:
    """Give ``space`` one wildcard contact handler with the ``begin`` and ``separate``
    callbacks of :func:`contact_callbacks`: set straight into chipmunk's handler when they
    are C callbacks (what pymunk's ``on_collision`` does, without its per-call dispatcher; the
    handler is returned, with chipmunk's default callbacks, for :func:`unhook`), else
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


def unhook(hooked: Any) -> None:
    """Give a handler of :func:`handle_contacts` back chipmunk's default callbacks, so that
    its space never calls C callbacks that may be freed before it (pymunk removes the
    shapes of a space it frees, which calls ``separate``)."""
    if hooked is not None:
        handler, (begin, separate) = hooked
        handler.beginFunc, handler.separateFunc = begin, separate
