"""``python -m a2cm_phys.replay RUN``: look into a run log.

Without options: a summary of the run (episodes, steps, captures, collisions, mean length
and return) over its simulated time, by tenths of the run. ``--episode N …`` prints
episodes (``--render text``, the default: boards whose symbols a legend line explains) or
draws them (``--render gif`` an animation at the game's pace, ``--render png`` a contact
sheet), one file per episode, ``RUNNAME-epN.gif`` in the current folder unless ``--out``
names it; a frame has a legend, marks a capture (a ring) and a collision (a star) and says
how the episode ended; physics episodes are drawn with each agent's path as a trail.
``--verify`` re-simulates the logged episodes (or the ``--episode`` ones) from their seeds
and the logged actions (the pursuers' moves or commands, and a learned evader's) with the
scenario stored in the log, shows its progress on stderr, and exits 1 on any divergence.
``--export-foxglove OUT.mcap`` writes ``foxglove.SceneUpdate`` frames of the chosen
(default: all logged) episodes, one after the other on topic ``/scene``, at the control
rate. Errors (missing file, not a run log, unknown episode) print one message and exit 2.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from .options import Parser, UsageError, int_range, output_file, positive_float, run_cli
from .picture_options import add_drawing_options

if TYPE_CHECKING:
    from ..record.runlog import RunLog

SAMPLE = 10
"""Episodes ``--export-foxglove`` and ``--serve`` take without ``--episode``: the last ones
logged (the whole log of the main job would be 55 MB of scenes)."""


def build_parser() -> argparse.ArgumentParser:
    """The ``python -m a2cm_phys.replay`` argument parser."""
    p = Parser(
        prog="python -m a2cm_phys.replay",
        description="Look into a run log: its summary table over training, episodes as text\n"
        "or pictures (--episode), a re-simulation (--verify), Foxglove scenes.",
    )
    p.add_argument("file", type=Path, help="a run folder (every part of its log), or one .mcap")
    p.add_argument(
        "--episode",
        type=int_range(0),
        nargs="+",
        metavar="N",
        help="episode id(s) to print or draw (default: none; the run's summary table)",
    )
    p.add_argument(
        "--render",
        choices=("text", "gif", "png"),
        default="text",
        help="how --episode is shown: text boards, a GIF animation, a PNG contact sheet",
    )
    p.add_argument(
        "--out",
        type=Path,
        metavar="FILE",
        help="the file of --render gif|png (default: RUNNAME-epN.gif|png in the current"
        " folder); with several episodes, -epN is added to its name",
    )
    add_drawing_options(p)
    _add_log_options(p)
    return p


def _add_log_options(p: argparse.ArgumentParser) -> None:
    """The options that read or stream the whole log: verify, Foxglove, the table."""
    p.add_argument(
        "--verify",
        action="store_true",
        help="re-simulate the logged episodes and compare them with the log; progress on stderr",
    )
    p.add_argument(
        "--export-foxglove",
        type=Path,
        metavar="OUT.mcap",
        help=f"write the --episode(s) as Foxglove scenes to OUT.mcap (default: the last"
        f" {SAMPLE} logged episodes, and it says so)",
    )
    p.add_argument(
        "--serve",
        nargs="?",
        const="",
        metavar="[HOST:]PORT",
        help=f"stream the --episode(s) to Foxglove over its WebSocket protocol, waiting for a"
        f" client (default: off; given alone, 127.0.0.1:8765; episodes: the last {SAMPLE}"
        f" logged)",
    )
    p.add_argument(
        "--wait",
        type=positive_float,
        metavar="SECONDS",
        help="--serve waits this long for a client before playing (default: as long as it takes)",
    )
    p.add_argument(
        "--speed",
        type=positive_float,
        default=1.0,
        metavar="K",
        help="--serve plays K times faster than the simulated time",
    )
    p.add_argument(
        "--parts",
        type=int_range(1, 1000),
        default=10,
        metavar="N",
        help="rows of the summary table: equal spans of the run's simulated time",
    )


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command; return the exit code (2 on errors, 1 on a failed --verify)."""
    return run_cli(_main, argv)


def _main(argv: Sequence[str]) -> int:
    args = build_parser().parse_args(argv)
    if args.out is not None:
        output_file(args.out, "--out", (f".{args.render}",) if args.render != "text" else ())
    if args.export_foxglove is not None:
        output_file(args.export_foxglove, "--export-foxglove", (".mcap",))
    from ..analysis.episodes import describe, summary_table
    from ..record.parts import read_run

    log = read_run(args.file)
    if args.verify:
        return _verify(args, log)
    if args.export_foxglove or args.serve is not None:
        return _foxglove(args, log)
    if args.episode:
        return _episodes(args, log)
    print(describe(log))
    print()
    print(summary_table(log, args.parts))
    return 1 if log.damaged else 0


def _verify(args: argparse.Namespace, log: RunLog) -> int:
    from ..analysis.episodes import find_trajectory, integrity_problems, log_state
    from ..record.verify import verify

    if not log.clean:
        print(f"note: {log_state(log)}; verifying the {len(log.logged_episodes)} recovered"
              " trajectories")  # fmt: skip
    chosen = None if args.episode is None else [find_trajectory(log, e) for e in args.episode]
    status = verify(log, chosen)
    problems = integrity_problems(Path(args.file), log)
    for problem in problems:
        print(f"INTEGRITY {problem}")
    n = log.n_episodes
    verdict = "holds" if not problems else f"BROKEN ({len(problems)} problems)"
    print(f"integrity: {n:,} episodes, ids 0 to {n - 1:,} each once, none lost: {verdict}")
    return 1 if problems or log.damaged else status


def _foxglove(args: argparse.Namespace, log: RunLog) -> int:
    """``--export-foxglove`` and ``--serve``: the chosen episodes, or the last logged."""
    from ..analysis.episodes import EXPORT_TOPIC, export_foxglove, find_trajectory

    episodes = args.episode
    if not episodes:
        episodes = list(log.logged_episodes[-SAMPLE:])
        if not episodes:
            raise UsageError(f"{args.file}: no episode's trajectory is logged")
        print(
            f"note: no --episode given: taking the last {len(episodes)} logged"
            f" ({episodes[0]} to {episodes[-1]}); --episode N [N ...] chooses",
            file=sys.stderr,
        )
    for episode in episodes:
        find_trajectory(log, episode)  # one line naming an episode the log lacks
    if args.export_foxglove:
        n = export_foxglove(log, args.export_foxglove, episodes)
        print(
            f"wrote {n} episodes as {EXPORT_TOPIC} (foxglove.SceneUpdate) to {args.export_foxglove}"
        )
    if args.serve is not None:
        from ..record.sdk import address
        from ..record.serve import serve_episodes

        host, port = address(args.serve, "--serve")
        n = serve_episodes(
            log,
            episodes,
            host,
            port,
            speed=args.speed,
            wait=args.wait,
            ready=lambda url: print(
                f"serving on {url} (in Foxglove: Open connection); waiting for a client",
                flush=True,
            ),
        )
        print(f"served {n} episodes")
    return 0


def _episodes(args: argparse.Namespace, log: RunLog) -> int:
    from ..analysis.episodes import episode_text, find_trajectory
    from ..analysis.pictures import (
        DEFAULT_MAX_FRAMES,
        episode_picture,
        picture_path,
        save_picture,
    )

    scenario = log.scenario
    several = len(args.episode) > 1
    for episode in args.episode:
        traj = find_trajectory(log, episode)
        if args.render == "text":
            print(episode_text(scenario, traj))
            continue
        out = picture_path(args.file, episode, args.render, args.out, several)
        if args.out is None:
            output_file(out, "--out", (f".{args.render}",))
        frames = args.max_frames or DEFAULT_MAX_FRAMES[args.render]
        picture = episode_picture(scenario, traj, frames, args.size, args.fps)
        save_picture(picture, out, args.render)
        print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
