"""The building blocks of the Foxglove scenes (:mod:`.scene`): colours, poses, cubes and
text from the Foxglove SDK's typed messages, and the parts every frame shares, the arena
(floor, walls, cell lines) and its obstacles. Units are metres in frame ``arena``."""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from foxglove.messages import (
    Color,
    CubePrimitive,
    CylinderPrimitive,
    LinePrimitive,
    LinePrimitiveLineType,
    Point3,
    Pose,
    Quaternion,
    TextPrimitive,
    Timestamp,
    Vector3,
)

from ..config import Scenario

WALL_HEIGHT = 0.3
"""How tall walls and obstacles are drawn (m)."""
_WALL = 0.15  # drawn wall thickness (m)


def rgba(colour: str, alpha: float = 1.0) -> Color:
    """A Foxglove colour of ``#rrggbb`` with opacity ``alpha``."""
    value = colour.lstrip("#")
    r, g, b = (int(value[i : i + 2], 16) / 255.0 for i in (0, 2, 4))
    return Color(r=r, g=g, b=b, a=alpha)


def pose(x: float, y: float, z: float, yaw: float = 0.0) -> Pose:
    """A pose at ``(x, y, z)`` turned by ``yaw`` (rad) about +z."""
    # Always an explicit orientation: an unset protobuf quaternion reads as all zeros.
    turn = Quaternion(x=0.0, y=0.0, z=float(np.sin(yaw / 2)), w=float(np.cos(yaw / 2)))
    return Pose(position=Vector3(x=x, y=y, z=z), orientation=turn)


def cube(
    x: float,
    y: float,
    z: float,
    size: tuple[float, float, float],
    colour: Color,
    yaw: float = 0.0,
) -> CubePrimitive:
    """A box of ``size`` centred at ``(x, y, z)``, turned by ``yaw``."""
    return CubePrimitive(
        pose=pose(x, y, z, yaw), size=Vector3(x=size[0], y=size[1], z=size[2]), color=colour
    )


def line(
    kind: LinePrimitiveLineType, points: list[Point3], thickness: float, colour: Color
) -> LinePrimitive:
    """A line of ``kind`` (strip, loop or list) through ``points`` in the arena's frame."""
    return LinePrimitive(
        type=kind, pose=pose(0, 0, 0), thickness=thickness, points=points, color=colour
    )


def text(x: float, y: float, z: float, text: str, size: float = 0.3) -> TextPrimitive:
    """Black text facing the camera at ``(x, y, z)``."""
    return TextPrimitive(
        pose=pose(x, y, z), billboard=True, font_size=size, color=rgba("#000000"), text=text
    )


def stamp(time_ns: int) -> Timestamp:
    """A Foxglove timestamp of ``time_ns`` nanoseconds."""
    return Timestamp(sec=time_ns // 1_000_000_000, nsec=time_ns % 1_000_000_000)


@lru_cache(maxsize=16)
def arena_primitives(cells: int) -> tuple[list[CubePrimitive], list[LinePrimitive]]:
    """The floor and walls (cubes) and the cells' lines of an arena of ``cells`` × ``cells``
    (made once per size: every frame draws the same)."""
    size = float(cells)
    grey, dark = rgba("#f2f2f2"), rgba("#555555")
    half, mid, h = _WALL / 2, size / 2, WALL_HEIGHT
    long, side = (size + 2 * _WALL, _WALL, h), (_WALL, size, h)
    cubes = [
        cube(mid, mid, -0.01, (size, size, 0.02), grey),
        cube(mid, -half, h / 2, long, dark),
        cube(mid, size + half, h / 2, long, dark),
        cube(-half, mid, h / 2, side, dark),
        cube(size + half, mid, h / 2, side, dark),
    ]
    points = []
    for k in range(1, cells):
        for a, b in (((k, 0.0), (k, size)), ((0.0, k), (size, k))):
            points += [Point3(x=a[0], y=a[1], z=0.001), Point3(x=b[0], y=b[1], z=0.001)]
    lines = [
        LinePrimitive(
            type=LinePrimitiveLineType.LineList,
            pose=pose(0.0, 0.0, 0.0),
            thickness=0.02,
            points=points,
            color=rgba("#bbbbbb"),
        )
    ]
    return cubes, lines if points else []


def obstacle_primitives(scenario: Scenario) -> dict[str, list]:
    """The obstacles' primitives, as tall as the walls: physics, a cube per box and a
    cylinder per circle; grid, a cube per blocked cell. Empty without obstacles."""
    dark, h = rgba("#555555"), WALL_HEIGHT
    if scenario.mode == "grid":
        blocked = np.flatnonzero(scenario.blocked_cells())
        y, x = np.divmod(blocked, scenario.size)
        cells = zip(x.tolist(), y.tolist(), strict=True)
        return {"cubes": [cube(i + 0.5, j + 0.5, h / 2, (1.0, 1.0, h), dark) for i, j in cells]}
    cubes, cylinders = [], []
    for obstacle in scenario.obstacles:
        if obstacle.shape == "circle":
            d = 2 * float(obstacle.radius)  # type: ignore[arg-type]
            at = pose(obstacle.x, obstacle.y, h / 2)
            cylinders.append(CylinderPrimitive(pose=at, size=Vector3(x=d, y=d, z=h), color=dark))
        else:
            hx, hy = obstacle.half_extents
            cubes.append(cube(obstacle.x, obstacle.y, h / 2, (2 * hx, 2 * hy, h), dark))
    return {"cubes": cubes, "cylinders": cylinders}


def centres_of(scenario: Scenario, positions: np.ndarray) -> np.ndarray:
    """Positions ``(…, N + 1, 2)`` in metres: cell centres in grid mode."""
    centres = np.asarray(positions, dtype=np.float64)
    return centres + 0.5 if scenario.mode == "grid" else centres
