"""Pictures of the arena: a text grid, and RGB frames (matplotlib, no display needed).

Both take one game's positions ``(N + 1, 2)`` (pursuers, then the evader): integer cells in
grid mode, metres in physics mode, where cell ``(x, y)`` spans ``[x, x + 1] × [y, y + 1]``.
What touched in a step (:class:`Contacts`, from :func:`step_contacts`) is marked in both:
in text by its own symbol (:data:`TEXT_LEGEND`), in a frame by a ring around a caught
evader and a star where two pursuers collided, with a legend under the arena. A frame
draws the scenario's obstacles (physics: their shapes; grid: the cells they block) in the
walls' colour, differential-drive pursuers turned by their headings, a notch on their
front edge, and with a range sensor (``sensing.rays``) each pursuer's rays to where they
stop.
"""

from __future__ import annotations

import textwrap
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..config import Scenario
from .grid import meet
from .sensing import ray_segments

PURSUER_COLOURS = ("#d62728", "#1f77b4", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b")
EVADER_COLOUR = "#444444"
WALL_COLOUR = "#555555"
"""The arena's walls and its obstacles."""
CAPTURE_COLOUR = "#f2b701"
"""The ring around a caught evader."""
COLLISION_COLOUR = "#ffe600"
"""The star (black edge) where two pursuers collided."""
CAPTION_COLOURS = {"capture": "#1a7f37", "collision": "#c00000", "other": "#333333"}
"""A caption's colour by what it tells: a capture, a collision, anything else."""

TEXT_CAPTURE, TEXT_COLLISION, TEXT_SHARED, TEXT_EMPTY = "X", "#", "*", "."
TEXT_LEGEND = (
    f"legend: 0-9 pursuer, E evader, {TEXT_CAPTURE} evader caught (a capture), "
    f"{TEXT_COLLISION} pursuer in a collision,\n"
    f"        {TEXT_SHARED} agents in one cell, not touching (physics), {TEXT_EMPTY} empty cell"
)
"""What the symbols of :func:`render_text` mean, in two lines."""

DEFAULT_PIXELS = 480
"""Default width of a frame in pixels (its height adds room for the caption and legend)."""
HEIGHT_RATIO = 1.3
"""A frame's height over its width: the arena, a title above it, a caption and a legend
under it."""
CAPTION_CHARACTERS = 46
"""Characters of a caption line (two lines at most)."""


@dataclass(frozen=True)
class Contacts:
    """What touched in one step: ``capturers`` the pursuers that caught the evader,
    ``collisions`` the pursuer pairs ``(i, j)``, ``i < j``, that collided."""

    capturers: tuple[int, ...] = ()
    collisions: tuple[tuple[int, int], ...] = ()

    def __bool__(self) -> bool:
        return bool(self.capturers or self.collisions)

    def __or__(self, other: Contacts) -> Contacts:
        return Contacts(
            tuple(sorted(set(self.capturers) | set(other.capturers))),
            tuple(sorted(set(self.collisions) | set(other.collisions))),
        )


def step_contacts(
    scenario: Scenario,
    before: np.ndarray,
    after: np.ndarray,
    events: list[tuple[str, str, str, int]] | None = None,
    step: int | None = None,
) -> Contacts:
    """The contacts of the step from positions ``before`` to ``after``: on the grid by its
    rule (two movers end on one cell or swap cells); in physics the contact events of
    ``step`` (the step's number, as the events carry it) in ``events``."""
    n = scenario.pursuers
    if scenario.mode == "grid":
        size = scenario.size
        old = np.asarray(before, dtype=np.int64) @ np.array([1, size])
        new = np.asarray(after, dtype=np.int64) @ np.array([1, size])
        touch = lambda i, j: bool(meet(old[i], new[i], old[j], new[j]))  # noqa: E731
        pairs = tuple((i, j) for i in range(n) for j in range(i + 1, n) if touch(i, j))
        return Contacts(tuple(i for i in range(n) if touch(i, n)), pairs)
    capturers: set[int] = set()
    pairs_set: set[tuple[int, int]] = set()
    for kind, a, b, when in events or ():
        if when != step:
            continue
        if kind == "pursuer_evader":
            capturers.add(_pursuer_index(a if a != "evader" else b))
        elif kind == "pursuer_pursuer":
            i, j = sorted((_pursuer_index(a), _pursuer_index(b)))
            pairs_set.add((i, j))
    return Contacts(tuple(sorted(capturers)), tuple(sorted(pairs_set)))


def _pursuer_index(name: str) -> int:
    return int(name.rsplit("_", 1)[-1])


def _centres(scenario: Scenario, positions: np.ndarray) -> np.ndarray:
    """Positions in metres (cell centres for grid mode)."""
    pos = np.asarray(positions, dtype=np.float64)
    return pos + 0.5 if scenario.mode == "grid" else pos


def render_text(scenario: Scenario, positions: np.ndarray, contacts: Contacts | None = None) -> str:
    """Rows from top (``y = size − 1``) to bottom: pursuer digits, ``E`` the evader, ``X``
    a caught evader, ``#`` a pursuer in a collision, ``*`` agents sharing a cell without
    touching (physics), ``.`` an empty cell (:data:`TEXT_LEGEND`). On the grid agents in one
    cell have met, so a shared cell is a capture or a collision even without ``contacts``."""
    size, n = scenario.size, scenario.pursuers
    cells = np.clip(np.floor(_centres(scenario, positions)).astype(int), 0, size - 1)
    board = [[TEXT_EMPTY for _ in range(size)] for _ in range(size)]
    symbols = [str(i % 10) for i in range(n)] + ["E"]
    for symbol, (x, y) in zip(symbols, cells, strict=True):
        board[y][x] = symbol if board[y][x] == TEXT_EMPTY else TEXT_SHARED
    contacts = contacts or Contacts()
    colliders = {i for pair in contacts.collisions for i in pair}
    if scenario.mode == "grid":
        shared = [tuple(c) for c in cells]
        colliders |= {i for i in range(n) if shared.count(shared[i]) > 1}
        caught = shared[n] in shared[:n]
    else:
        caught = bool(contacts.capturers)
    for i in sorted(colliders):
        board[cells[i][1]][cells[i][0]] = TEXT_COLLISION
    if caught or contacts.capturers:
        board[cells[n][1]][cells[n][0]] = TEXT_CAPTURE
    return "\n".join(" ".join(row) for row in reversed(board))


def legend_labels(scenario: Scenario, trail: bool = False) -> list[str]:
    """The entries of a frame's legend, in order (``trail``: paths are drawn)."""
    n = scenario.pursuers
    labels = [f"pursuers {', '.join(map(str, range(n)))}" if n > 1 else "pursuer 0", "evader"]
    if scenario.obstacles:
        labels.append("obstacle")
    if trail:
        labels.append("path so far")
    if scenario.mode == "physics":
        labels.append("velocity")
    return [*labels, "capture (ring)", "collision (star)"]


def render_rgb(
    scenario: Scenario,
    positions: np.ndarray,
    velocities: np.ndarray | None = None,
    title: str | None = None,
    pixels: int = DEFAULT_PIXELS,
    trail: np.ndarray | None = None,
    contacts: Contacts | None = None,
    caption: str = "",
    caption_kind: str = "other",
    headings: np.ndarray | None = None,
) -> np.ndarray:
    """An RGB uint8 picture ``pixels`` wide (:data:`HEIGHT_RATIO` × as high): the arena with
    its grid lines and walls, pursuer squares (with velocity arrows in physics mode) and the evader
    disc, like the paper's figures 2–4; ``title`` above it, ``caption`` under it (in the
    colour of ``caption_kind``: capture, collision or other) and a legend at the bottom.
    ``trail``, earlier positions ``(T, N + 1, 2)`` (oldest first), draws each agent's path
    as a thin line in its colour (continuous control's paths). ``contacts`` are marked: a
    ring around a caught evader, a star between two pursuers that collided. On the grid,
    agents in one cell are drawn smaller, side by side, so that none hides another.
    ``headings`` ``(N, 2)`` ``(cos θ, sin θ)`` (differential drive) turn the pursuers' squares
    and notch their front edges; without them squares are drawn unturned. A scenario with
    ``sensing.rays`` draws each pursuer's rays, thin, in its colour."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(4, 4 * HEIGHT_RATIO), dpi=pixels / 4)
    height = 4 * HEIGHT_RATIO  # inches, from the bottom: legend, caption, arena, title
    ax = fig.add_axes((0.05, 0.95 / height, 0.9, 3.6 / height))
    _draw_arena(ax, scenario)
    centres, scale = _drawn_centres(scenario, positions)
    if trail is not None and len(trail):
        path = np.concatenate((_centres(scenario, trail), _centres(scenario, positions)[None]))
        for xy, colour in zip(path.transpose(1, 0, 2), _colours(scenario), strict=True):
            ax.plot(xy[:, 0], xy[:, 1], color=colour, lw=1.4, alpha=0.6)
    if scenario.sensing.rays:
        starts, ends = ray_segments(scenario, positions, headings)
        for i, colour in enumerate(_colours(scenario)[:-1]):
            for (x0, y0), (x1, y1) in zip(starts[i], ends[i], strict=True):
                ax.plot([x0, x1], [y0, y1], color=colour, lw=0.7, alpha=0.6, zorder=2.5)
    _draw_agents(ax, scenario, centres, scale, velocities, headings)
    _draw_contacts(ax, scenario, centres, contacts or Contacts())
    if title:
        fig.text(0.5, 1 - 0.06 / height, title, ha="center", va="top", fontsize=10.5)
    if caption:
        colour = CAPTION_COLOURS.get(caption_kind, CAPTION_COLOURS["other"])
        text = textwrap.fill(caption, CAPTION_CHARACTERS, max_lines=2, placeholder=" …")
        fig.text(0.5, 0.9 / height, text, ha="center", va="top", fontsize=10, color=colour,
                 weight="bold")  # fmt: skip
    _draw_legend(fig, scenario, trail is not None)
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    return np.asarray(canvas.buffer_rgba())[..., :3].copy()


def _colours(scenario: Scenario) -> list[str]:
    n = scenario.pursuers
    return [PURSUER_COLOURS[i % len(PURSUER_COLOURS)] for i in range(n)] + [EVADER_COLOUR]


def _draw_arena(ax: Any, scenario: Scenario) -> None:
    from matplotlib.patches import Rectangle

    size, wall = scenario.size, 0.15
    ax.set_xlim(-wall, size + wall)
    ax.set_ylim(-wall, size + wall)
    ax.set_aspect("equal")
    ax.axis("off")
    ax.add_patch(Rectangle((-wall, -wall), size + 2 * wall, size + 2 * wall, color=WALL_COLOUR))
    ax.add_patch(Rectangle((0, 0), size, size, color="white"))
    for k in range(1, size):
        ax.plot([k, k], [0, size], color="#dddddd", lw=0.8, zorder=1)  # under the agents
        ax.plot([0, size], [k, k], color="#dddddd", lw=0.8, zorder=1)
    _draw_obstacles(ax, scenario)


def _draw_obstacles(ax: Any, scenario: Scenario) -> None:
    """Physics: each obstacle's shape; grid: the cells the obstacles block (what the game
    plays), over the cells' lines and under the agents."""
    from matplotlib.patches import Circle, Rectangle

    if scenario.mode == "grid":
        blocked = np.flatnonzero(scenario.blocked_cells())
        for y, x in zip(*np.divmod(blocked, scenario.size), strict=True):
            ax.add_patch(Rectangle((x, y), 1.0, 1.0, color=WALL_COLOUR, zorder=2))
        return
    for obstacle in scenario.obstacles:
        if obstacle.shape == "circle":
            ax.add_patch(Circle((obstacle.x, obstacle.y), obstacle.radius, color=WALL_COLOUR,
                                zorder=2))  # fmt: skip
        else:
            hx, hy = obstacle.half_extents
            corner = (obstacle.x - hx, obstacle.y - hy)
            ax.add_patch(Rectangle(corner, 2 * hx, 2 * hy, color=WALL_COLOUR, zorder=2))


def _drawn_centres(scenario: Scenario, positions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where each agent is drawn and how large (a factor): on the grid, agents sharing a
    cell are spread around its centre at 0.6 × their size."""
    centres = _centres(scenario, positions).copy()
    scale = np.ones(len(centres))
    if scenario.mode != "grid":
        return centres, scale
    cells = [tuple(c) for c in np.asarray(positions, dtype=np.int64)]
    for cell in set(cells):
        group = [i for i, c in enumerate(cells) if c == cell]
        if len(group) < 2:
            continue
        for j, i in enumerate(group):
            angle = np.pi * (0.75 - 2 * j / len(group))
            centres[i] += 0.25 * np.array([np.cos(angle), np.sin(angle)])
            scale[i] = 0.65
    return centres, scale


def _draw_agents(
    ax: Any,
    scenario: Scenario,
    centres: np.ndarray,
    scale: np.ndarray,
    velocities: np.ndarray | None,
    headings: np.ndarray | None = None,
) -> None:
    from matplotlib import patheffects
    from matplotlib.patches import Circle, Rectangle

    phys = scenario.physics
    outline = [patheffects.withStroke(linewidth=2.5, foreground="black")]
    for i, (x, y) in enumerate(centres[:-1]):
        side = phys.box_side * scale[i]
        colour = PURSUER_COLOURS[i % len(PURSUER_COLOURS)]
        corner = (x - side / 2, y - side / 2)
        if headings is None:
            ax.add_patch(Rectangle(corner, side, side, color=colour, zorder=3))
        else:
            cos, sin = (float(v) for v in headings[i])
            degrees = float(np.degrees(np.arctan2(sin, cos)))
            ax.add_patch(Rectangle(corner, side, side, angle=degrees, rotation_point="center",
                                   color=colour, zorder=3))  # fmt: skip
            front = np.array([x, y]) + side / 2 * np.array([cos, sin])
            across = side / 4 * np.array([-sin, cos])
            notch = np.stack([front - across, front + across])
            ax.plot(notch[:, 0], notch[:, 1], color="black", lw=3, zorder=4)
        ax.text(x, y, str(i), ha="center", va="center", color="white", zorder=7,
                fontsize=13 * scale[i], weight="bold", path_effects=outline)  # fmt: skip
    ex, ey = centres[-1]
    ax.add_patch(Circle((ex, ey), phys.evader_radius * scale[-1], color=EVADER_COLOUR, zorder=3))
    if velocities is not None:
        for (x, y), (vx, vy) in zip(centres, np.asarray(velocities), strict=True):
            ax.arrow(x, y, 0.4 * vx, 0.4 * vy, width=0.02, color="black", zorder=4,
                     length_includes_head=True)  # fmt: skip


def _draw_contacts(ax: Any, scenario: Scenario, centres: np.ndarray, contacts: Contacts) -> None:
    """A ring around a caught evader; a star halfway between two pursuers that collided."""
    from matplotlib.patches import Circle

    if contacts.capturers:
        radius = scenario.physics.evader_radius + 0.12
        ax.add_patch(Circle(centres[-1], radius, fill=False, lw=4, ec=CAPTURE_COLOUR, zorder=5))
        ax.add_patch(Circle(centres[-1], radius + 0.06, fill=False, lw=1, ec="black", zorder=5))
    for i, j in contacts.collisions:
        x, y = (centres[i] + centres[j]) / 2
        ax.plot(x, y, marker="*", ms=22, mfc=COLLISION_COLOUR, mec="black", mew=1.2, zorder=6)


def _draw_legend(fig: Any, scenario: Scenario, trail: bool) -> None:
    from matplotlib.legend_handler import HandlerTuple
    from matplotlib.lines import Line2D

    square = dict(marker="s", ls="none", ms=7)
    pursuers = tuple(
        Line2D([], [], color=c, **square) for c in _colours(scenario)[:-1][: len(PURSUER_COLOURS)]
    )
    handles: list[Any] = [
        pursuers,
        Line2D([], [], marker="o", ls="none", ms=9, color=EVADER_COLOUR),
    ]
    if scenario.obstacles:
        handles.append(Line2D([], [], marker="s", ls="none", ms=9, color=WALL_COLOUR))
    if trail:
        handles.append(Line2D([], [], color=PURSUER_COLOURS[0], lw=1.4, alpha=0.6))
    if scenario.mode == "physics":
        handles.append(Line2D([], [], marker=r"$\rightarrow$", ls="none", ms=12, color="black"))
    handles.append(
        Line2D([], [], marker="o", ls="none", ms=13, mfc="none", mec=CAPTURE_COLOUR, mew=3)
    )
    handles.append(
        Line2D([], [], marker="*", ls="none", ms=15, mfc=COLLISION_COLOUR, mec="black", mew=1)
    )
    labels = legend_labels(scenario, trail)
    fig.legend(
        handles,
        labels,
        loc="lower center",
        bbox_to_anchor=(0.5, 0.0),
        ncol=2 if len(labels) <= 4 else 3,
        fontsize=8.5,
        frameon=False,
        handler_map={tuple: HandlerTuple(ndivide=None, pad=0.2)},
        handlelength=max(2.0, 0.95 * min(scenario.pursuers, len(PURSUER_COLOURS))),
        handletextpad=0.5,
        columnspacing=1.0,
    )
