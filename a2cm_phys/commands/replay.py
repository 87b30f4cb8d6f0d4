"""``python -m a2cm_phys.replay FILE.mcap``: look into a run log.

Without options: a summary of the run (episodes, steps, captures, collisions, mean length
and return) over time, by tenths of the run. ``--episode N …`` prints episodes (``--render
text``, the default) or draws them (``--render gif`` an animation, ``--render png`` a
contact sheet; ``--out`` names the file; physics episodes are drawn with each agent's path
as a trail). ``--verify`` re-simulates the logged episodes (or the ``--episode`` ones) from
their seeds and the logged actions (the pursuers' moves or commands, and a learned
evader's) with the scenario stored in the log, and exits 1 on any divergence.
``--export-foxglove OUT.mcap`` writes ``foxglove.SceneUpdate`` frames of the chosen
(default: all logged) episodes, one after the other on topic ``/scene``, at the control
rate. Errors (missing file, not a run log, unknown episode) print
one message and exit 2.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path

from ..analysis.episodes import (
    EXPORT_TOPIC,
    describe,
    episode_frames,
    episode_text,
    export_foxglove,
    find_trajectory,
    integrity_problems,
    log_state,
    save_picture,
    summary_table,
)
from ..record.parts import read_run
from ..record.verify import verify
from .options import Parser, int_range, output_file, positive_float, run_cli

# --------------------------------------------------------------------------- CLI


def _parser() -> argparse.ArgumentParser:
    p = Parser(
        prog="python -m a2cm_phys.replay", description=__doc__.split("\n\n")[0].split(": ", 1)[-1]
    )
    p.add_argument("file", type=Path, help="a run folder (every part of its log), or one .mcap")
    p.add_argument("--episode", type=int_range(0), nargs="+", metavar="N", help="episode id(s)")
    p.add_argument("--render", choices=("text", "gif", "png"), default="text")
    p.add_argument("--out", type=Path, help="output file of --render gif|png")
    p.add_argument("--fps", type=positive_float, default=4.0, help="gif frames per second")
    p.add_argument(
        "--max-frames", type=int_range(1, 10_000), default=200, help="frames per gif/png at most"
    )
    p.add_argument("--verify", action="store_true", help="re-simulate and compare")
    p.add_argument("--export-foxglove", type=Path, metavar="OUT.mcap")
    p.add_argument("--parts", type=int_range(1, 1000), default=10, help="rows of the summary table")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command; return the exit code (2 on errors, 1 on a failed --verify)."""
    return run_cli(_main, argv)


def _main(argv: Sequence[str]) -> int:
    args = _parser().parse_args(argv)
    if args.out is not None:
        output_file(args.out, "--out", (f".{args.render}",) if args.render != "text" else ())
    if args.export_foxglove is not None:
        output_file(args.export_foxglove, "--export-foxglove", (".mcap",))
    log = read_run(args.file)
    if args.verify:
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
    if args.export_foxglove:
        n = export_foxglove(log, args.export_foxglove, args.episode)
        print(
            f"wrote {n} episodes as {EXPORT_TOPIC} (foxglove.SceneUpdate) to {args.export_foxglove}"
        )
        return 0
    if args.episode:
        scenario = log.scenario
        for episode in args.episode:
            traj = find_trajectory(log, episode)
            if args.render == "text":
                print(episode_text(scenario, traj))
                continue
            out = args.out or log.path.with_name(f"episode_{episode}.{args.render}")
            if len(args.episode) > 1 and args.out:
                out = out.with_name(f"{out.stem}_{episode}{out.suffix}")
            save_picture(
                episode_frames(scenario, traj, args.max_frames), out, args.render, args.fps
            )
            print(f"wrote {out}")
        return 0
    print(describe(log))
    print()
    print(summary_table(log, args.parts))
    return 1 if log.damaged else 0


if __name__ == "__main__":
    raise SystemExit(main())
