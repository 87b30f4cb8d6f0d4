"""The pictures ``evaluate --render gif|png`` draws of episodes it plays: the options
(:func:`add_render_options`), their checks before anything is played
(:func:`check_render`), and the episodes played and drawn into files
(:func:`draw_episodes`, over :mod:`a2cm_phys.analysis.playback` and
:mod:`a2cm_phys.analysis.pictures`). Its own module so that ``evaluate``'s stays small; the
options read as ``replay``'s picture options do.
"""

from __future__ import annotations

import argparse
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .options import UsageError, int_range, output_file, positive_float

if TYPE_CHECKING:
    from ..analysis.policies import Matchup

# The drawing and the game are imported inside draw_episodes, after the command line is
# parsed, so that --help answers at once.

DEFAULT_PIXELS = 480
"""``--size``'s default (:data:`a2cm_phys.envs.render.DEFAULT_PIXELS`, not imported here so
that ``--help`` stays fast)."""


def add_render_options(p: argparse.ArgumentParser) -> None:
    """``--render`` and the options of the pictures it draws."""
    g = p.add_argument_group("pictures of episodes played after the report")
    g.add_argument(
        "--render",
        choices=("gif", "png"),
        help="play --render-episodes more episodes (same pairing, seed and --greedy) and draw"
        " each: a GIF animation at the game's pace, or a PNG contact sheet (default: none)",
    )
    g.add_argument(
        "--out",
        type=Path,
        metavar="FILE",
        help="the file of --render (default: STEM-epN.gif|png in the current folder, STEM"
        " being pretrained-NAME, onnx-FOLDER, POLICY-SCENARIO or the run's name); with"
        " several episodes, -epN is added to its name",
    )
    g.add_argument(
        "--render-episodes",
        type=int_range(1, 1000),
        default=1,
        metavar="K",
        help="episodes played and drawn with --render, one file each",
    )
    add_drawing_options(g)


def add_drawing_options(g: argparse._ActionsContainer) -> None:
    """``--size``, ``--fps`` and ``--max-frames``: how an episode is drawn (``evaluate``
    and ``replay`` alike)."""
    g.add_argument(
        "--size",
        type=int_range(120, 4000),
        default=DEFAULT_PIXELS,
        metavar="PIXELS",
        help="picture width in pixels (the height is 1.3 x, for the caption and legend)",
    )
    g.add_argument(
        "--fps",
        type=positive_float,
        help="GIF frames per second (default: the control rate 1/physics.dt in physics,"
        " 2 on grids; the last frame stays 2 s)",
    )
    g.add_argument(
        "--max-frames",
        type=int_range(1, 10_000),
        metavar="N",
        help="frames drawn at most, evenly spaced over the episode (default: 200 for gif,"
        " 12 for png)",
    )


def check_render(args: argparse.Namespace, parser: argparse.ArgumentParser) -> None:
    """A :class:`UsageError` for picture options without ``--render``, ``--render`` with
    ``--cross-play``, or an ``--out`` that cannot be written: before anything is played."""
    if args.render is None:
        given = [
            option
            for option in ("out", "render_episodes", "size", "fps", "max_frames")
            if getattr(args, option) != parser.get_default(option)
        ]
        if given:
            raise UsageError(
                f"--{given[0].replace('_', '-')} draws pictures: give --render gif|png"
            )
        return
    if args.cross_play:
        raise UsageError("--render draws the episodes of one pairing: not with --cross-play")
    if args.out is not None:
        output_file(args.out, "--out", (f".{args.render}",))


def draw_episodes(
    args: argparse.Namespace, game: Matchup, pursuers: str
) -> Iterator[dict[str, Any]]:
    """Play and draw ``--render-episodes`` episodes of ``game`` (see the module docstring);
    yield each file written, as the JSON report lists it, once it is written."""
    from ..analysis.pictures import DEFAULT_MAX_FRAMES, episode_picture, picture_file, save_picture
    from ..analysis.playback import picture_stem, play_episodes

    show, kind = not args.no_progress, args.render
    stem = picture_stem(pursuers, game.scenario.name)
    several = args.render_episodes > 1
    for traj in play_episodes(game, args.render_episodes, args.seed, show):
        out = picture_file(stem, traj.episode, kind, args.out, several)
        if args.out is None:
            output_file(out, "--out", (f".{kind}",))
        frames = args.max_frames or DEFAULT_MAX_FRAMES[kind]
        picture = episode_picture(game.scenario, traj, frames, args.size, args.fps, show)
        save_picture(picture, out, kind)
        yield {
            "file": str(out),
            "episode": traj.episode,
            "seed": traj.seed,
            "length": traj.length,
            "frames": len(picture.frames),
            "ending": picture.captions[-1],
        }
