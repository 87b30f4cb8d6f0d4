"""Foxglove ``SceneUpdate`` messages that draw an episode in Foxglove's 3D panel, built from
the Foxglove SDK's own typed messages (:mod:`foxglove.messages`, protobuf-encoded).

Each frame is self-contained (the arena with its walls and cells, pursuer cubes, the evader
sphere, each agent's trail, a caption, velocity arrows in physics mode, and the contacts of
the step that led to it), so seeking anywhere shows the full scene. Entities keep fixed ids
(``arena``, ``pursuer_0`` …, ``evader``, ``trails``, ``contacts``), so each frame replaces
the previous one; ``contacts`` is empty except on the frame of a capture (a ring around the
evader) or a collision (a marker between the two pursuers), so contacts flash. In a
sensing scenario (SPEC §6b) an entity ``sensing`` (:func:`sensing_primitives`) draws each
pursuer's range faintly and a line from each pursuer that knows the evader to it; without
sensing there is no such entity and the frames are as before. A scenario's obstacles are
part of the ``arena`` entity (physics: their shapes, as the walls; grid: the cells they
block), and differential-drive pursuers' cubes are turned by their headings when the
frame is given them. Units are
metres in frame ``arena``: a grid cell ``(x, y)`` is drawn at its centre
``(x + 0.5, y + 0.5)``, as in :mod:`a2cm_phys.envs.render`.

Over the layout test's 400-line limit since issue 46 (``KEPT_LARGE``): to be split.
"""

from __future__ import annotations

from collections.abc import Iterator
from functools import lru_cache

import numpy as np
from foxglove.messages import (
    ArrowPrimitive,
    Color,
    CubePrimitive,
    CylinderPrimitive,
    LinePrimitive,
    LinePrimitiveLineType,
    Point3,
    Pose,
    Quaternion,
    SceneEntity,
    SceneUpdate,
    SpherePrimitive,
    TextPrimitive,
    Timestamp,
    Vector3,
)

from ..config import Scenario
from ..envs.core import agent_names
from ..envs.render import EVADER_COLOUR, PURSUER_COLOURS, step_contacts
from .masks import in_range
from .runlog import Trajectory, state_masks

FRAME_ID = "arena"
"""The frame every entity is drawn in (set it as the 3D panel's display frame)."""
TRAIL_STATES = 40
"""States of each agent's trail (the path it took to the frame's state, at most)."""

_WALL = 0.15  # drawn wall thickness (m)
_WALL_HEIGHT = 0.3
_CAPTURE_COLOUR = "#f2b701"
_RANGE_ALPHA = 0.12  # a pursuer's sensing range: faint, the agents stay in front
_COLLISION_COLOUR = "#ffe600"


def _rgba(colour: str, alpha: float = 1.0) -> Color:
    value = colour.lstrip("#")
    r, g, b = (int(value[i : i + 2], 16) / 255.0 for i in (0, 2, 4))
    return Color(r=r, g=g, b=b, a=alpha)


def _pose(x: float, y: float, z: float, yaw: float = 0.0) -> Pose:
    # Always an explicit orientation: an unset protobuf quaternion reads as all zeros.
    turn = Quaternion(x=0.0, y=0.0, z=float(np.sin(yaw / 2)), w=float(np.cos(yaw / 2)))
    return Pose(position=Vector3(x=x, y=y, z=z), orientation=turn)


def _cube(
    x: float,
    y: float,
    z: float,
    size: tuple[float, float, float],
    colour: Color,
    yaw: float = 0.0,
):
    return CubePrimitive(
        pose=_pose(x, y, z, yaw), size=Vector3(x=size[0], y=size[1], z=size[2]), color=colour
    )


def _text(x: float, y: float, z: float, text: str, size: float = 0.3) -> TextPrimitive:
    return TextPrimitive(
        pose=_pose(x, y, z), billboard=True, font_size=size, color=_rgba("#000000"), text=text
    )


def _stamp(time_ns: int) -> Timestamp:
    return Timestamp(sec=time_ns // 1_000_000_000, nsec=time_ns % 1_000_000_000)


@lru_cache(maxsize=16)
def _arena(cells: int) -> tuple[list[CubePrimitive], list[LinePrimitive]]:
    """The floor and walls (cubes) and the cells' lines of an arena of ``cells`` × ``cells``
    (made once per size: every frame draws the same)."""
    size = float(cells)
    grey, dark = _rgba("#f2f2f2"), _rgba("#555555")
    half, mid, h = _WALL / 2, size / 2, _WALL_HEIGHT
    long, side = (size + 2 * _WALL, _WALL, h), (_WALL, size, h)
    cubes = [
        _cube(mid, mid, -0.01, (size, size, 0.02), grey),
        _cube(mid, -half, h / 2, long, dark),
        _cube(mid, size + half, h / 2, long, dark),
        _cube(-half, mid, h / 2, side, dark),
        _cube(size + half, mid, h / 2, side, dark),
    ]
    points = []
    for k in range(1, cells):
        for a, b in (((k, 0.0), (k, size)), ((0.0, k), (size, k))):
            points += [Point3(x=a[0], y=a[1], z=0.001), Point3(x=b[0], y=b[1], z=0.001)]
    lines = [
        LinePrimitive(
            type=LinePrimitiveLineType.LineList,
            pose=_pose(0.0, 0.0, 0.0),
            thickness=0.02,
            points=points,
            color=_rgba("#bbbbbb"),
        )
    ]
    return cubes, lines if points else []


def _obstacles(scenario: Scenario) -> dict[str, list]:
    """The obstacles' primitives, as tall as the walls: physics, a cube per box and a
    cylinder per circle; grid, a cube per blocked cell. Empty without obstacles."""
    dark, h = _rgba("#555555"), _WALL_HEIGHT
    if scenario.mode == "grid":
        blocked = np.flatnonzero(scenario.blocked_cells())
        y, x = np.divmod(blocked, scenario.size)
        cells = zip(x.tolist(), y.tolist(), strict=True)
        return {"cubes": [_cube(i + 0.5, j + 0.5, h / 2, (1.0, 1.0, h), dark) for i, j in cells]}
    cubes, cylinders = [], []
    for obstacle in scenario.obstacles:
        if obstacle.shape == "circle":
            d = 2 * float(obstacle.radius)  # type: ignore[arg-type]
            pose = _pose(obstacle.x, obstacle.y, h / 2)
            cylinders.append(CylinderPrimitive(pose=pose, size=Vector3(x=d, y=d, z=h), color=dark))
        else:
            hx, hy = obstacle.half_extents
            cubes.append(_cube(obstacle.x, obstacle.y, h / 2, (2 * hx, 2 * hy, h), dark))
    return {"cubes": cubes, "cylinders": cylinders}


def _entity(entity_id: str, stamp: Timestamp, **primitives: list) -> SceneEntity:
    return SceneEntity(timestamp=stamp, frame_id=FRAME_ID, id=entity_id, **primitives)


def _agent(
    scenario: Scenario, i: int, name: str, x: float, y: float, yaw: float = 0.0
) -> dict[str, list]:
    """The primitives of agent ``i`` at ``(x, y)``: the evader's sphere, or a pursuer's
    cube (turned by ``yaw``, rad) with its number above it."""
    phys = scenario.physics
    if name == "evader":
        d = 2 * phys.evader_radius
        return {
            "spheres": [
                SpherePrimitive(
                    pose=_pose(x, y, phys.evader_radius),
                    size=Vector3(x=d, y=d, z=d),
                    color=_rgba(EVADER_COLOUR),
                )
            ]
        }
    side = phys.box_side
    colour = _rgba(PURSUER_COLOURS[i % len(PURSUER_COLOURS)])
    return {
        "cubes": [_cube(x, y, side / 2, (side, side, side), colour, yaw)],
        "texts": [_text(x, y, side + 0.25, str(i), 0.25)],
    }


def _arrow(x: float, y: float, z: float, vx: float, vy: float) -> list[ArrowPrimitive]:
    """A velocity arrow (none when at rest)."""
    speed = float(np.hypot(vx, vy))
    if speed <= 1e-9:
        return []
    return [
        ArrowPrimitive(
            pose=_pose(x, y, z, float(np.arctan2(vy, vx))),
            shaft_length=0.4 * speed,
            shaft_diameter=0.04,
            head_length=0.1,
            head_diameter=0.1,
            color=_rgba("#000000"),
        )
    ]


def _trails(centres: np.ndarray, z: float) -> list[LinePrimitive]:
    """Each agent's path over ``centres`` ``(T, N + 1, 2)``, a line in its colour."""
    if len(centres) < 2:
        return []
    out = []
    for i in range(centres.shape[1]):
        last = i == centres.shape[1] - 1
        colour = EVADER_COLOUR if last else PURSUER_COLOURS[i % len(PURSUER_COLOURS)]
        points = [Point3(x=float(x), y=float(y), z=z) for x, y in centres[:, i].tolist()]
        out.append(
            LinePrimitive(
                type=LinePrimitiveLineType.LineStrip,
                pose=_pose(0, 0, 0),
                thickness=0.05,
                points=points,
                color=_rgba(colour, 0.5),
            )
        )
    return out


def _contact_marks(scenario: Scenario, centres: np.ndarray, contacts) -> dict[str, list]:
    """A ring around a caught evader, a sphere between two pursuers that collided."""
    marks: dict[str, list] = {"lines": [], "spheres": []}
    if contacts is None:
        return marks
    if contacts.capturers:
        x, y = centres[-1]
        r = scenario.physics.evader_radius + 0.12
        ring = [
            Point3(x=float(x + r * np.cos(a)), y=float(y + r * np.sin(a)), z=0.05)
            for a in np.linspace(0, 2 * np.pi, 24, endpoint=False)
        ]
        marks["lines"].append(
            LinePrimitive(
                type=LinePrimitiveLineType.LineLoop,
                pose=_pose(0, 0, 0),
                thickness=0.08,
                points=ring,
                color=_rgba(_CAPTURE_COLOUR),
            )
        )
    for i, j in contacts.collisions:
        x, y = (centres[i] + centres[j]) / 2
        z = scenario.physics.box_side + 0.1
        marks["spheres"].append(
            SpherePrimitive(
                pose=_pose(float(x), float(y), z),
                size=Vector3(x=0.35, y=0.35, z=0.35),
                color=_rgba(_COLLISION_COLOUR),
            )
        )
    return marks


def _range(scenario: Scenario, i: int, x: float, y: float) -> dict[str, list]:
    """Pursuer ``i``'s sensing range around its centre ``(x, y)``: on grids a flat square
    over the ``(2r + 1)²`` cells around its cell (within the arena), in physics a disc of
    radius ``r`` m with its rim."""
    colour = PURSUER_COLOURS[i % len(PURSUER_COLOURS)]
    r, size = float(scenario.sensing.radius), float(scenario.size)
    if scenario.mode == "grid":
        reach = np.floor(r) + 0.5  # whole cells: Chebyshev distance <= r
        x0, x1 = max(x - reach, 0.0), min(x + reach, size)
        y0, y1 = max(y - reach, 0.0), min(y + reach, size)
        square = (x1 - x0, y1 - y0, 0.004)
        return {
            "cubes": [
                _cube((x0 + x1) / 2, (y0 + y1) / 2, 0.004, square, _rgba(colour, _RANGE_ALPHA))
            ]
        }
    disc = CylinderPrimitive(
        pose=_pose(x, y, 0.004),
        size=Vector3(x=2 * r, y=2 * r, z=0.004),
        bottom_scale=1.0,
        top_scale=1.0,
        color=_rgba(colour, _RANGE_ALPHA),
    )
    rim = [
        Point3(x=float(x + r * np.cos(a)), y=float(y + r * np.sin(a)), z=0.01)
        for a in np.linspace(0, 2 * np.pi, 48, endpoint=False)
    ]
    line = LinePrimitive(
        type=LinePrimitiveLineType.LineLoop,
        pose=_pose(0, 0, 0),
        thickness=0.03,
        points=rim,
        color=_rgba(colour, 0.5),
    )
    return {"cylinders": [disc], "lines": [line]}


def sensing_primitives(
    scenario: Scenario, positions: np.ndarray, masks: np.ndarray
) -> dict[str, list]:
    """The ``sensing`` entity's primitives for a state of a sensing scenario: each pursuer's
    range (:func:`_range`), and a line from each pursuer that knows the evader (``masks``
    ``(N + 1, N + 1)``) to it: opaque when the evader is in its own range, faint when it
    knows it from a teammate (``share``)."""
    centres = centres_of(scenario, positions)
    n = scenario.pursuers
    prims: dict[str, list] = {"cubes": [], "cylinders": [], "lines": []}
    for i in range(n):
        for kind, items in _range(scenario, i, *map(float, centres[i])).items():
            prims[kind] += items
    own = in_range(scenario, positions)
    ex, ey = map(float, centres[n])
    z = scenario.physics.box_side / 2
    for i in np.flatnonzero(np.asarray(masks)[:n, n]):
        x, y = map(float, centres[i])
        colour = PURSUER_COLOURS[i % len(PURSUER_COLOURS)]
        prims["lines"].append(
            LinePrimitive(
                type=LinePrimitiveLineType.LineStrip,
                pose=_pose(0, 0, 0),
                thickness=0.06 if own[i] else 0.03,
                points=[Point3(x=x, y=y, z=z), Point3(x=ex, y=ey, z=z)],
                color=_rgba(colour, 0.9 if own[i] else 0.35),
            )
        )
    return prims


def centres_of(scenario: Scenario, positions: np.ndarray) -> np.ndarray:
    """Positions ``(…, N + 1, 2)`` in metres: cell centres in grid mode."""
    centres = np.asarray(positions, dtype=np.float64)
    return centres + 0.5 if scenario.mode == "grid" else centres


def scene_update(
    scenario: Scenario,
    positions: np.ndarray,
    time_ns: int,
    caption: str = "",
    velocities: np.ndarray | None = None,
    trail: np.ndarray | None = None,
    contacts: object | None = None,
    sensing: np.ndarray | None = None,
    headings: np.ndarray | None = None,
) -> SceneUpdate:
    """One SceneUpdate of a game's ``positions`` ``(N + 1, 2)``; ``trail`` the states that
    led there ``(T, N + 1, 2)`` (the last one ``positions``), ``contacts`` the
    :class:`~a2cm_phys.envs.render.Contacts` of the step that led there, ``sensing`` the
    state's sensing masks ``(N + 1, N + 1)`` (a sensing scenario: ranges and sightings),
    ``headings`` the pursuers' ``(N, 2)`` ``(cos θ, sin θ)`` (differential drive)."""
    stamp = _stamp(time_ns)
    centres = centres_of(scenario, positions)
    cubes, lines = _arena(scenario.size)
    arena: dict[str, list] = {"cubes": cubes, "lines": lines}
    if scenario.obstacles:
        blocks = _obstacles(scenario)
        arena["cubes"] = [*cubes, *blocks["cubes"]]
        if blocks.get("cylinders"):
            arena["cylinders"] = blocks["cylinders"]
    if caption:
        arena["texts"] = [_text(scenario.size / 2, scenario.size + 0.6, 0.5, caption)]
    entities = [_entity("arena", stamp, **arena)]
    side = scenario.physics.box_side
    for i, name in enumerate(agent_names(scenario)):
        x, y = float(centres[i, 0]), float(centres[i, 1])
        yaw = 0.0
        if headings is not None and i < len(headings):
            yaw = float(np.arctan2(headings[i, 1], headings[i, 0]))
        prims = _agent(scenario, i, name, x, y, yaw)
        if velocities is not None:
            prims["arrows"] = _arrow(x, y, side + 0.05, *map(float, velocities[i]))
        entities.append(_entity(name, stamp, **prims))
    drawn = centres[None] if trail is None else centres_of(scenario, trail)
    entities.append(_entity("trails", stamp, lines=_trails(drawn, 0.02)))
    entities.append(_entity("contacts", stamp, **_contact_marks(scenario, centres, contacts)))
    if sensing is not None:
        prims = sensing_primitives(scenario, positions, sensing)
        entities.append(_entity("sensing", stamp, **prims))
    return SceneUpdate(entities=entities)


def episode_frame(scenario: Scenario, traj: Trajectory, k: int, time_ns: int) -> SceneUpdate:
    """The SceneUpdate of state ``k`` of an episode (0: its start), stamped ``time_ns``:
    a caption with the return so far, the trails that led there, the step's contacts (and
    in a sensing scenario the state's ranges and sightings)."""
    contacts, status = None, ""
    if k and (traj.captured[k - 1] or traj.collisions[k - 1]):
        before, after = traj.positions[k - 1], traj.positions[k]
        contacts = step_contacts(scenario, before, after, traj.events, k)
    if k == traj.length:
        status = "  captured" if traj.length and traj.captured[-1] else "  end"
    ret = float(np.sum(traj.reward[:k]))
    caption = f"episode {traj.episode}  step {k}/{traj.length}  return {ret:g}{status}"
    vel = None if traj.velocities is None else traj.velocities[k]
    trail = traj.positions[max(0, k + 1 - TRAIL_STATES) : k + 1]
    masks = state_masks(scenario, traj, k)
    headings = None if traj.headings is None else traj.headings[k]
    return scene_update(
        scenario, traj.positions[k], time_ns, caption, vel, trail, contacts, masks, headings
    )


def episode_frames(scenario: Scenario, traj: Trajectory) -> Iterator[tuple[int, SceneUpdate]]:
    """``(log_time_ns, SceneUpdate)`` of every state of the episode (its start, then after
    each step), timed on the run clock (``t0 + k · dt``)."""
    for k in range(traj.length + 1):
        time_ns = round((traj.t0 + k * traj.dt) * 1e9)
        yield time_ns, episode_frame(scenario, traj, k, time_ns)


def episode_scenes(scenario: Scenario, traj: Trajectory) -> Iterator[tuple[int, bytes]]:
    """``(log_time_ns, protobuf bytes)`` of :func:`episode_frames`: the messages of a
    ``foxglove.SceneUpdate`` channel (see :mod:`.foxglove`)."""
    for time_ns, msg in episode_frames(scenario, traj):
        yield time_ns, msg.encode()
