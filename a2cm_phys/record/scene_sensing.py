"""What a sensing scenario adds to a Foxglove scene (:mod:`.scene`): each pursuer's range,
the lines from the pursuers that know where the evader is to it, and the range sensor's
rays where it has them."""

from __future__ import annotations

import numpy as np
from foxglove.messages import (
    CylinderPrimitive,
    LinePrimitive,
    LinePrimitiveLineType,
    Point3,
    Vector3,
)

from ..config import Scenario
from ..envs.render import PURSUER_COLOURS
from ..envs.sensing import ray_segments
from .masks import in_range
from .scene_shapes import centres_of, cube, line, pose, rgba

_RANGE_ALPHA = 0.12  # a pursuer's sensing range: faint, the agents stay in front


def range_primitives(scenario: Scenario, i: int, x: float, y: float) -> dict[str, list]:
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
            "cubes": [cube((x0 + x1) / 2, (y0 + y1) / 2, 0.004, square, rgba(colour, _RANGE_ALPHA))]
        }
    disc = CylinderPrimitive(
        pose=pose(x, y, 0.004),
        size=Vector3(x=2 * r, y=2 * r, z=0.004),
        bottom_scale=1.0,
        top_scale=1.0,
        color=rgba(colour, _RANGE_ALPHA),
    )
    rim = [
        Point3(x=float(x + r * np.cos(a)), y=float(y + r * np.sin(a)), z=0.01)
        for a in np.linspace(0, 2 * np.pi, 48, endpoint=False)
    ]
    line = LinePrimitive(
        type=LinePrimitiveLineType.LineLoop,
        pose=pose(0, 0, 0),
        thickness=0.03,
        points=rim,
        color=rgba(colour, 0.5),
    )
    return {"cylinders": [disc], "lines": [line]}


def _rays(scenario: Scenario, positions: np.ndarray, headings: np.ndarray | None) -> list:
    """Each pursuer's range-sensor rays, from its centre to where each one stops (the first
    shape it meets, or ``sensing.range``): one faint line list per pursuer."""
    starts, ends = ray_segments(scenario, positions, headings)
    z = scenario.physics.box_side / 2
    lines = []
    for i in range(scenario.pursuers):
        points = []
        for (x0, y0), (x1, y1) in zip(starts[i].tolist(), ends[i].tolist(), strict=True):
            points += [Point3(x=x0, y=y0, z=z), Point3(x=x1, y=y1, z=z)]
        colour = rgba(PURSUER_COLOURS[i % len(PURSUER_COLOURS)], 0.6)
        lines.append(line(LinePrimitiveLineType.LineList, points, 0.02, colour))
    return lines


def sensing_primitives(
    scenario: Scenario,
    positions: np.ndarray,
    masks: np.ndarray,
    headings: np.ndarray | None = None,
) -> dict[str, list]:
    """The ``sensing`` entity's primitives for a state of a sensing scenario: each pursuer's
    range (:func:`range_primitives`), a line from each pursuer that knows the evader
    (``masks`` ``(N + 1, N + 1)``) to it, opaque when the evader is in its own range, faint
    when it knows it from a teammate (``share``); and with ``sensing.rays`` each pursuer's
    rays (turned by its ``headings`` ``(N, 2)`` with differential drive)."""
    centres = centres_of(scenario, positions)
    n = scenario.pursuers
    prims: dict[str, list] = {"cubes": [], "cylinders": [], "lines": []}
    for i in range(n):
        for kind, items in range_primitives(scenario, i, *map(float, centres[i])).items():
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
                pose=pose(0, 0, 0),
                thickness=0.06 if own[i] else 0.03,
                points=[Point3(x=x, y=y, z=z), Point3(x=ex, y=ey, z=z)],
                color=rgba(colour, 0.9 if own[i] else 0.35),
            )
        )
    if scenario.sensing.rays:
        prims["lines"] += _rays(scenario, positions, headings)
    return prims
