"""Re-simulate logged episodes and compare them with the log: ``replay --verify``.

Each trajectory is replayed from its seed and the pursuers' logged actions with the
scenario stored in the log, and compared step by step (positions, velocities, the evader's
moves, rewards, captures, collisions, wall contacts, contact events, the episode's end);
then the episode's summary is checked against the trajectory (env, seed, length, return,
captured, truncated, ended by a collision, collisions, wall contacts), so that a changed
summary is caught as well.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from ..config import Scenario
from ..envs.factory import make_core
from .reader import RunLog, Trajectory


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


def summary_mismatch(log: RunLog, traj: Trajectory, scenario: Scenario) -> str | None:
    """``None`` if the summary of ``traj``'s episode agrees with the trajectory, else what
    differs (a summary missing from the log is a mismatch too)."""
    ep = log.episodes
    rows = np.flatnonzero(ep["episode"] == traj.episode)
    if len(rows) != 1:
        return f"{len(rows)} summaries of this episode in the log (expected 1)"
    i = int(rows[0])
    last = traj.length - 1
    captured = last >= 0 and bool(traj.captured[last])
    collided = scenario.collisions.mode == "terminate" and last >= 0 and traj.collisions[last] > 0
    terminated = captured or collided
    expected = {
        "env": traj.env,
        "seed": traj.seed,
        "length": traj.length,
        "return": float(traj.reward.sum()),
        "captured": captured,
        "truncated": traj.length >= scenario.max_steps and not terminated,
        "collision_terminated": terminated and not captured,
        "collisions": int(traj.collisions.sum()),
        "wall_contacts": int(traj.wall_contacts.sum()),
    }
    for key, want in expected.items():
        got = ep[key][i].item()
        same = np.isclose(got, want, rtol=1e-12, atol=0) if key == "return" else got == want
        if not same:
            return f"summary {key} is {got!r}, the trajectory gives {want!r}"
    return None


def verify(log: RunLog, trajs: Iterable[Trajectory] | None = None) -> int:
    """Verify ``trajs`` of ``log`` (default: every logged one) and their summaries; print a
    report; 0 if all match, 1 otherwise (or if there is nothing to verify)."""
    scenario = log.scenario
    trajs = log.trajectories() if trajs is None else trajs
    core = make_core(scenario, 1)
    count = steps = 0
    bad: list[str] = []
    for traj in trajs:
        problem = verify_trajectory(scenario, traj, core) or summary_mismatch(log, traj, scenario)
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
