"""``foxglove.SceneUpdate`` messages that draw an episode in Foxglove's 3D panel.

Each frame is self-contained (arena, walls, grid lines, pursuer cubes, evader sphere, a
caption, and velocity arrows in physics mode), so seeking anywhere shows the full scene.
Entities keep fixed ids (``arena``, ``pursuer_0`` …, ``evader``), so each frame replaces the
previous one. Units are metres in frame ``arena``: a grid cell ``(x, y)`` is drawn at its
centre ``(x + 0.5, y + 0.5)``, as in :mod:`a2cm_phys.envs.render`.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from typing import Any

import numpy as np

from ..config import Scenario
from ..envs.core import agent_names
from ..envs.render import EVADER_COLOUR, PURSUER_COLOURS
from .runlog import Trajectory

FRAME_ID = "arena"
"""The frame every entity is drawn in (set it as the 3D panel's display frame)."""

_WALL = 0.15  # drawn wall thickness (m)
_WALL_HEIGHT = 0.3
_IDENTITY = {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}
_FOREVER = {"sec": 0, "nsec": 0}


def _rgba(colour: str, alpha: float = 1.0) -> dict[str, float]:
    value = colour.lstrip("#")
    r, g, b = (int(value[i : i + 2], 16) / 255.0 for i in (0, 2, 4))
    return {"r": r, "g": g, "b": b, "a": alpha}


def _pose(x: float, y: float, z: float) -> dict[str, Any]:
    return {"position": {"x": x, "y": y, "z": z}, "orientation": _IDENTITY}


def _cube(
    x: float, y: float, z: float, sx: float, sy: float, sz: float, colour: dict[str, float]
) -> dict[str, Any]:
    return {"pose": _pose(x, y, z), "size": {"x": sx, "y": sy, "z": sz}, "color": colour}


def _text(x: float, y: float, z: float, text: str, size: float = 0.3) -> dict[str, Any]:
    return {
        "pose": _pose(x, y, z),
        "billboard": True,
        "font_size": size,
        "scale_invariant": False,
        "color": _rgba("#000000"),
        "text": text,
    }


def _entity(entity_id: str, stamp: dict[str, int], **primitives: list[Any]) -> dict[str, Any]:
    entity: dict[str, Any] = {
        "timestamp": stamp,
        "frame_id": FRAME_ID,
        "id": entity_id,
        "lifetime": _FOREVER,
        "frame_locked": False,
        "metadata": [],
    }
    for kind in (
        "arrows",
        "cubes",
        "spheres",
        "cylinders",
        "lines",
        "triangles",
        "texts",
        "models",
    ):
        entity[kind] = primitives.get(kind, [])
    return entity


def _arena_primitives(scenario: Scenario) -> dict[str, list[Any]]:
    size = float(scenario.size)
    grey, dark = _rgba("#f2f2f2"), _rgba("#555555")
    half, mid = _WALL / 2, size / 2
    cubes = [
        _cube(mid, mid, -0.01, size, size, 0.02, grey),
        _cube(mid, -half, _WALL_HEIGHT / 2, size + 2 * _WALL, _WALL, _WALL_HEIGHT, dark),
        _cube(mid, size + half, _WALL_HEIGHT / 2, size + 2 * _WALL, _WALL, _WALL_HEIGHT, dark),
        _cube(-half, mid, _WALL_HEIGHT / 2, _WALL, size, _WALL_HEIGHT, dark),
        _cube(size + half, mid, _WALL_HEIGHT / 2, _WALL, size, _WALL_HEIGHT, dark),
    ]
    points = []
    for k in range(1, scenario.size):
        points += [
            {"x": k, "y": 0.0, "z": 0.001},
            {"x": k, "y": size, "z": 0.001},
            {"x": 0.0, "y": k, "z": 0.001},
            {"x": size, "y": k, "z": 0.001},
        ]
    lines = (
        [
            {
                "type": 2,
                "pose": _pose(0.0, 0.0, 0.0),
                "thickness": 0.02,
                "scale_invariant": False,
                "points": points,
                "color": _rgba("#bbbbbb"),
                "colors": [],
                "indices": [],
            }
        ]
        if points
        else []
    )
    return {"cubes": cubes, "lines": lines}


def _stamp(time_ns: int) -> dict[str, int]:
    return {"sec": time_ns // 1_000_000_000, "nsec": time_ns % 1_000_000_000}


def scene_update(
    scenario: Scenario,
    positions: np.ndarray,
    time_ns: int,
    caption: str = "",
    velocities: np.ndarray | None = None,
) -> dict[str, Any]:
    """One SceneUpdate (a dict ready for JSON) of a game's ``positions`` ``(N + 1, 2)``."""
    stamp = _stamp(time_ns)
    centres = np.asarray(positions, dtype=np.float64)
    if scenario.mode == "grid":
        centres = centres + 0.5
    phys = scenario.physics
    side, radius = phys.box_side, phys.evader_radius
    arena = _arena_primitives(scenario)
    if caption:
        arena["texts"] = [_text(scenario.size / 2, scenario.size + 0.6, 0.5, caption)]
    entities = [_entity("arena", stamp, **arena)]
    names = agent_names(scenario)
    for i, name in enumerate(names):
        x, y = float(centres[i, 0]), float(centres[i, 1])
        prims: dict[str, list[Any]] = {}
        if name == "evader":
            d = 2 * radius
            prims["spheres"] = [
                {
                    "pose": _pose(x, y, radius),
                    "size": {"x": d, "y": d, "z": d},
                    "color": _rgba(EVADER_COLOUR),
                }
            ]
        else:
            colour = _rgba(PURSUER_COLOURS[i % len(PURSUER_COLOURS)])
            prims["cubes"] = [_cube(x, y, side / 2, side, side, side, colour)]
            prims["texts"] = [_text(x, y, side + 0.25, str(i), 0.25)]
        if velocities is not None:
            vx, vy = float(velocities[i, 0]), float(velocities[i, 1])
            speed = float(np.hypot(vx, vy))
            if speed > 1e-9:
                yaw = float(np.arctan2(vy, vx))
                arrow = {
                    "pose": {
                        "position": {"x": x, "y": y, "z": side + 0.05},
                        "orientation": {
                            "x": 0.0,
                            "y": 0.0,
                            "z": float(np.sin(yaw / 2)),
                            "w": float(np.cos(yaw / 2)),
                        },
                    },
                    "shaft_length": 0.4 * speed,
                    "shaft_diameter": 0.04,
                    "head_length": 0.1,
                    "head_diameter": 0.1,
                    "color": _rgba("#000000"),
                }
                prims["arrows"] = [arrow]
        entity = _entity(name, stamp, **prims)
        entity["metadata"] = [{"key": "x", "value": f"{x:g}"}, {"key": "y", "value": f"{y:g}"}]
        entities.append(entity)
    return {"deletions": [], "entities": entities}


def episode_scenes(scenario: Scenario, traj: Trajectory) -> Iterator[tuple[int, bytes]]:
    """``(log_time_ns, json_bytes)`` of one SceneUpdate per state of the episode (start, then
    after each step), timed on the run clock (``t0 + k · dt``)."""
    ret = 0.0
    for k in range(traj.length + 1):
        if k:
            ret += float(traj.reward[k - 1])
        status = ""
        if k == traj.length:
            status = "  captured" if traj.captured[-1] else "  end"
        caption = f"episode {traj.episode}  step {k}/{traj.length}  return {ret:g}{status}"
        time_ns = round((traj.t0 + k * traj.dt) * 1e9)
        vel = None if traj.velocities is None else traj.velocities[k]
        msg = scene_update(scenario, traj.positions[k], time_ns, caption, vel)
        yield time_ns, json.dumps(msg, separators=(",", ":")).encode()
