"""Static obstacles in physics mode (the scenario's ``[[obstacles]]``): their pymunk shapes,
and which bodies at given positions overlap one (for random starts and placed positions).

An obstacle is a box (axis-aligned) or a disc on the world's static body, like the walls:
the contact solver stops agents at it and an agent touching it is an ``agent_obstacle``
contact (:mod:`.contacts`). The overlap tests take the bodies as they stand at a start:
pursuers as unrotated boxes of side ``box_side`` (every start has heading 0), the evader as
its disc; touching is not overlapping.
"""

from __future__ import annotations

import numpy as np
import pymunk

from ..config import InvalidKey, Obstacle, Scenario


def obstacle_shape(obstacle: Obstacle, static: pymunk.Body) -> pymunk.Shape:
    """The pymunk shape of ``obstacle`` on the static body ``static`` (world coordinates):
    a four-vertex :class:`pymunk.Poly` for a box, a :class:`pymunk.Circle` for a circle."""
    if obstacle.shape == "circle":
        return pymunk.Circle(static, float(obstacle.radius), (obstacle.x, obstacle.y))
    hx, hy = obstacle.half_extents
    x0, y0, x1, y1 = obstacle.x - hx, obstacle.y - hy, obstacle.x + hx, obstacle.y + hy
    return pymunk.Poly(static, [(x0, y0), (x1, y0), (x1, y1), (x0, y1)])


def substep_reach(scenario: Scenario) -> float:
    """How far (m) a point of a body can move in one solver substep: at ``max_speed``, plus
    with differential drive a pursuer's corner turning at ``max_turn_rate`` half a
    diagonal from its centre. A body reaching a static shape sinks into it by up to this
    before their contact exists (detection is discrete), and the solver then pushes it out
    along the shallower way."""
    ph = scenario.physics
    speed = ph.max_speed
    if scenario.differential:
        speed += ph.max_turn_rate * ph.box_side / 2**0.5
    return speed * ph.dt / ph.substeps


def check_thickness(scenario: Scenario) -> None:
    """Refuse an obstacle so thin that a body could sink past its middle in one substep
    (:func:`substep_reach`), where the solver would push it out on the far side: raise
    :class:`~a2cm_phys.config.InvalidKey` naming the obstacle."""
    reach = substep_reach(scenario)
    for i, obstacle in enumerate(scenario.obstacles):
        half = min(obstacle.half_extents)
        if reach >= half:
            raise InvalidKey(
                f"obstacles[{i}]",
                f"obstacles[{i}] is {2 * half:g} m thick, but a body can move {reach:.3g} m "
                f"in one substep (physics.dt / physics.substeps at max_speed, and a turning "
                f"corner's speed with differential drive), past its middle, and be pushed "
                f"through it: make it thicker than {2 * reach:.3g} m or raise physics.substeps",
            )


def obstacle_overlaps(scenario: Scenario, xy: np.ndarray) -> np.ndarray:
    """Whether each body at positions ``xy`` ``(..., N + 1, 2)`` (metres; pursuers, then
    the evader) overlaps an obstacle, ``(..., N + 1)`` bool (exact for unrotated boxes and
    discs; touching is fine). All ``False`` without obstacles."""
    xy = np.asarray(xy, dtype=np.float64)
    n, ph = scenario.pursuers, scenario.physics
    hit = np.zeros(xy.shape[:-1], dtype=bool)
    half = ph.box_side / 2
    for obstacle in scenario.obstacles:
        dx = np.abs(xy[..., 0] - obstacle.x)
        dy = np.abs(xy[..., 1] - obstacle.y)
        if obstacle.shape == "box":
            hx, hy = obstacle.half_extents
            boxes = (dx < hx + half) & (dy < hy + half)
            gap = np.hypot(np.maximum(dx - hx, 0.0), np.maximum(dy - hy, 0.0))
            disc = gap < ph.evader_radius
        else:
            radius = float(obstacle.radius)  # type: ignore[arg-type]
            gap = np.hypot(np.maximum(dx - half, 0.0), np.maximum(dy - half, 0.0))
            boxes = gap < radius
            disc = np.hypot(dx, dy) < radius + ph.evader_radius
        hit[..., :n] |= boxes[..., :n]
        hit[..., n] |= disc[..., n]
    return hit


def clear_of_obstacles(scenario: Scenario, xy: np.ndarray) -> np.ndarray:
    """Whether every body of each start ``xy`` ``(..., N + 1, 2)`` is clear of every
    obstacle, ``(...,)`` bool: what a random start must also be (for
    :func:`~.starts.random_starts`' validity test, ``_physics_valid``)."""
    return ~obstacle_overlaps(scenario, xy).any(axis=-1)
