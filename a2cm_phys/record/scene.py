"""Foxglove ``SceneUpdate`` messages that draw an episode in Foxglove's 3D panel, built from
the Foxglove SDK's own typed messages (:mod:`foxglove.messages`, protobuf-encoded).

Each frame is self-contained (the arena with its walls and cells, pursuer cubes, the evader
sphere, each agent's trail, a caption, velocity arrows in physics mode, and the contacts of
the step that led to it), so seeking anywhere shows the full scene. Entities keep fixed ids
(``arena``, ``pursuer_0`` …, ``evader``, ``trails``, ``contacts``), so each frame replaces
the previous one; ``contacts`` is empty except on the frame of a capture (a ring around the
evader) or a collision (a marker between the two pursuers), so contacts flash.

- A scenario's obstacles are part of the ``arena`` entity (physics: their shapes, as the
  walls; grid: the cells they block; :mod:`.scene_shapes`).
- Differential-drive pursuers' cubes are turned by their headings, and each carries an
  arrow in its colour along its heading.
- In a sensing scenario an entity ``sensing`` (:func:`~.scene_sensing.sensing_primitives`)
  draws each pursuer's range faintly, a line from each pursuer that knows the evader to it,
  and the range sensor's rays where it has them; without sensing there is no such entity
  and the frames are as before.

Units are metres in frame ``arena``: a grid cell ``(x, y)`` is drawn at its centre
``(x + 0.5, y + 0.5)``, as in :mod:`a2cm_phys.envs.render`.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
from foxglove.messages import (
    ArrowPrimitive,
    LinePrimitive,
    LinePrimitiveLineType,
    Point3,
    SceneEntity,
    SceneUpdate,
    SpherePrimitive,
    Timestamp,
    Vector3,
)

from ..config import Scenario
from ..envs.core import agent_names
from ..envs.render import EVADER_COLOUR, PURSUER_COLOURS, step_contacts
from .runlog import Trajectory, state_masks
from .scene_sensing import sensing_primitives
from .scene_shapes import (
    arena_primitives,
    centres_of,
    cube,
    line,
    obstacle_primitives,
    pose,
    rgba,
    stamp,
    text,
)

FRAME_ID = "arena"
"""The frame every entity is drawn in (set it as the 3D panel's display frame)."""
TRAIL_STATES = 40
"""States of each agent's trail (the path it took to the frame's state, at most)."""

_CAPTURE_COLOUR = "#f2b701"
_COLLISION_COLOUR = "#ffe600"


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
                    pose=pose(x, y, phys.evader_radius),
                    size=Vector3(x=d, y=d, z=d),
                    color=rgba(EVADER_COLOUR),
                )
            ]
        }
    side = phys.box_side
    colour = rgba(PURSUER_COLOURS[i % len(PURSUER_COLOURS)])
    return {
        "cubes": [cube(x, y, side / 2, (side, side, side), colour, yaw)],
        "texts": [text(x, y, side + 0.25, str(i), 0.25)],
    }


def _arrow(x: float, y: float, z: float, vx: float, vy: float) -> list[ArrowPrimitive]:
    """A velocity arrow (none when at rest)."""
    speed = float(np.hypot(vx, vy))
    if speed <= 1e-9:
        return []
    return [
        ArrowPrimitive(
            pose=pose(x, y, z, float(np.arctan2(vy, vx))),
            shaft_length=0.4 * speed,
            shaft_diameter=0.04,
            head_length=0.1,
            head_diameter=0.1,
            color=rgba("#000000"),
        )
    ]


def _heading_arrow(scenario: Scenario, i: int, x: float, y: float, yaw: float) -> ArrowPrimitive:
    """Pursuer ``i``'s heading: an arrow in its colour from its centre, on top of its cube,
    to beyond its front face."""
    side = scenario.physics.box_side
    return ArrowPrimitive(
        pose=pose(x, y, side + 0.01, yaw),
        shaft_length=0.5 * side,
        shaft_diameter=0.06,
        head_length=0.2,
        head_diameter=0.16,
        color=rgba(PURSUER_COLOURS[i % len(PURSUER_COLOURS)]),
    )


def _trails(centres: np.ndarray, z: float) -> list[LinePrimitive]:
    """Each agent's path over ``centres`` ``(T, N + 1, 2)``, a line in its colour."""
    if len(centres) < 2:
        return []
    out = []
    for i in range(centres.shape[1]):
        last = i == centres.shape[1] - 1
        colour = EVADER_COLOUR if last else PURSUER_COLOURS[i % len(PURSUER_COLOURS)]
        points = [Point3(x=float(x), y=float(y), z=z) for x, y in centres[:, i].tolist()]
        out.append(line(LinePrimitiveLineType.LineStrip, points, 0.05, rgba(colour, 0.5)))
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
                pose=pose(0, 0, 0),
                thickness=0.08,
                points=ring,
                color=rgba(_CAPTURE_COLOUR),
            )
        )
    for i, j in contacts.collisions:
        x, y = (centres[i] + centres[j]) / 2
        z = scenario.physics.box_side + 0.1
        marks["spheres"].append(
            SpherePrimitive(
                pose=pose(float(x), float(y), z),
                size=Vector3(x=0.35, y=0.35, z=0.35),
                color=rgba(_COLLISION_COLOUR),
            )
        )
    return marks


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
    when = stamp(time_ns)
    centres = centres_of(scenario, positions)
    cubes, lines = arena_primitives(scenario.size)
    arena: dict[str, list] = {"cubes": cubes, "lines": lines}
    if scenario.obstacles:
        blocks = obstacle_primitives(scenario)
        arena["cubes"] = [*cubes, *blocks["cubes"]]
        if blocks.get("cylinders"):
            arena["cylinders"] = blocks["cylinders"]
    if caption:
        arena["texts"] = [text(scenario.size / 2, scenario.size + 0.6, 0.5, caption)]
    entities = [_entity("arena", when, **arena)]
    side = scenario.physics.box_side
    for i, name in enumerate(agent_names(scenario)):
        x, y = float(centres[i, 0]), float(centres[i, 1])
        turned = headings is not None and i < len(headings)
        yaw = float(np.arctan2(headings[i, 1], headings[i, 0])) if turned else 0.0
        prims = _agent(scenario, i, name, x, y, yaw)
        if velocities is not None:
            prims["arrows"] = _arrow(x, y, side + 0.05, *map(float, velocities[i]))
        if turned:
            prims["arrows"] = [*prims.get("arrows", []), _heading_arrow(scenario, i, x, y, yaw)]
        entities.append(_entity(name, when, **prims))
    drawn = centres[None] if trail is None else centres_of(scenario, trail)
    entities.append(_entity("trails", when, lines=_trails(drawn, 0.02)))
    entities.append(_entity("contacts", when, **_contact_marks(scenario, centres, contacts)))
    if sensing is not None:
        prims = sensing_primitives(scenario, positions, sensing, headings)
        entities.append(_entity("sensing", when, **prims))
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
