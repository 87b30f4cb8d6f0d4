"""Pictures of the arena: a text grid, and RGB frames (matplotlib, no display needed).

Both take one game's positions ``(N + 1, 2)`` (pursuers, then the evader): integer cells in
grid mode, metres in physics mode, where cell ``(x, y)`` spans ``[x, x + 1] × [y, y + 1]``.
"""

from __future__ import annotations

import numpy as np

from ..config import Scenario

PURSUER_COLOURS = ("#d62728", "#1f77b4", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b")
EVADER_COLOUR = "#444444"


def _centres(scenario: Scenario, positions: np.ndarray) -> np.ndarray:
    """Positions in metres (cell centres for grid mode)."""
    pos = np.asarray(positions, dtype=np.float64)
    return pos + 0.5 if scenario.mode == "grid" else pos


def render_text(scenario: Scenario, positions: np.ndarray) -> str:
    """Rows from top (``y = size − 1``) to bottom: pursuer digits, ``E`` the evader,
    ``*`` several agents in one cell, ``.`` an empty cell."""
    size = scenario.size
    cells = np.clip(np.floor(_centres(scenario, positions)).astype(int), 0, size - 1)
    board = [["." for _ in range(size)] for _ in range(size)]
    symbols = [str(i % 10) for i in range(scenario.pursuers)] + ["E"]
    for symbol, (x, y) in zip(symbols, cells, strict=True):
        board[y][x] = symbol if board[y][x] == "." else "*"
    return "\n".join(" ".join(row) for row in reversed(board))


def render_rgb(
    scenario: Scenario,
    positions: np.ndarray,
    velocities: np.ndarray | None = None,
    title: str | None = None,
    pixels: int = 320,
    trail: np.ndarray | None = None,
) -> np.ndarray:
    """An ``(pixels, pixels, 3)`` uint8 picture: grid lines, walls, pursuer squares (with
    velocity arrows in physics mode) and the evader disc, like the paper's figures 2–4.
    ``trail``, earlier positions ``(T, N + 1, 2)`` (oldest first), draws each agent's path
    as a thin line in its colour (continuous control's paths)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.patches import Circle, Rectangle

    size, phys = scenario.size, scenario.physics
    centres = _centres(scenario, positions)
    fig = Figure(figsize=(4, 4), dpi=pixels / 4)
    ax = fig.add_axes((0.02, 0.02, 0.96, 0.9 if title else 0.96))
    wall = 0.15
    ax.set_xlim(-wall, size + wall)
    ax.set_ylim(-wall, size + wall)
    ax.set_aspect("equal")
    ax.axis("off")
    ax.add_patch(Rectangle((-wall, -wall), size + 2 * wall, size + 2 * wall, color="#555555"))
    ax.add_patch(Rectangle((0, 0), size, size, color="white"))
    for k in range(1, size):
        ax.plot([k, k], [0, size], color="#dddddd", lw=0.8)
        ax.plot([0, size], [k, k], color="#dddddd", lw=0.8)
    if trail is not None and len(trail):
        path = np.concatenate((_centres(scenario, trail), centres[None]))  # (T + 1, N + 1, 2)
        colours = [PURSUER_COLOURS[i % len(PURSUER_COLOURS)] for i in range(len(centres) - 1)]
        for xy, colour in zip(path.transpose(1, 0, 2), [*colours, EVADER_COLOUR], strict=True):
            ax.plot(xy[:, 0], xy[:, 1], color=colour, lw=1.2, alpha=0.6)
    side = phys.box_side
    for i, (x, y) in enumerate(centres[:-1]):
        colour = PURSUER_COLOURS[i % len(PURSUER_COLOURS)]
        ax.add_patch(Rectangle((x - side / 2, y - side / 2), side, side, color=colour, alpha=0.85))
        ax.text(x, y, str(i), ha="center", va="center", color="white", fontsize=11)
    ex, ey = centres[-1]
    ax.add_patch(Circle((ex, ey), phys.evader_radius, color=EVADER_COLOUR))
    if velocities is not None:
        for (x, y), (vx, vy) in zip(centres, np.asarray(velocities), strict=True):
            ax.arrow(x, y, 0.4 * vx, 0.4 * vy, width=0.02, color="black", length_includes_head=True)
    if title:
        fig.suptitle(title, fontsize=10, y=0.98)
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    return np.asarray(canvas.buffer_rgba())[..., :3].copy()
