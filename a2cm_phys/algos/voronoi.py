"""The evader's Voronoi cell in the arena: the region it reaches before any pursuer.

The cell is the arena's box cut by one half-plane per pursuer, the points nearer the evader
than that pursuer: ``{x : |x − e| ≤ |x − p_i|}``, i.e. ``(p_i − e)·x ≤ (|p_i|² − |e|²) / 2``.
Its area is the classic measure of an evader's room in cooperative pursuit (Huang, Zhang,
Ding, Stipanović & Tomlin, "Guaranteed decentralized pursuit-evasion in the plane with
multiple pursuers", CDC 2011): every pursuer that shares an edge with the cell shrinks it
by advancing, even while the evader runs, and a team shrinks it fastest by closing the
evader's ways out together, which running straight at it does not do.

:func:`cell_area` computes it for many games at once: Sutherland–Hodgman clipping of the
box by each half-plane in turn, on fixed-size vertex arrays (a convex polygon cut by a
line gains at most one vertex), so the work is a few dozen numpy calls whatever the
number of rows.
"""

from __future__ import annotations

import numpy as np


def _following(poly: np.ndarray, count: np.ndarray) -> np.ndarray:
    """Each vertex's successor around its polygon (the first after the last valid one)."""
    k = np.arange(poly.shape[1])
    after = np.where(k + 1 < count[:, None], k + 1, 0)
    return np.take_along_axis(poly, after[..., None], axis=1)


def clip_convex(
    poly: np.ndarray, count: np.ndarray, normal: np.ndarray, offset: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Cut convex polygons by the half-planes ``normal · x ≤ offset``.

    Args:
        poly: ``(R, M, 2)`` vertices in order; row ``r`` uses its first ``count[r]``.
        count: ``(R,)`` vertex counts.
        normal: ``(R, 2)`` half-plane normals (a zero normal with ``offset ≥ 0`` keeps all).
        offset: ``(R,)``.

    Returns:
        ``(R, 2M, 2)`` vertices and ``(R,)`` counts of the clipped polygons (0 when nothing
        is left).
    """
    rows, m, _ = poly.shape
    valid = np.arange(m) < count[:, None]
    nxt = _following(poly, count)
    side = np.einsum("rmd,rd->rm", poly, normal) - offset[:, None]  # > 0: outside
    side_next = np.einsum("rmd,rd->rm", nxt, normal) - offset[:, None]
    keep = valid & (side <= 0)
    cross = valid & (side * side_next < 0)  # the edge to the next vertex crosses the line
    t = side / np.where(cross, side - side_next, 1.0)
    hit = poly + np.where(cross, t, 0.0)[..., None] * (nxt - poly)
    # Each vertex, then its edge's crossing: in order around the polygon.
    candidates = np.stack([poly, hit], axis=2).reshape(rows, 2 * m, 2)
    kept = np.stack([keep, cross], axis=2).reshape(rows, 2 * m)
    order = np.argsort(~kept, axis=1, kind="stable")  # kept ones first, in order
    return np.take_along_axis(candidates, order[..., None], axis=1), kept.sum(1)


def polygon_area(poly: np.ndarray, count: np.ndarray) -> np.ndarray:
    """Areas ``(R,)`` of polygons ``(R, M, 2)`` with ``count`` vertices (shoelace formula)."""
    nxt = _following(poly, count)
    cross = poly[..., 0] * nxt[..., 1] - poly[..., 1] * nxt[..., 0]
    valid = np.arange(poly.shape[1]) < count[:, None]
    return 0.5 * np.abs(np.where(valid, cross, 0.0).sum(1))


def cell_area(evader: np.ndarray, pursuers: np.ndarray, low: float, high: float) -> np.ndarray:
    """Area of the evader's Voronoi cell inside the box ``[low, high]²``.

    Args:
        evader: ``(..., 2)`` positions.
        pursuers: ``(..., N, 2)`` positions (same units).
        low, high: the box's bounds on both axes.

    Returns:
        ``(...)`` float64 areas, in the positions' units squared. A pursuer on the evader's
        position leaves the cell whole on its side (the zero half-plane keeps everything).
    """
    e = np.asarray(evader, dtype=np.float64)
    p = np.asarray(pursuers, dtype=np.float64)
    shape = e.shape[:-1]
    e = e.reshape(-1, 2)
    p = p.reshape(len(e), p.shape[-2], 2)
    rows = len(e)
    box = np.array([[low, low], [high, low], [high, high], [low, high]], dtype=np.float64)
    poly = np.broadcast_to(box, (rows, 4, 2))
    count = np.full(rows, 4)
    half_e = 0.5 * (e * e).sum(-1)
    for i in range(p.shape[1]):
        normal = p[:, i] - e
        poly, count = clip_convex(poly, count, normal, 0.5 * (p[:, i] ** 2).sum(-1) - half_e)
        poly = poly[:, : count.max(initial=0)]  # drop the unused tail
    return polygon_area(poly, count).reshape(shape)
