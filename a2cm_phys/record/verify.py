"""Re-simulate logged episodes and compare them with the log: ``replay --verify``.

Each trajectory is replayed from its seed and the logged actions with the scenario stored
in the log: the pursuers' (moves, or continuous commands fed back exactly as they were
given, so the env clips them again the same way), and a learned evader's (given as the
step's ``evader_actions``). It is compared step by step (positions, velocities, the evader's
actions, rewards, a learned evader's rewards, captures, collisions, wall contacts, contact
events, the episode's end, the pursuers' headings where the log holds them (differential
drive), and in a sensing scenario's log the sensing masks, recomputed
from the re-simulated positions with :func:`a2cm_phys.envs.sensing.sensed`), bit for bit;
then the episode's summary is checked against the trajectory (env, seed, length, return,
a learned evader's return, captured, truncated, ended by a collision, collisions, wall
contacts), so that a changed summary is caught too.
"""

from __future__ import annotations

from collections.abc import Iterable, Sized

import numpy as np

from ..base.progress import Progress
from ..config import Scenario
from ..envs.core import evader_reward
from ..envs.factory import make_core
from .masks import masks_of, packed
from .runlog import RunLog, Trajectory


def verify_trajectory(
    scenario: Scenario, traj: Trajectory, core: object | None = None
) -> str | None:
    """Re-simulate ``traj`` from its seed and logged actions; ``None`` if it matches the
    log exactly, else a description of the first divergence."""
    core = core if core is not None else make_core(scenario, 1)
    if traj.continuous != scenario.continuous:
        kind = "commands" if traj.continuous else "moves"
        return f"the log holds {kind}, but scenario {scenario.name} has {scenario.control} control"
    sim, sim_events = _resimulate(scenario, traj, core)
    logged = _logged(traj, scenario.pursuers)
    problem = _add_masks(scenario, traj, sim, logged)
    return problem or _first_divergence(sim, logged) or _event_divergence(traj, sim_events)


def _add_masks(
    scenario: Scenario,
    traj: Trajectory,
    sim: dict[str, np.ndarray],
    logged: dict[str, np.ndarray | None],
) -> str | None:
    """Add the sensing masks, re-simulated and logged (as the log's integers), to the
    values compared, if the log holds them (older logs do not); a description if they
    cannot be compared (the wrong shape, or masks in a log of a scenario without sensing)."""
    if traj.sensed is None:
        return None
    if not scenario.sensing.on:
        return f"the log holds sensing masks, but scenario {scenario.name} has no sensing"
    sim["sensing masks"] = packed(masks_of(scenario, sim["positions"]))
    logged["sensing masks"] = packed(traj.sensed)
    if logged["sensing masks"].shape != sim["sensing masks"].shape:
        shape = logged["sensing masks"].shape
        return f"sensing masks of shape {shape}, expected {sim['sensing masks'].shape}"
    return None


def _resimulate(
    scenario: Scenario, traj: Trajectory, core: object
) -> tuple[dict[str, np.ndarray], list[tuple]]:
    """Replay ``traj``'s actions from its seed in ``core`` (one game): the simulated values
    by name (those :func:`_logged` names; a step's values stay zero after an early end) and
    the contact events."""
    n, length = scenario.pursuers, traj.length
    learned = scenario.evader == "learned"
    core.reset(np.array([0]), np.array([traj.seed], dtype=np.uint64))
    sim = {
        "positions": np.zeros_like(traj.positions),
        "evader action": np.zeros_like(traj.actions[:, n]),
        "reward": np.zeros(length),
        "captured": np.zeros(length, dtype=bool),
        "collisions": np.zeros(length, dtype=np.int64),
        "wall contacts": np.zeros(length, dtype=np.int64),
        "episode end": np.zeros(length, dtype=bool),
    }
    check_evader_reward = learned and traj.evader_reward is not None  # format 1: not logged
    if check_evader_reward:
        sim["evader reward"] = np.zeros(length)
    physics = traj.velocities is not None
    if physics:
        sim["velocities"] = np.zeros_like(traj.velocities)
        sim["velocities"][0] = core.velocities()[0]
    turning = traj.headings is not None and scenario.differential
    if turning:
        sim["headings"] = np.zeros_like(traj.headings)
        sim["headings"][0] = core.headings()[0]
    sim["positions"][0] = core.positions()[0]
    sim_events: list[tuple] = []
    actions = np.ascontiguousarray(traj.actions[:, :n])
    evader_actions = np.ascontiguousarray(traj.actions[:, n]) if learned else None
    for k in range(length):
        given = None if evader_actions is None else evader_actions[k : k + 1]
        out = core.step(actions[k : k + 1], given)
        sim["positions"][k + 1] = core.positions()[0]
        if physics:
            sim["velocities"][k + 1] = core.velocities()[0]
        if turning:
            sim["headings"][k + 1] = core.headings()[0]
        sim["evader action"][k] = out.evader_action[0]
        sim["reward"][k] = out.reward[0]
        if check_evader_reward:
            sim["evader reward"][k] = evader_reward(scenario, out)[0]
        sim["captured"][k] = out.captured[0]
        sim["collisions"][k] = out.collisions[0]
        sim["wall contacts"][k] = out.wall_contacts[0]
        sim["episode end"][k] = out.terminated[0] or out.truncated[0]
        if out.events is not None:
            sim_events += [tuple(e) for e in out.events[0]]
        if sim["episode end"][k] and k < length - 1:
            break
    return sim, sim_events


def _logged(traj: Trajectory, pursuers: int) -> dict[str, np.ndarray | None]:
    """The logged values :func:`_resimulate` reproduces, by the same names (the episode ends
    at its last step and nowhere before)."""
    end = np.zeros(traj.length, dtype=bool)
    end[-1] = True
    return {
        "positions": traj.positions,
        "velocities": traj.velocities,
        "headings": traj.headings,
        "evader action": traj.actions[:, pursuers],
        "reward": traj.reward,
        "evader reward": traj.evader_reward,
        "captured": traj.captured,
        "collisions": traj.collisions,
        "wall contacts": traj.wall_contacts,
        "episode end": end,
    }


_STATES = ("positions", "velocities", "headings", "sensing masks")
"""The values compared per state (row 0 the start), not per step."""


def _first_divergence(
    sim: dict[str, np.ndarray], logged: dict[str, np.ndarray | None]
) -> str | None:
    """The earliest step at which a simulated value differs from the logged one, described;
    ``None`` if none does."""
    first: tuple[int, str] | None = None
    for name, sim_values in sim.items():
        log_values = logged[name]
        differs = _differs(log_values, sim_values, bitwise=name == "evader action")
        if differs.any():
            k = int(np.argmax(differs))
            state = name in _STATES  # row k is the state after k steps
            step = k if state else k + 1
            if first is None or step < first[0]:
                first = (step, _divergence((name, step, log_values[k], sim_values[k])))
    return None if first is None else first[1]


def _event_divergence(traj: Trajectory, sim_events: list[tuple]) -> str | None:
    """Where the re-simulated contact events first differ from the logged ones (physics
    logs); ``None`` if they agree or the log holds none."""
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


def _differs(logged: np.ndarray, sim: np.ndarray, bitwise: bool) -> np.ndarray:
    """Per row, whether ``logged`` and ``sim`` differ: by ``!=``, or for float actions (which
    the log holds bit-exact) bit for bit, so that ``-0.0`` is not ``0.0`` and NaN is NaN.
    (States and rewards are compared by value: their text may write ``-0.0`` as ``0``.)"""
    logged, sim = np.asarray(logged), np.asarray(sim)
    rows = len(logged)
    if bitwise and logged.dtype.kind == "f":
        a = logged.astype(np.float64).reshape(rows, -1).view(np.int64)
        b = np.asarray(sim, dtype=np.float64).reshape(rows, -1).view(np.int64)
        return (a != b).any(axis=1)
    return (logged != sim).reshape(rows, -1).any(axis=1)


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
        **(
            {"evader_return": float(traj.evader_reward.sum())}
            if traj.evader_reward is not None and "evader_return" in ep
            else {}
        ),
        "captured": captured,
        "truncated": traj.length >= scenario.max_steps and not terminated,
        "collision_terminated": terminated and not captured,
        "collisions": int(traj.collisions.sum()),
        "wall_contacts": int(traj.wall_contacts.sum()),
    }
    for key, want in expected.items():
        got = ep[key][i].item()
        returns = key in ("return", "evader_return")
        same = np.isclose(got, want, rtol=1e-12, atol=0) if returns else got == want
        if not same:
            return f"summary {key} is {got!r}, the trajectory gives {want!r}"
    return None


def verify(log: RunLog, trajs: Iterable[Trajectory] | None = None) -> int:
    """Verify ``trajs`` of ``log`` (default: every logged one) and their summaries; print a
    report; 0 if all match, 1 otherwise (or if there is nothing to verify). Progress over
    the episodes goes to stderr (:class:`~a2cm_phys.base.progress.Progress`)."""
    scenario = log.scenario
    total = len(trajs) if isinstance(trajs, Sized) else None
    if trajs is None:
        trajs, total = log.trajectories(), len(log.logged_episodes)
    core = make_core(scenario, 1)
    count = steps = 0
    bad: list[str] = []
    with Progress("verify", total, "episodes") as progress:
        for traj in trajs:
            problem = verify_trajectory(scenario, traj, core) or summary_mismatch(
                log, traj, scenario
            )
            count, steps = count + 1, steps + traj.length
            if problem:
                bad.append(f"episode {traj.episode} (env {traj.env}, seed {traj.seed}): {problem}")
                progress.note(f"{len(bad)} diverged")
            progress.update(1)
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
