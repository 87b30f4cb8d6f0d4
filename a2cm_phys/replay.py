"""``python -m a2cm_phys.replay FILE.mcap``: look into a run log.

Without options: a summary of the run (episodes, steps, captures, collisions, mean length
and return) over time, by tenths of the run. ``--episode N …`` prints episodes (``--render
text``, the default) or draws them (``--render gif`` an animation, ``--render png`` a
contact sheet; ``--out`` names the file). ``--verify`` re-simulates the logged episodes
(or the ``--episode`` ones) from their seeds and the pursuers' actions with the scenario
stored in the log, and exits 1 on any divergence. ``--export-foxglove OUT.mcap`` writes
``foxglove.SceneUpdate`` frames of the chosen (default: all logged) episodes, one after
the other on topic ``/scene``. Errors (missing file, not a run log, unknown episode) print
one message and exit 2.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from .config import Scenario
from .envs.core import ACTION_NAMES
from .envs.factory import make_core
from .record.reader import LogError, RunLog, Trajectory, read_run

EXPORT_TOPIC = "/scene"
"""Topic of ``--export-foxglove`` files."""


class ReplayError(Exception):
    """A request the log cannot satisfy (e.g. an episode it does not hold)."""


# --------------------------------------------------------------------------- summary


def summary_table(log: RunLog, parts: int = 10) -> str:
    """A markdown table of the run by ``parts`` equal spans of the log clock."""
    ep = log.episodes
    if not len(ep["episode"]):
        return "(no finished episodes)"
    end = float(ep["t1"].max())
    edges = np.linspace(0.0, end, parts + 1)
    which = np.clip(np.searchsorted(edges, ep["t1"], side="left") - 1, 0, parts - 1)
    lines = [
        "| part | run time (s) | episodes | env steps | captured | truncated | collisions "
        "| coll./ep. | mean length | mean return |",
        "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |",
    ]
    rows = [(f"{100 * k // parts}–{100 * (k + 1) // parts}%", which == k) for k in range(parts)]
    rows.append(("all", np.ones_like(which, dtype=bool)))
    for k, (name, mask) in enumerate(rows):
        n = int(mask.sum())
        span = f"{edges[k]:.0f}–{edges[k + 1]:.0f}" if k < parts else f"0–{end:.0f}"
        if not n:
            lines.append(f"| {name} | {span} | 0 | 0 | | | | | | |")
            continue
        cap, trunc = int(ep["captured"][mask].sum()), int(ep["truncated"][mask].sum())
        col = int(ep["collisions"][mask].sum())
        lines.append(
            f"| {name} | {span} | {n} | {int(ep['length'][mask].sum())} "
            f"| {cap} ({100 * cap / n:.0f}%) | {trunc} | {col} | {col / n:.2f} "
            f"| {ep['length'][mask].mean():.1f} | {ep['return'][mask].mean():.4g} |"
        )
    return "\n".join(lines)


def describe(log: RunLog) -> str:
    """Header lines: file, state, scenario, algorithm, provenance."""
    meta, sc = log.metadata, log.scenario
    state = (
        "closed cleanly"
        if log.clean
        else (
            f"NOT closed cleanly (killed or still running): recovered {log.n_episodes} episodes "
            f"from its complete chunks; reading stopped at {log.error or 'the end of the file'}"
        )
    )
    logged = len(log.logged_episodes)
    lines = [
        f"{log.path}: {state}",
        f"{log.n_episodes} episodes ({logged} with trajectories), "
        f"{int(log.episodes['length'].sum())} env steps, {len(log.updates)} updates",
        f"scenario {sc.name}: {sc.mode}, {sc.size}x{sc.size}, {sc.pursuers} pursuers, "
        f"{sc.evader} evader, collisions {sc.collisions.mode}, max_steps {sc.max_steps}",
        f"label {log.label} · seed {meta.get('seed', '?')} · a2cm_phys {meta.get('version', '?')}"
        f" · {meta.get('created', '')}",
        f"command: {meta.get('command', '?')}",
    ]
    return "\n".join(lines)


# --------------------------------------------------------------------------- episodes


def _trajectory(log: RunLog, episode: int) -> Trajectory:
    if not 0 <= episode < int(log.episodes["episode"].max(initial=-1)) + 1:
        raise ReplayError(
            f"unknown episode {episode}: the log holds episodes 0–"
            f"{int(log.episodes['episode'].max(initial=-1))}"
        )
    try:
        return log.trajectory(episode)
    except KeyError:
        every = log.metadata.get("log_every", "?")
        raise ReplayError(
            f"episode {episode} has no logged trajectory (log_every={every}; "
            f"logged: {_ranges_text(log.logged_episodes)})"
        ) from None


def _ranges_text(ids: Sequence[int], limit: int = 6) -> str:
    if not ids:
        return "none"
    shown = ", ".join(map(str, ids[:limit]))
    return shown + (f", … ({len(ids)} in all)" if len(ids) > limit else "")


def episode_text(scenario: Scenario, traj: Trajectory) -> str:
    """Every state of an episode as a text board, with the actions that led to it."""
    from .render import render_text

    n = scenario.pursuers
    out = [
        f"episode {traj.episode}: env {traj.env}, seed {traj.seed}, {traj.length} steps, "
        f"return {traj.reward.sum():g}, {'captured' if traj.captured.any() else 'not captured'}"
        f", {int(traj.collisions.sum())} collisions"
    ]
    for k in range(traj.length + 1):
        head = f"t={k}"
        if k:
            acts = " ".join(f"{i}:{ACTION_NAMES[a]}" for i, a in enumerate(traj.actions[k - 1, :n]))
            head += (
                f"  actions {acts} E:{ACTION_NAMES[traj.actions[k - 1, n]]}"
                f"  reward {traj.reward[k - 1]:g}"
            )
            if traj.captured[k - 1]:
                head += "  CAPTURED"
            if traj.collisions[k - 1]:
                head += f"  collisions {traj.collisions[k - 1]}"
        out += [head, render_text(scenario, traj.positions[k]), ""]
    return "\n".join(out)


def episode_frames(scenario: Scenario, traj: Trajectory, max_frames: int) -> list[np.ndarray]:
    """RGB frames of (at most ``max_frames`` evenly spaced) states of an episode."""
    from .render import render_rgb

    states = np.unique(np.linspace(0, traj.length, min(max_frames, traj.length + 1)).round())
    frames = []
    for k in states.astype(int):
        vel = None if traj.velocities is None else traj.velocities[k]
        title = f"episode {traj.episode}  step {k}/{traj.length}"
        if k == traj.length and traj.captured[-1]:
            title += "  captured"
        frames.append(render_rgb(scenario, traj.positions[k], vel, title=title, pixels=240))
    return frames


def save_picture(frames: list[np.ndarray], path: Path, kind: str, fps: float) -> None:
    """A GIF animation or a PNG contact sheet (up to 4 frames a row) of ``frames``."""
    from PIL import Image

    images = [Image.fromarray(f) for f in frames]
    path.parent.mkdir(parents=True, exist_ok=True)
    if kind == "gif":
        images[0].save(
            path, save_all=True, append_images=images[1:], duration=int(1000 / fps), loop=0
        )
        return
    cols = min(4, len(images))
    rows = -(-len(images) // cols)
    w, h = images[0].size
    sheet = Image.new("RGB", (cols * w, rows * h), "white")
    for i, im in enumerate(images):
        sheet.paste(im, ((i % cols) * w, (i // cols) * h))
    sheet.save(path)


# --------------------------------------------------------------------------- verify


def verify_trajectory(
    scenario: Scenario, traj: Trajectory, core: object | None = None
) -> str | None:
    """Re-simulate ``traj`` from its seed and pursuer actions; ``None`` if it matches the
    log exactly, else a description of the first divergence."""
    core = core if core is not None else make_core(scenario, 1)
    n, length = scenario.pursuers, traj.length
    core.reset(np.array([0]), np.array([traj.seed], dtype=np.uint64))
    sim = {
        "positions": np.zeros_like(traj.positions),
        "evader action": np.zeros(length, dtype=np.int64),
        "reward": np.zeros(length),
        "captured": np.zeros(length, dtype=bool),
        "collisions": np.zeros(length, dtype=np.int64),
        "wall contacts": np.zeros(length, dtype=np.int64),
        "episode end": np.zeros(length, dtype=bool),
    }
    physics = traj.velocities is not None
    if physics:
        sim["velocities"] = np.zeros_like(traj.velocities)
        sim["velocities"][0] = core.velocities()[0]
    sim["positions"][0] = core.positions()[0]
    sim_events: list[tuple] = []
    actions = traj.actions[:, :n].astype(np.int64)
    for k in range(length):
        out = core.step(actions[k : k + 1])
        sim["positions"][k + 1] = core.positions()[0]
        if physics:
            sim["velocities"][k + 1] = core.velocities()[0]
        sim["evader action"][k] = out.evader_action[0]
        sim["reward"][k] = out.reward[0]
        sim["captured"][k] = out.captured[0]
        sim["collisions"][k] = out.collisions[0]
        sim["wall contacts"][k] = out.wall_contacts[0]
        sim["episode end"][k] = out.terminated[0] or out.truncated[0]
        if out.events is not None:
            sim_events += [tuple(e) for e in out.events[0]]
        if sim["episode end"][k] and k < length - 1:
            break
    end = np.zeros(length, dtype=bool)
    end[-1] = True
    logged = {
        "positions": traj.positions,
        "velocities": traj.velocities,
        "evader action": traj.actions[:, n],
        "reward": traj.reward,
        "captured": traj.captured,
        "collisions": traj.collisions,
        "wall contacts": traj.wall_contacts,
        "episode end": end,
    }
    first: tuple[int, str] | None = None
    for name, sim_values in sim.items():
        log_values = logged[name]
        differs = (log_values != sim_values).reshape(len(log_values), -1).any(axis=1)
        if differs.any():
            k = int(np.argmax(differs))
            state = name in ("positions", "velocities")  # row k is the state after k steps
            step = k if state else k + 1
            if first is None or step < first[0]:
                first = (step, _divergence((name, step, log_values[k], sim_values[k])))
    if first is not None:
        return first[1]
    logged_events = [tuple(e) for e in traj.events or ()]
    if traj.events is not None and logged_events != sim_events:
        i = next(
            (i for i, (a, b) in enumerate(zip(logged_events, sim_events, strict=False)) if a != b),
            min(len(logged_events), len(sim_events)),
        )
        return (
            f"contact events differ from event {i}: logged "
            f"{logged_events[i : i + 2]}, re-simulated {sim_events[i : i + 2]}"
        )
    return None


def _divergence(check: tuple[str, int, object, object]) -> str:
    name, k, logged, sim = check
    fmt = lambda v: np.array2string(np.asarray(v), separator=",").replace("\n", "")  # noqa: E731
    return f"{name} differ at step {k}: logged {fmt(logged)}, re-simulated {fmt(sim)}"


def verify(log: RunLog, episodes: list[int] | None) -> int:
    """Verify logged episodes; print a report; 0 if all match, 1 otherwise."""
    scenario = log.scenario
    core = make_core(scenario, 1)
    trajs = log.trajectories() if episodes is None else (_trajectory(log, e) for e in episodes)
    count = steps = 0
    bad: list[str] = []
    for traj in trajs:
        problem = verify_trajectory(scenario, traj, core)
        count, steps = count + 1, steps + traj.length
        if problem:
            bad.append(f"episode {traj.episode} (env {traj.env}, seed {traj.seed}): {problem}")
    if not count:
        print("verify: the log holds no trajectories to verify")
        return 1
    for line in bad[:20]:
        print(f"DIVERGED {line}")
    if len(bad) > 20:
        print(f"… and {len(bad) - 20} more")
    verdict = "all match" if not bad else f"{len(bad)} DIVERGED"
    print(f"verify: {count} episodes ({steps} steps) re-simulated with {scenario.name}: {verdict}")
    return 1 if bad else 0


# --------------------------------------------------------------------------- export


def export_foxglove(log: RunLog, out: Path, episodes: list[int] | None) -> int:
    """Write SceneUpdate frames of ``episodes`` (default all logged) to ``out``, one
    episode after the other on :data:`EXPORT_TOPIC`; return the number of episodes."""
    import dataclasses
    import json

    from mcap.writer import CompressionType, Writer

    from .record.scene import episode_scenes
    from .record.schemas import METADATA_NAME, SCENE_SCHEMA, schema_bytes

    scenario = log.scenario
    trajs = log.trajectories() if episodes is None else (_trajectory(log, e) for e in episodes)
    out.parent.mkdir(parents=True, exist_ok=True)
    count, clock = 0, 0.0
    with open(out, "wb") as fh:
        writer = Writer(fh, compression=CompressionType.ZSTD)
        writer.start(library="a2cm_phys replay")
        writer.add_metadata(METADATA_NAME, {k: json.dumps(v) for k, v in log.metadata.items()})
        schema = writer.register_schema(
            SCENE_SCHEMA["title"], "jsonschema", schema_bytes(SCENE_SCHEMA)
        )
        channel = writer.register_channel(EXPORT_TOPIC, "json", schema)
        for traj in trajs:
            shifted = dataclasses.replace(traj, t0=clock)
            for log_time, data in episode_scenes(scenario, shifted):
                writer.add_message(channel, log_time, data, log_time)
            clock += (traj.length + 2) * traj.dt
            count += 1
        writer.finish()
    return count


# --------------------------------------------------------------------------- CLI


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m a2cm_phys.replay", description=__doc__.split("\n\n")[0].split(": ", 1)[-1]
    )
    p.add_argument("file", type=Path, help="episodes.mcap, or a run folder holding one")
    p.add_argument("--episode", type=int, nargs="+", metavar="N", help="episode id(s)")
    p.add_argument("--render", choices=("text", "gif", "png"), default="text")
    p.add_argument("--out", type=Path, help="output file of --render gif|png")
    p.add_argument("--fps", type=float, default=4.0, help="gif frames per second")
    p.add_argument("--max-frames", type=int, default=200, help="frames per gif/png at most")
    p.add_argument("--verify", action="store_true", help="re-simulate and compare")
    p.add_argument("--export-foxglove", type=Path, metavar="OUT.mcap")
    p.add_argument("--parts", type=int, default=10, help="rows of the summary table")
    return p


def main(argv: list[str] | None = None) -> int:
    """Run the command; return the exit code (2 on errors, 1 on a failed --verify)."""
    args = _parser().parse_args(argv)
    try:
        return _run(args)
    except (LogError, ReplayError) as err:
        print(f"replay: error: {err}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # e.g. piped into head: stop quietly
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except OSError as err:
        print(f"replay: error: {err.filename or ''}: {err.strerror}", file=sys.stderr)
        return 2


def _run(args: argparse.Namespace) -> int:
    log = read_run(args.file)
    if args.verify:
        if not log.clean:
            print(
                f"note: {log.path} was not closed cleanly; verifying the "
                f"{len(log.logged_episodes)} recovered trajectories"
            )
        return verify(log, args.episode)
    if args.export_foxglove:
        n = export_foxglove(log, args.export_foxglove, args.episode)
        print(
            f"wrote {n} episodes as {EXPORT_TOPIC} (foxglove.SceneUpdate) to {args.export_foxglove}"
        )
        return 0
    if args.episode:
        scenario = log.scenario
        for episode in args.episode:
            traj = _trajectory(log, episode)
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
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
