"""Range sensing in closed form: rays and sight lines against the arena's shapes, for every
game of a batch at once.

An agent's range sensor (``sensing.rays = R``) casts ``R`` rays from its centre, evenly
spaced from its heading (from ``+x`` for holonomic bodies), and reads the distance to the
first shape each one meets, out to ``sensing.range`` metres. The shapes are the physics
world's: the arena walls (the boundary of ``[0, size]²``), static obstacles, the other
pursuers' boxes (turned by their headings) and the evader's disc. Their outlines are
boxes and circles, so a ray's first hit has a closed form (the slab test for a box in its
own frame, a quadratic for a circle), and numpy evaluates every ray of every pursuer of
every game in a handful of array operations, where a pymunk segment query per ray would
cost a Python call each. The tests hold these distances to pymunk's own
:meth:`pymunk.Space.segment_query_first` on the same shapes.

The same geometry answers line of sight (``sensing.occlusion``): a body is hidden when the
segment between the two centres crosses an obstacle.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence

import numpy as np

from ..config import Obstacle

_EPS = 1e-12


def ray_angles(rays: int, heading: np.ndarray | None, shape: tuple[int, ...]) -> np.ndarray:
    """Every ray's world angle ``(*shape, rays)``: ``rays`` evenly spaced angles from each
    sensor's ``heading`` (``shape``; ``None``: from ``+x``)."""
    offsets = 2 * np.pi * np.arange(rays) / rays
    base = np.zeros(shape) if heading is None else np.asarray(heading, dtype=np.float64)
    return base[..., None] + offsets


def _box_hits(
    origin: np.ndarray,
    direction: np.ndarray,
    centre: np.ndarray,
    half: np.ndarray,
    angle: np.ndarray | None,
) -> np.ndarray:
    """Distance along unit rays to boxes (slab test in each box's frame); ``inf`` on a miss.

    ``origin``/``direction`` ``(..., 2)`` broadcast against ``centre`` ``(..., 2)``, half
    sizes ``half`` ``(..., 2)`` and optional ``angle`` (the box turned by it). A ray that
    starts inside a box hits it at 0. The axes are kept apart (reductions over a last axis
    of length 2 cost numpy several times two elementwise operations)."""
    rx, ry = origin[..., 0] - centre[..., 0], origin[..., 1] - centre[..., 1]
    dx, dy = direction[..., 0], direction[..., 1]
    if angle is not None:
        c, s = np.cos(angle), np.sin(angle)
        rx, ry = c * rx + s * ry, c * ry - s * rx
        dx, dy = c * dx + s * dy, c * dy - s * dx
    near, far = _slab(rx, dx, half[..., 0])
    near_y, far_y = _slab(ry, dy, half[..., 1])
    np.maximum(near, near_y, out=near)
    np.minimum(far, far_y, out=far)
    hit = (far >= near) & (far >= 0)
    return np.where(hit, np.maximum(near, 0.0), np.inf)


def _slab(rel: np.ndarray, d: np.ndarray, half: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Entry and exit distances of rays through the slab ``|x| <= half`` along one axis."""
    inv = 1.0 / np.where(np.abs(d) < _EPS, _EPS, d)
    t0, t1 = (-half - rel) * inv, (half - rel) * inv
    return np.minimum(t0, t1), np.maximum(t0, t1)


def _circle_hits(
    origin: np.ndarray, direction: np.ndarray, centre: np.ndarray, radius: np.ndarray
) -> np.ndarray:
    """Distance along unit rays to discs; ``inf`` on a miss, 0 from inside."""
    rx, ry = origin[..., 0] - centre[..., 0], origin[..., 1] - centre[..., 1]
    b = rx * direction[..., 0] + ry * direction[..., 1]
    c = rx * rx + ry * ry - radius * radius
    disc = b * b - c
    root = np.sqrt(np.maximum(disc, 0.0))
    near, far = -b - root, -b + root
    hit = (disc >= 0) & (far >= 0)
    return np.where(hit, np.maximum(near, 0.0), np.inf)


def _wall_hits(origin: np.ndarray, direction: np.ndarray, size: float) -> np.ndarray:
    """Distance along unit rays from inside ``[0, size]²`` to its boundary."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(
            direction > _EPS,
            (size - origin) / direction,
            np.where(direction < -_EPS, -origin / direction, np.inf),
        )
    return np.maximum(np.minimum(t[..., 0], t[..., 1]), 0.0)


@functools.cache
def _obstacle_arrays(obstacles: tuple[Obstacle, ...]) -> tuple[np.ndarray, ...]:
    """The obstacles as arrays: box centres and half sizes, circle centres and radii
    (computed once per layout: the layout is fixed for a scenario)."""
    boxes = [o for o in obstacles if o.shape == "box"]
    circles = [o for o in obstacles if o.shape == "circle"]
    return (
        np.array([(o.x, o.y) for o in boxes], dtype=np.float64).reshape(-1, 2),
        np.array([o.half_extents for o in boxes], dtype=np.float64).reshape(-1, 2),
        np.array([(o.x, o.y) for o in circles], dtype=np.float64).reshape(-1, 2),
        np.array([o.radius for o in circles], dtype=np.float64),
    )


def _obstacle_hits(
    origin: np.ndarray, direction: np.ndarray, obstacles: tuple[Obstacle, ...]
) -> np.ndarray:
    """Distance along unit rays ``(..., 2)`` to the first obstacle; ``inf`` where none."""
    box_c, box_h, circle_c, circle_r = _obstacle_arrays(obstacles)
    first = np.full(np.broadcast_shapes(origin.shape, direction.shape)[:-1], np.inf)
    if len(box_c):
        hits = _box_hits(origin[..., None, :], direction[..., None, :], box_c, box_h, None)
        first = np.minimum(first, hits.min(-1))
    if len(circle_c):
        hits = _circle_hits(origin[..., None, :], direction[..., None, :], circle_c, circle_r)
        first = np.minimum(first, hits.min(-1))
    return first


def cast_rays(
    positions: np.ndarray,
    headings: np.ndarray | None,
    rays: int,
    reach: float,
    size: float,
    box_side: float,
    evader_radius: float,
    obstacles: Sequence[Obstacle] = (),
) -> np.ndarray:
    """Every agent's range readings ``(B, N + 1, rays)`` in metres, at most ``reach``.

    ``positions`` ``(B, N + 1, 2)`` are the centres (pursuers, then the evader); ``headings``
    ``(B, N)`` the pursuers' angles (``None``: holonomic, unturned boxes). A pursuer's rays
    start at its heading, the evader's at ``+x``. A ray meets the first of: the arena's
    walls, the obstacles, the pursuers' boxes (side ``box_side``) and the evader's disc;
    an agent's own body is not in its way."""
    xy = np.asarray(positions, dtype=np.float64)
    b, count, _ = xy.shape
    n = count - 1
    turns = np.zeros((b, count))
    if headings is not None:
        turns[:, :n] = headings
    angle = ray_angles(rays, turns, (b, count))  # (B, C, R)
    direction = np.stack([np.cos(angle), np.sin(angle)], -1)  # (B, C, R, 2)
    origin = xy[:, :, None, :]  # (B, C, 1, 2)
    best = np.minimum(_wall_hits(origin, direction, size), reach)  # (B, C, R)
    # the pursuers' boxes: (B, C sensors, R, N boxes)
    boxes = xy[:, None, None, :n, :]
    turned = None if headings is None else np.asarray(headings)[:, None, None, :]
    half = np.full(2, box_side / 2)
    hits = _box_hits(origin[..., None, :], direction[..., None, :], boxes, half, turned)
    hits[:, np.arange(n), :, np.arange(n)] = np.inf  # a pursuer's own box
    best = np.minimum(best, hits.min(-1))
    disc = _circle_hits(origin, direction, xy[:, None, None, n, :], np.float64(evader_radius))
    disc[:, n] = np.inf  # the evader's own disc
    best = np.minimum(best, disc)
    return np.minimum(best, _obstacle_hits(origin, direction, tuple(obstacles)))


def visible(positions: np.ndarray, obstacles: Sequence[Obstacle]) -> np.ndarray:
    """Line of sight ``(B, C, C)`` bool between every pair of centres ``(B, C, 2)``: whether
    the segment between them crosses no obstacle (every body sees itself)."""
    xy = np.asarray(positions, dtype=np.float64)
    gap = xy[:, None, :, :] - xy[:, :, None, :]  # (B, C from, C to, 2)
    length = np.sqrt((gap * gap).sum(-1))
    safe = np.where(length > 0, length, 1.0)
    direction = gap / safe[..., None]
    origin = np.broadcast_to(xy[:, :, None, :], gap.shape)
    return _obstacle_hits(origin, direction, tuple(obstacles)) >= length
