"""The arena's fixed contents: the fixed start and the static obstacles (``[[obstacles]]``),
with the cells they block on a grid."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from .parse import InvalidKey

ObstacleShape = Literal["box", "circle"]


def default_start(size: int, pursuers: int) -> np.ndarray:
    """The fixed start's cells ``(N + 1, 2)`` (SPEC §1): the first pursuers in the corners,
    the rest along the border, the evader in the centre."""
    top = size - 1
    corners = [(0, 0), (top, 0), (0, top), (top, top)]
    border = [(x, 0) for x in range(size)] + [(top, y) for y in range(1, size)]
    border += [(x, top) for x in range(top - 1, -1, -1)] + [(0, y) for y in range(top - 1, 0, -1)]
    order = corners + [c for c in border if c not in corners]
    centre = (size // 2, size // 2)
    cells = [c for c in order if c != centre][:pursuers]
    return np.array([*cells, centre], dtype=np.int64)


@dataclass(frozen=True)
class Obstacle:
    """A static obstacle, one ``[[obstacles]]`` table: a ``box`` (``width`` × ``height``,
    axis-aligned) or a ``circle`` (``radius``) centred at ``(x, y)`` metres. The arena is
    ``[0, size]²`` and cell ``(i, j)`` spans ``[i, i + 1] × [j, j + 1]``, so the same list
    places walls in physics and blocks, on a grid, every cell whose centre it covers."""

    x: float
    y: float
    shape: ObstacleShape = "box"
    width: float | None = None
    height: float | None = None
    radius: float | None = None

    def validate(self) -> None:
        """Raise ``ValueError`` naming the key of the first impossible value."""
        needed = ("width", "height") if self.shape == "box" else ("radius",)
        for key in ("width", "height", "radius"):
            value = getattr(self, key)
            if key in needed and value is None:
                raise InvalidKey(key, f"a {self.shape} needs {' and '.join(needed)}")
            if key not in needed and value is not None:
                raise InvalidKey(key, f"a {self.shape} takes {' and '.join(needed)}, not {key}")
            if value is not None and not value > 0:
                raise InvalidKey(key, f"must be > 0, got {value!r}")

    @property
    def half_extents(self) -> tuple[float, float]:
        """Half the obstacle's width and height (its bounding box), metres."""
        if self.shape == "circle":
            return (self.radius, self.radius)  # type: ignore[return-value]
        return (self.width / 2, self.height / 2)  # type: ignore[operator]

    def covers(self, x: np.ndarray, y: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """Whether points ``(x, y)`` lie inside the obstacle grown by ``margin`` (strictly)."""
        dx, dy = np.abs(np.asarray(x) - self.x), np.abs(np.asarray(y) - self.y)
        if self.shape == "circle":
            return np.hypot(dx, dy) < self.radius + margin  # type: ignore[operator]
        hx, hy = self.half_extents
        return (dx < hx + margin) & (dy < hy + margin)


def blocked_cells(size: int, obstacles: tuple[Obstacle, ...]) -> np.ndarray:
    """Whether each cell ``x + size · y`` of a ``size × size`` grid has its centre inside an
    obstacle, ``(size²,)`` bool."""
    y, x = np.divmod(np.arange(size * size), size)
    blocked = np.zeros(size * size, dtype=bool)
    for obstacle in obstacles:
        blocked |= obstacle.covers(x + 0.5, y + 0.5)
    return blocked


def check_obstacles(
    obstacles: tuple[Obstacle, ...],
    size: int,
    pursuers: int,
    reach: tuple[float, float] | None,
    random_start: bool,
) -> None:
    """Raise :class:`InvalidKey` naming the first obstacle that reaches outside the arena or
    covers the fixed start (unless starts are random). ``reach`` is, in physics, the radius
    of a pursuer's and of the evader's bounding circle (a start body must not touch an
    obstacle); ``None`` on a grid, where each obstacle must also block a cell and the free
    cells must be connected and hold every agent."""
    start = default_start(size, pursuers)
    centres = start + 0.5
    y, x = np.divmod(np.arange(size * size), size)
    margin = 0.0 if reach is None else np.array([reach[0]] * pursuers + [reach[1]])
    for i, obstacle in enumerate(obstacles):
        key = f"obstacles[{i}]"
        hx, hy = obstacle.half_extents
        if (
            min(obstacle.x - hx, obstacle.y - hy) < 0
            or max(obstacle.x + hx, obstacle.y + hy) > size
        ):
            raise InvalidKey(key, f"reaches outside the {size}x{size} arena [0, {size}]²")
        if reach is None and not obstacle.covers(x + 0.5, y + 0.5).any():
            raise InvalidKey(key, "covers no cell centre, so it blocks nothing on a grid")
        hit = obstacle.covers(centres[:, 0], centres[:, 1], margin)
        if hit.any() and not random_start:
            cell = tuple(int(v) for v in start[int(np.argmax(hit))])
            raise InvalidKey(key, f"covers the fixed start of cell {cell}")
    if reach is None:
        free = ~blocked_cells(size, obstacles)
        if free.sum() < pursuers + 1:
            raise InvalidKey(
                "obstacles", f"leave {free.sum()} free cells for {pursuers + 1} agents"
            )
        if not _connected(free.reshape(size, size)):
            raise InvalidKey("obstacles", "split the free cells into parts no agent can cross")


def _connected(free: np.ndarray) -> bool:
    """Whether the ``True`` cells of a square mask form one 4-connected region: a flood fill
    by repeated one-cell growth (scipy's ``ndimage.label`` would do it too, but importing it
    costs every command a tenth of a second)."""
    reached = np.zeros_like(free)
    reached.flat[int(np.flatnonzero(free)[0])] = True
    while True:
        grown = reached.copy()
        grown[1:] |= reached[:-1]
        grown[:-1] |= reached[1:]
        grown[:, 1:] |= reached[:, :-1]
        grown[:, :-1] |= reached[:, 1:]
        grown &= free
        if (grown == reached).all():
            return bool((reached == free).all())
        reached = grown
