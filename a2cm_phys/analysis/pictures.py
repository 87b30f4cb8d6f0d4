"""Episodes drawn for people (``replay --episode N --render gif|png``): frames with a title,
a caption for what happened (a capture, a collision, the time limit) and a legend
(:func:`episode_picture`), a GIF that plays at the game's pace or a PNG contact sheet
(:func:`save_picture`), and the file names a user would pick (:func:`picture_path`).

In a sensing scenario (SPEC §6b) each frame also shows every pursuer's sensing range,
faint in its colour (grids: the ``(2r + 1)²`` cells around it; physics: a disc of radius
``r`` m), a line from each pursuer that knows the evader to it (solid when the evader is in
its own range, dashed when a teammate told it), and the title names who knows the evader
(:func:`sensing_overlay`). Without sensing the frames are as before.

The pace: in physics one frame per control period (``physics.dt``: 1 s with discrete moves,
0.1 s with continuous commands), on grids :data:`GRID_FRAME_SECONDS`, slow enough to follow
each move; the last frame stays :data:`END_HOLD_SECONDS` so that the ending can be read.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..base.progress import Progress
from ..config import Scenario
from ..envs.render import (
    DEFAULT_PIXELS,
    HEIGHT_RATIO,
    PURSUER_COLOURS,
    Contacts,
    render_rgb,
    step_contacts,
)
from ..record.masks import in_range
from ..record.runlog import Trajectory, trajectory_masks

GRID_FRAME_SECONDS = 0.5
"""Seconds a grid frame shows: two moves a second, a pace a person can follow."""
END_HOLD_SECONDS = 2.0
"""Seconds the last frame shows at least, for its caption."""
MIN_FRAME_SECONDS = 0.02
"""The shortest frame GIF viewers honour (shorter ones they slow down to 0.1 s)."""
DEFAULT_MAX_FRAMES = {"gif": 200, "png": 12}
"""Frames drawn at most by default: a GIF's, a contact sheet's."""
RANGE_ALPHA = 0.14
"""Opacity of a pursuer's sensing range: faint, so that the agents stay plain."""
_WALL = 0.15  # the arena's drawn wall (m), as render_rgb draws it


@dataclass
class EpisodePicture:
    """An episode's frames, each with the state it shows (``steps``), the seconds it shows
    in a GIF (``seconds``) and its caption (``captions``, as plain text)."""

    frames: list[np.ndarray] = field(default_factory=list)
    steps: list[int] = field(default_factory=list)
    seconds: list[float] = field(default_factory=list)
    captions: list[str] = field(default_factory=list)


def frame_steps(traj: Trajectory, max_frames: int) -> list[int]:
    """The states drawn: every one, or ``max_frames`` evenly spaced (first and last kept)."""
    states = np.unique(np.linspace(0, traj.length, min(max_frames, traj.length + 1)).round())
    return [int(k) for k in states]


def frame_seconds(
    scenario: Scenario, traj: Trajectory, frames: int, fps: float | None
) -> list[float]:
    """Seconds each of ``frames`` frames shows: ``1 / fps`` if given, else the control
    period in physics and :data:`GRID_FRAME_SECONDS` on grids; the last at least
    :data:`END_HOLD_SECONDS`."""
    if fps is not None:
        each = 1.0 / fps
    elif scenario.mode == "physics":
        each = float(traj.dt)
    else:
        each = GRID_FRAME_SECONDS
    seconds = [max(each, MIN_FRAME_SECONDS)] * frames
    if seconds:
        seconds[-1] = max(seconds[-1], END_HOLD_SECONDS)
    return seconds


def contacts_in(scenario: Scenario, traj: Trajectory, first: int, last: int) -> Contacts:
    """What touched in the steps that led from state ``first`` to state ``last``."""
    found = Contacts()
    for k in range(first + 1, last + 1):
        if traj.captured[k - 1] or traj.collisions[k - 1]:
            found |= step_contacts(
                scenario, traj.positions[k - 1], traj.positions[k], traj.events, k
            )
    return found


def _who(indices: tuple[int, ...] | list[int]) -> str:
    names = [str(i) for i in indices]
    joined = names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]
    return f"pursuer{'s' if len(names) > 1 else ''} {joined}"


def _when(traj: Trajectory, k: int, physics: bool) -> str:
    """``step k`` (and the simulated time), with no-break spaces: a caption's line is
    never broken inside it."""
    text = f"step {k}" + (f" (t = {k * traj.dt:.3g} s)" if physics else "")
    return text.replace(" ", "\u00a0")


def caption(scenario: Scenario, traj: Trajectory, k: int, contacts: Contacts) -> tuple[str, str]:
    """The caption of the frame of state ``k`` and what it tells (``capture``, ``collision``
    or ``other``): the ending on the last frame, a contact on the frame that shows it."""
    physics, end = scenario.mode == "physics", k == traj.length
    pairs = list(contacts.collisions)
    crash = "; ".join(_who(pair) for pair in pairs)
    if contacts.capturers:
        text = f"CAPTURE: {_who(contacts.capturers)} caught the evader at {_when(traj, k, physics)}"
        return text + (f"; {crash} collided too" if pairs else ""), "capture"
    if pairs:
        mode = scenario.collisions.mode
        if end and mode == "terminate":
            text = f"COLLISION of {crash} at {_when(traj, k, physics)}: the episode ends"
            return text, "collision"
        cost = f"penalty {scenario.rewards.collision:g}" if mode != "off" else "no penalty"
        return f"collision of {crash} at {_when(traj, k, physics)} ({cost})", "collision"
    if end and traj.length >= scenario.max_steps:
        return f"time limit: the evader was not caught in {traj.length} steps", "other"
    so_far = int(traj.collisions[:k].sum())
    if so_far:
        return f"{so_far} collision{'s' if so_far > 1 else ''} so far", "other"
    return "", "other"


def frame_title(scenario: Scenario, traj: Trajectory, k: int, stride: float) -> str:
    """Two lines: the scenario and episode; the step, simulated time, frames' spacing."""
    line = f"step {k} of {traj.length}"
    if scenario.mode == "physics":
        line += f" · t = {k * traj.dt:.1f} s"
    if stride > 1.01:
        line += f" · {stride:.2g} steps/frame"
    return f"{scenario.name} · episode {traj.episode}\n{line}"


def sensing_title(scenario: Scenario, masks: np.ndarray) -> str:
    """The title's third line in a sensing scenario: who knows the evader in this state."""
    knowing = np.flatnonzero(np.asarray(masks)[: scenario.pursuers, -1])
    if not len(knowing):
        return "\nno pursuer knows where the evader is"
    return f"\nthe evader is known to {_who(tuple(int(i) for i in knowing))}"


def sensing_overlay(
    scenario: Scenario, frame: np.ndarray, positions: np.ndarray, masks: np.ndarray
) -> np.ndarray:
    """``frame`` (a :func:`~a2cm_phys.envs.render.render_rgb` picture of ``positions``)
    with the pursuers' sensing ranges and sightings drawn over it (see the module docs);
    ``masks`` ``(N + 1, N + 1)`` are the state's. The overlay is drawn on a transparent
    figure laid out as ``render_rgb`` lays out its arena, then blended in."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.patches import Circle, Rectangle

    height, width = 4 * HEIGHT_RATIO, frame.shape[1]
    fig = Figure(figsize=(4, height), dpi=width / 4)
    fig.patch.set_alpha(0.0)
    ax = fig.add_axes((0.05, 0.95 / height, 0.9, 3.6 / height))  # render_rgb's arena axes
    size = scenario.size
    ax.set_xlim(-_WALL, size + _WALL)
    ax.set_ylim(-_WALL, size + _WALL)
    ax.set_aspect("equal")
    ax.axis("off")
    arena = Rectangle((0, 0), size, size, transform=ax.transData)
    centres = np.asarray(positions, dtype=np.float64) + (0.5 if scenario.mode == "grid" else 0.0)
    r, n = float(scenario.sensing.radius), scenario.pursuers
    for i, (x, y) in enumerate(centres[:n]):
        colour = PURSUER_COLOURS[i % len(PURSUER_COLOURS)]
        if scenario.mode == "grid":
            reach = np.floor(r) + 0.5  # whole cells within Chebyshev distance r
            patch = Rectangle((x - reach, y - reach), 2 * reach, 2 * reach)
        else:
            patch = Circle((x, y), r)
        patch.set(fc=colour, alpha=RANGE_ALPHA, lw=0)
        ax.add_patch(patch)
        patch.set_clip_path(arena)
    own = in_range(scenario, positions)
    for i in np.flatnonzero(np.asarray(masks)[:n, n]):
        colour = PURSUER_COLOURS[i % len(PURSUER_COLOURS)]
        (x, y), (ex, ey) = centres[i], centres[n]
        style = (
            {"ls": "-", "lw": 2.2, "alpha": 0.9}
            if own[i]
            else {"ls": "--", "lw": 1.4, "alpha": 0.6}
        )
        ax.plot([x, ex], [y, ey], color=colour, **style)
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    over = np.asarray(canvas.buffer_rgba()).astype(np.float64)
    if over.shape[:2] != frame.shape[:2]:  # render_rgb's layout changed: never misplace
        raise RuntimeError(f"sensing overlay {over.shape[:2]} != frame {frame.shape[:2]}")
    alpha = over[..., 3:] / 255.0
    return np.round(frame * (1 - alpha) + over[..., :3] * alpha).astype(np.uint8)


def episode_picture(
    scenario: Scenario,
    traj: Trajectory,
    max_frames: int,
    pixels: int = DEFAULT_PIXELS,
    fps: float | None = None,
    progress: bool = True,
) -> EpisodePicture:
    """The frames of (at most ``max_frames`` evenly spaced) states of an episode, ``pixels``
    wide, with their titles, captions and the seconds each shows (:func:`frame_seconds`).
    Physics episodes show each agent's path so far as a trail: every state up to the
    frame's, also those between frames, so a continuous path is drawn whole however few
    frames; a frame marks the contacts of the steps since the previous frame. ``progress``
    counts the frames drawn on stderr. A sensing scenario's frames show the ranges and
    sightings (:func:`sensing_overlay`)."""
    steps = frame_steps(traj, max_frames)
    masks = trajectory_masks(scenario, traj)
    stride = traj.length / max(len(steps) - 1, 1)
    trails = scenario.mode == "physics"
    picture = EpisodePicture(steps=steps, seconds=frame_seconds(scenario, traj, len(steps), fps))
    previous = 0
    bar = Progress(f"drawing episode {traj.episode}", len(steps), "frames", enabled=progress)
    with bar:
        for k in steps:
            contacts = contacts_in(scenario, traj, previous, k)
            text, kind = caption(scenario, traj, k, contacts)
            vel = None if traj.velocities is None else traj.velocities[k]
            title = frame_title(scenario, traj, k, stride)
            if masks is not None:
                title += sensing_title(scenario, masks[k])
            frame = render_rgb(
                scenario,
                traj.positions[k],
                vel,
                title=title,
                pixels=pixels,
                trail=traj.positions[:k] if trails else None,
                contacts=contacts,
                caption=text,
                caption_kind=kind,
                headings=None if traj.headings is None else traj.headings[k],
            )
            if masks is not None:
                frame = sensing_overlay(scenario, frame, traj.positions[k], masks[k])
            picture.frames.append(frame)
            picture.captions.append(text.replace("\u00a0", " "))
            previous = k
            bar.update(1)
    return picture


def save_picture(picture: EpisodePicture, path: Path, kind: str) -> None:
    """A GIF animation (each frame for its seconds) or a PNG contact sheet (up to 4 frames
    a row) of ``picture``."""
    from PIL import Image

    images = [Image.fromarray(f) for f in picture.frames]
    path.parent.mkdir(parents=True, exist_ok=True)
    if kind == "gif":
        durations = [round(1000 * s) for s in picture.seconds]
        images[0].save(path, save_all=True, append_images=images[1:], duration=durations, loop=0)
        return
    cols = min(4, len(images))
    rows = -(-len(images) // cols)
    w, h = images[0].size
    sheet = Image.new("RGB", (cols * w, rows * h), "white")
    for i, im in enumerate(images):
        sheet.paste(im, ((i % cols) * w, (i // cols) * h))
    sheet.save(path)


def run_name(source: Path) -> str:
    """A run's short name from what ``replay`` was given: a run folder's name, the folder
    of a run's log file (``episodes*.mcap``), else the file's stem."""
    source = Path(source).resolve()
    if source.is_dir():
        return source.name
    if source.name.startswith("episodes") and source.parent.name:
        return source.parent.name
    return source.stem


def picture_path(source: Path, episode: int, kind: str, out: Path | None, several: bool) -> Path:
    """Where episode ``episode``'s picture goes: ``out`` (with ``-epN`` added to its name
    when ``several`` episodes are drawn), else ``RUNNAME-epN.gif|png`` in the current
    folder (a relative path)."""
    return picture_file(run_name(source), episode, kind, out, several)


def picture_file(stem: str, episode: int, kind: str, out: Path | None, several: bool) -> Path:
    """:func:`picture_path` for pictures named ``stem`` rather than after a run: ``out``
    (``-epN`` added when ``several``), else ``STEM-epN.gif|png`` in the current folder."""
    if out is None:
        return Path(f"{stem}-ep{episode}.{kind}")
    return out.with_name(f"{out.stem}-ep{episode}{out.suffix}") if several else out
