"""A run's log for people (the ``replay`` command prints it): the summary table over training
(:func:`summary_table`), the header (:func:`describe`), an episode as text
(:func:`episode_text`; drawn, in :mod:`.pictures`), Foxglove
scenes of chosen episodes (:func:`export_foxglove`), and the run's invariant read with its
checkpoints and summary (:func:`integrity_problems`)."""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..base.errors import UserError
from ..config import Scenario
from ..envs.core import ACTION_NAMES
from ..record.integrity import check_run_log
from ..record.runlog import RunLog, Trajectory
from ..record.schemas import step_seconds
from ..training import checkpoint
from ..training.rundir import SUMMARY_NAME

EXPORT_TOPIC = "/scene"
"""Topic of ``--export-foxglove`` files."""


TABLE_NOTES = (
    "simulated time: each game's own clock (all games step together; not the wall time);",
    "  an episode is counted in the part of the run it ends in.",
    "env steps: the steps of all games; time limit: episodes that reached max_steps uncaught;",
    "collisions: pursuer-pursuer contacts; return: the team's raw reward summed per episode.",
)
"""What :func:`summary_table`'s columns mean, printed under it."""


class ReplayError(UserError):
    """A request the log cannot satisfy (e.g. an episode it does not hold)."""


# --------------------------------------------------------------------------- summary


def summary_table(log: RunLog, parts: int = 10) -> str:
    """A markdown table of the run by ``parts`` equal spans of its simulated time (each
    game's clock: the games step in lockstep), an episode counted in the span it ends in;
    a line under it says so."""
    ep = log.episodes
    if not len(ep["episode"]):
        return "(no finished episodes)"
    end = float(ep["t1"].max())
    edges = np.linspace(0.0, end, parts + 1)
    which = np.clip(np.searchsorted(edges, ep["t1"], side="left") - 1, 0, parts - 1)
    lines = [
        "| part of the run | simulated time (s) | episodes | env steps | captured "
        "| time limit | collisions | collisions/episode | mean length (steps) | mean return |",
        "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |",
    ]
    rows = [(f"{100 * k // parts}–{100 * (k + 1) // parts}%", which == k) for k in range(parts)]
    rows.append(("all", np.ones_like(which, dtype=bool)))
    evader = ep.get("evader_return")
    if evader is not None:
        lines[0] += " mean evader return |"
        lines[1] += " ---: |"
    for k, (name, mask) in enumerate(rows):
        n = int(mask.sum())
        span = f"{edges[k]:.0f}–{edges[k + 1]:.0f}" if k < parts else f"0–{end:.0f}"
        if not n:
            empty = " |" if evader is not None else ""
            lines.append(f"| {name} | {span} | 0 | 0 | | | | | | |{empty}")
            continue
        cap, trunc = int(ep["captured"][mask].sum()), int(ep["truncated"][mask].sum())
        col = int(ep["collisions"][mask].sum())
        lines.append(
            f"| {name} | {span} | {n} | {int(ep['length'][mask].sum())} "
            f"| {cap} ({100 * cap / n:.0f}%) | {trunc} | {col} | {col / n:.2f} "
            f"| {ep['length'][mask].mean():.1f} | {ep['return'][mask].mean():.4g} |"
            + (f" {evader[mask].mean():.4g} |" if evader is not None else "")
        )
    lines += ["", *TABLE_NOTES]
    return "\n".join(lines)


def integrity_problems(path: Path, log: RunLog) -> list[str]:
    """What breaks the run's invariant (:mod:`a2cm_phys.record.integrity`): the log read
    with the run's checkpoints and summary when ``path`` is a run directory."""
    if not path.is_dir():
        return check_run_log(log)
    counts, problems = checkpoint.saved_counts(path)
    summary = None
    summary_path = path / SUMMARY_NAME
    if summary_path.exists():
        try:
            summary = json.loads(summary_path.read_text(encoding="utf-8"))
        except (OSError, ValueError) as err:
            problems.append(f"{summary_path}: unreadable ({err})")
        if not isinstance(summary, dict):
            summary = None
    return problems + check_run_log(log, counts, summary)


def log_state(log: RunLog) -> str:
    """How the log (or the run's parts) ended."""
    if log.clean:
        return "closed cleanly"
    if log.damaged:
        return (
            f"DAMAGED (a record fails its checks: {log.error}); recovered {log.n_episodes} "
            "episodes from the records before it"
        )
    return (
        f"NOT closed cleanly (killed or still running): recovered {log.n_episodes} episodes "
        f"from its complete chunks; reading stopped at {log.error or 'the end of the file'}"
    )


def describe(log: RunLog) -> str:
    """Header lines: file(s), state, scenario, algorithm, provenance."""
    meta, sc = log.metadata, log.scenario
    where = log.path if len(log.parts) <= 1 else f"{log.path.parent}/"
    lines = [f"{where}: {log_state(log)}"]
    lines += [f"PROBLEM {p}" for p in log.problems]
    if len(log.parts) > 1:
        names = ", ".join(p.name for p in log.parts)
        lines.append(f"{len(log.parts)} parts (one per session, read as one log): {names}")
    logged = len(log.logged_episodes)
    lines += [
        f"{log.n_episodes} episodes ({logged} with trajectories), "
        f"{int(log.episodes['length'].sum())} env steps, {len(log.updates)} updates",
        f"scenario {sc.name}: {sc.mode}, {sc.size}x{sc.size}, {sc.pursuers} pursuers, "
        f"{sc.evader} evader, collisions {sc.collisions.mode}, max_steps {sc.max_steps}"
        + (f", {sc.control} control every {step_seconds(sc):g} s" if sc.mode == "physics" else ""),
        f"label {log.label} · seed {meta.get('seed', '?')} · a2cm_phys {meta.get('version', '?')}"
        f" · {meta.get('created', '')}",
        f"command: {meta.get('command', '?')}",
    ]
    if log.n_episodes:
        lines.append(_time_line(log))
    return "\n".join(lines)


def _time_line(log: RunLog) -> str:
    """The run's simulated time per game and, from the run's summary, its wall time."""
    train = log.metadata.get("train")
    games = train.get("num_envs") if isinstance(train, dict) else None
    text = f"simulated time: {float(log.episodes['t1'].max()):,.0f} s in each game"
    if games:
        text += f" ({games} games stepped together)"
    try:
        summary = json.loads((log.path.parent / SUMMARY_NAME).read_text(encoding="utf-8"))
        wall = float(summary["wall_time_s"])
    except (OSError, ValueError, KeyError, TypeError):
        return text
    return text + f"; wall time of the last session: {wall:,.1f} s ({SUMMARY_NAME})"


# --------------------------------------------------------------------------- episodes


def find_trajectory(log: RunLog, episode: int) -> Trajectory:
    """The logged trajectory of ``episode``; a :class:`ReplayError` saying why if the log
    does not hold it."""
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


def action_text(action: np.ndarray) -> str:
    """One agent's action: a move's name, or a command ``(vx,vy)`` (fractions of max_speed)."""
    if np.ndim(action):
        return f"({action[0]:+.2f},{action[1]:+.2f})"
    return ACTION_NAMES[int(action)]


def _outcome(scenario: Scenario, traj: Trajectory) -> str:
    """How an episode ended, in a few words."""
    if traj.captured.any():
        return "captured"
    if scenario.collisions.mode == "terminate" and traj.length and traj.collisions[-1]:
        return "ended by a collision"
    return "time limit, not captured" if traj.length >= scenario.max_steps else "not captured"


def episode_text(scenario: Scenario, traj: Trajectory) -> str:
    """Every state of an episode as a text board, with the actions that led to it and what
    touched (:data:`~a2cm_phys.envs.render.TEXT_LEGEND` under the header line)."""
    from ..envs.render import TEXT_LEGEND, render_text, step_contacts

    n = scenario.pursuers
    evader_return = (
        "" if traj.evader_reward is None else f", evader return {traj.evader_reward.sum():g}"
    )
    out = [
        f"episode {traj.episode}: env {traj.env}, seed {traj.seed}, {traj.length} steps "
        f"({traj.length * traj.dt:g} s), return {traj.reward.sum():g}{evader_return}, "
        f"{_outcome(scenario, traj)}, {int(traj.collisions.sum())} collision(s)",
        TEXT_LEGEND,
        "",
    ]
    for k in range(traj.length + 1):
        head, contacts = f"t={k}", None
        if k:
            row = traj.actions[k - 1]
            acts = " ".join(f"{i}:{action_text(a)}" for i, a in enumerate(row[:n]))
            head += f"  actions {acts} E:{action_text(row[n])}  reward {traj.reward[k - 1]:g}"
            if traj.evader_reward is not None:
                head += f"  evader reward {traj.evader_reward[k - 1]:g}"
            if traj.captured[k - 1] or traj.collisions[k - 1]:
                before, after = traj.positions[k - 1], traj.positions[k]
                contacts = step_contacts(scenario, before, after, traj.events, k)
            if traj.captured[k - 1]:
                who = ", ".join(map(str, contacts.capturers))
                plural = "s" if len(contacts.capturers) > 1 else ""
                head += f"  CAPTURED (by pursuer{plural} {who})" if who else "  CAPTURED"
            if traj.collisions[k - 1]:
                pairs = "; ".join(f"{i} and {j}" for i, j in contacts.collisions)
                head += f"  collisions {traj.collisions[k - 1]}"
                head += f" (pursuers {pairs})" if pairs else ""
        out += [head, render_text(scenario, traj.positions[k], contacts), ""]
    return "\n".join(out)


# --------------------------------------------------------------------------- export


def export_foxglove(log: RunLog, out: Path, episodes: list[int] | None) -> int:
    """Write SceneUpdate frames of ``episodes`` (default all logged) to ``out``, one
    episode after the other on :data:`EXPORT_TOPIC`; return the number of episodes."""
    import dataclasses
    import json

    from mcap.writer import CompressionType, Writer

    from ..record.scene import episode_scenes
    from ..record.schemas import METADATA_NAME
    from ..record.sdk import register_scene_channel

    scenario = log.scenario
    trajs = log.trajectories() if episodes is None else (find_trajectory(log, e) for e in episodes)
    out.parent.mkdir(parents=True, exist_ok=True)
    count, clock = 0, 0.0
    with open(out, "wb") as fh:
        writer = Writer(fh, compression=CompressionType.ZSTD)
        writer.start(library="a2cm_phys replay")
        writer.add_metadata(METADATA_NAME, {k: json.dumps(v) for k, v in log.metadata.items()})
        channel = register_scene_channel(writer, EXPORT_TOPIC, {})  # the SDK's protobuf schema
        for traj in trajs:
            shifted = dataclasses.replace(traj, t0=clock)
            for log_time, data in episode_scenes(scenario, shifted):
                writer.add_message(channel, log_time, data, log_time)
            clock += (traj.length + 2) * traj.dt
            count += 1
        writer.finish()
    return count
