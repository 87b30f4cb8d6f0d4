"""The MCAP run log: round trip against the env, schemas, Foxglove scenes (the Foxglove SDK's
protobuf messages, decoded with ``mcap-protobuf-support``), crash safety."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jsonschema
import numpy as np
import pytest
from foxglove.messages import SceneUpdate
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

from a2cm_phys.config import Scenario, load_scenario, to_dict
from a2cm_phys.envs.vector import VectorEnv
from a2cm_phys.record import EpisodeRecorder, LogError, RunLog, read_run
from a2cm_phys.record.schemas import (
    SCENE_TOPIC_PREFIX,
    SCHEMAS,
    SUMMARY_TOPIC,
    TRAJECTORY_TOPIC,
    UPDATE_TOPIC,
)


def validator(schema: dict) -> jsonschema.Validator:
    """A validator for ``schema`` (checked once against its metaschema)."""
    cls = jsonschema.validators.validator_for(schema)
    cls.check_schema(schema)
    return cls(schema)


def random_actions(
    sc: Scenario, rng: np.random.Generator, envs: int
) -> tuple[np.ndarray, np.ndarray | None]:
    """Random pursuer actions and (with a learned evader) evader actions for one vector step:
    moves, or float32 commands partly outside the unit disc (the env clips them), with an
    exact ``-0.0`` now and then, as a policy's output would be."""
    if sc.continuous:
        actions = rng.uniform(-1.4, 1.4, size=(envs, sc.pursuers, 2)).astype(np.float32)
        actions[rng.random(actions.shape) < 0.05] = np.float32(-0.0)
    else:
        actions = rng.integers(0, sc.actions, size=(envs, sc.pursuers))
    if sc.evader != "learned":
        return actions, None
    if sc.continuous:
        return actions, rng.uniform(-1.4, 1.4, size=(envs, 2)).astype(np.float32)
    return actions, rng.integers(0, sc.actions, size=envs)


def make_log(
    path: Path,
    scenario: str = "grid",
    envs: int = 4,
    steps: int = 300,
    seed: int = 0,
    updates_every: int = 8,
    algo: str = "a2cm",
    label: str | None = "test run",
    overrides: dict | None = None,
    metrics: dict[int, dict] | None = None,
    policy: Callable[..., tuple[np.ndarray, np.ndarray | None]] | None = None,
    **recorder: object,
) -> dict:
    """Drive a VectorEnv with random actions (or ``policy(scenario, rng, envs)``'s) while
    recording; return what the env produced (finished episodes in order, each with its
    step-by-step data) to compare with. ``metrics`` adds metrics to the updates whose
    number it holds."""
    policy = policy or random_actions
    sc = load_scenario(scenario, overrides)
    env = VectorEnv(sc, envs)
    rng = np.random.default_rng(seed)
    obs = env.reset(seed)
    vel0 = env.core.velocities()

    def fresh(i: int) -> dict:
        v = env.core.velocities()
        return {
            "pos": [env.core.positions()[i]],
            "act": [],
            "rew": [],
            "cap": [],
            "col": [],
            "wall": [],
            "vel": None if v is None else [v[i]],
            "events": [],
            "erew": [],
        }

    current = [fresh(i) for i in range(envs)]
    finished: list[tuple] = []
    updates: list[dict] = []
    meta = {"train": {"algo": algo, "seed": seed}, "label": label}
    with EpisodeRecorder(path, sc, meta, **recorder) as rec:
        rec.start(env, obs)
        for k in range(steps):
            actions, evader_actions = policy(sc, rng, envs)
            step = env.step(actions, evader_actions)
            rec.record_step(actions, step)
            out = step.outcome
            for i in range(envs):
                c = current[i]
                c["pos"].append(step.positions[i].copy())
                c["act"].append(np.concatenate([actions[i], out.evader_action[i][None]]))
                if step.evader_reward is not None:
                    c["erew"].append(step.evader_reward[i])
                c["rew"].append(out.reward[i])
                c["cap"].append(out.captured[i])
                c["col"].append(out.collisions[i])
                c["wall"].append(out.wall_contacts[i])
                if vel0 is not None:
                    c["vel"].append(step.velocities[i].copy())
                if out.events is not None:
                    c["events"] += [tuple(e) for e in out.events[i]]
            for e in step.episodes:
                finished.append((e, current[e.env]))
                current[e.env] = fresh(e.env)
            if updates_every and k % updates_every == updates_every - 1:
                logged = {
                    "policy_loss": float(k),
                    "value_loss": np.float32(0.5),
                    "entropy": 1.25,
                    "grad_norm": float("nan"),
                    **(metrics or {}).get(k // updates_every, {}),
                }
                rec.record_update(k // updates_every, logged)
                updates.append(logged)
    return {"scenario": sc, "finished": finished, "updates": updates, "envs": envs}


@pytest.fixture(scope="module")
def grid_log(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict]:
    path = tmp_path_factory.mktemp("run") / "episodes.mcap"
    return path, make_log(path, scene_every=9)


def test_round_trip_every_channel(grid_log: tuple[Path, dict]) -> None:
    path, expected = grid_log
    log = read_run(path)
    finished = expected["finished"]
    assert log.clean and log.error is None
    assert log.n_episodes == len(finished) > 20
    ep = log.episodes
    assert ep["episode"].tolist() == list(range(len(finished)))
    for j, (e, data) in enumerate(finished):
        assert ep["env"][j] == e.env and int(ep["seed"][j]) == e.seed
        assert ep["length"][j] == e.length and ep["return"][j] == e.ret
        assert ep["captured"][j] == e.captured and ep["truncated"][j] == e.truncated
        assert ep["collision_terminated"][j] == e.collision_terminated
        assert ep["collisions"][j] == e.collisions and ep["wall_contacts"][j] == e.wall_contacts
        assert ep["t1"][j] - ep["t0"][j] == e.length
        traj = log.trajectory(j)
        assert (traj.episode, traj.env, traj.seed, traj.length) == (j, e.env, e.seed, e.length)
        np.testing.assert_array_equal(traj.positions, np.array(data["pos"]))
        np.testing.assert_array_equal(traj.actions, np.array(data["act"]))
        np.testing.assert_array_equal(traj.reward, data["rew"])
        np.testing.assert_array_equal(traj.captured, data["cap"])
        np.testing.assert_array_equal(traj.collisions, data["col"])
        np.testing.assert_array_equal(traj.wall_contacts, data["wall"])
        assert traj.velocities is None and traj.events is None
    assert [t.episode for t in log.trajectories()] == list(range(len(finished)))
    assert len(log.updates) == len(expected["updates"])
    for k, (got, want) in enumerate(zip(log.updates, expected["updates"], strict=True)):
        assert got["update"] == k and got["policy_loss"] == want["policy_loss"]
        assert got["value_loss"] == 0.5 and got["grad_norm"] is None
        assert got["env_steps"] == (k + 1) * 8 * expected["envs"] and got["steps_per_s"] > 0


def test_episode_ids_run_on_across_writes(tmp_path: Path) -> None:
    """More steps than the step buffers hold: the queue is written several steps at a time
    (when the buffers fill, and at the end), and every episode keeps its own id."""
    expected = make_log(tmp_path / "m.mcap", envs=3, steps=2600, updates_every=0)
    finished = expected["finished"]
    log = read_run(tmp_path / "m.mcap")
    assert log.episodes["episode"].tolist() == list(range(len(finished)))
    assert log.episodes["length"].tolist() == [e.length for e, _ in finished]
    assert log.episodes["env"].tolist() == [e.env for e, _ in finished]
    assert [t.length for t in log.trajectories()] == [e.length for e, _ in finished]


def test_metadata_holds_scenario_and_provenance(grid_log: tuple[Path, dict]) -> None:
    path, expected = grid_log
    log = read_run(path)
    assert log.scenario == expected["scenario"]
    meta = log.metadata
    assert meta["train"] == {"algo": "a2cm", "seed": 0} and meta["seed"] == 0
    assert meta["scenario"] == to_dict(expected["scenario"])
    assert meta["version"] and meta["command"] and meta["algo"] == "a2cm"
    assert meta["format"].startswith("a2cm_phys")
    assert log.label == "test run"


def test_every_message_matches_its_schema(grid_log: tuple[Path, dict]) -> None:
    path, _ = grid_log
    seen = check_messages(path)
    assert {TRAJECTORY_TOPIC, SUMMARY_TOPIC, UPDATE_TOPIC} <= set(seen)
    assert any(t.startswith(SCENE_TOPIC_PREFIX) for t in seen)


def decode_scene(schema: Any, channel: Any, data: bytes) -> Any:
    """A scene message decoded by ``mcap-protobuf-support`` from the schema it was stored
    with, after checking the channel is as Foxglove expects: the SDK's own
    ``foxglove.SceneUpdate`` schema (its protobuf ``FileDescriptorSet``), protobuf messages."""
    assert schema.name == "foxglove.SceneUpdate" and schema.encoding == "protobuf"
    assert channel.message_encoding == "protobuf"
    assert schema.data == SceneUpdate.get_schema().data
    decoder = DecoderFactory().decoder_for(channel.message_encoding, schema)
    assert decoder is not None
    return decoder(data)


def stamp_ns(entity: Any) -> int:
    """A decoded scene entity's timestamp in nanoseconds."""
    return entity.timestamp.seconds * 1_000_000_000 + entity.timestamp.nanos


def check_messages(
    path: Path, expected: dict[str, Any] | None = None
) -> dict[str, list[tuple[int, Any]]]:
    """Validate every JSON message of a log against its stored schema (the package's own:
    ``expected``, by default the fixed topics' :data:`SCHEMAS`),
    decode every scene through ``mcap`` and ``mcap-protobuf-support`` with the schema it was
    stored with, check each channel's times never go back; return each topic's
    ``(log_time, message)`` list (a dict, or a decoded ``foxglove.SceneUpdate``)."""
    stored: dict[int, jsonschema.Validator] = {}
    seen: dict[str, list[tuple[int, Any]]] = {}
    with open(path, "rb") as fh:
        for schema, channel, message in make_reader(fh).iter_messages(log_time_order=False):
            if channel.topic.startswith(SCENE_TOPIC_PREFIX):
                decoded = decode_scene(schema, channel, message.data)
                ids = [e.id for e in decoded.entities]
                assert {"arena", "pursuer_0", "evader", "trails", "contacts"} <= set(ids)
                assert all(stamp_ns(e) == message.log_time for e in decoded.entities)
                seen.setdefault(channel.topic, []).append((message.log_time, decoded))
                continue
            doc = json.loads(message.data)
            assert channel.message_encoding == "json" and schema.encoding == "jsonschema"
            if schema.id not in stored:
                stored[schema.id] = validator(json.loads(schema.data))
                assert json.loads(schema.data) == (expected or SCHEMAS)[channel.topic]
            stored[schema.id].validate(doc)
            seen.setdefault(channel.topic, []).append((message.log_time, doc))
    for topic, messages in seen.items():  # each channel's log times never go back
        times = [t for t, _ in messages]
        assert times == sorted(times), topic
    return seen


def test_scene_frames_cover_every_state_of_drawn_episodes(grid_log: tuple[Path, dict]) -> None:
    path, expected = grid_log
    drawn = [e for j, (e, _) in enumerate(expected["finished"]) if j % 9 == 0]
    log = read_run(path)
    frames = sum(n for t, n in log.topic_counts.items() if t.startswith(SCENE_TOPIC_PREFIX))
    assert frames == sum(e.length + 1 for e in drawn)


def test_log_every_keeps_every_kth_trajectory_and_all_summaries(tmp_path: Path) -> None:
    expected = make_log(tmp_path / "e.mcap", steps=150, log_every=3)
    log = read_run(tmp_path / "e.mcap")
    n = len(expected["finished"])
    assert log.n_episodes == n
    assert log.logged_episodes == list(range(0, n, 3))
    assert log.episodes["logged"].tolist() == [j % 3 == 0 for j in range(n)]
    with pytest.raises(KeyError):
        log.trajectory(1)


def test_physics_round_trip_with_velocities_and_events(tmp_path: Path) -> None:
    pytest.importorskip("pymunk")
    expected = make_log(tmp_path / "p.mcap", scenario="phys", envs=2, steps=60, scene_every=5)
    log = read_run(tmp_path / "p.mcap")
    assert log.n_episodes == len(expected["finished"]) > 0
    for j, (_, data) in enumerate(expected["finished"]):
        traj = log.trajectory(j)
        np.testing.assert_array_equal(traj.positions, np.array(data["pos"]))  # bit-exact
        np.testing.assert_array_equal(traj.velocities, np.array(data["vel"]))
        assert traj.events == data["events"]


def test_a_resumed_run_logs_running_episodes_without_trajectories(tmp_path: Path) -> None:
    sc = load_scenario("grid")
    env = VectorEnv(sc, 4)
    rng = np.random.default_rng(3)
    env.reset(3)
    for _ in range(3):  # the games are mid-episode when recording starts, as after a resume
        env.step(rng.integers(0, 4, size=(4, 3)))
    running = {i for i in range(4) if env.core.t[i] > 0}
    finished = []
    with EpisodeRecorder(tmp_path / "r.mcap", sc, {}) as rec:
        rec.start(env, step=1000, episode=50)
        for _ in range(100):
            actions = rng.integers(0, 4, size=(4, 3))
            step = env.step(actions)
            rec.record_step(actions, step)
            finished += step.episodes
    log = read_run(tmp_path / "r.mcap")
    assert log.episodes["episode"].tolist() == list(range(50, 50 + len(finished)))
    assert log.episodes["length"].tolist() == [e.length for e in finished]
    first_of = {e.env: j for j, e in reversed(list(enumerate(finished)))}
    partial = {50 + first_of[i] for i in running if i in first_of}
    assert partial and set(log.logged_episodes) == set(log.episodes["episode"].tolist()) - partial
    assert log.episodes["t1"].min() > 1000
    assert main_verify(log) == 0


def main_verify(log: RunLog) -> int:
    """``replay --verify`` on ``log``, quietly."""
    import contextlib
    import io

    from a2cm_phys.record.verify import verify

    with contextlib.redirect_stdout(io.StringIO()):
        return verify(log, None)


# --------------------------------------------------------------------------- crash safety


def test_truncated_file_yields_complete_episodes_up_to_the_last_chunk(tmp_path: Path) -> None:
    path = tmp_path / "full.mcap"
    make_log(path, steps=400, flush_seconds=0.0, updates_every=0)  # a chunk per step
    data = path.read_bytes()
    full = read_run(path)
    with open(path, "rb") as fh:
        chunks = sorted(
            make_reader(fh).get_summary().chunk_indexes, key=lambda c: c.chunk_start_offset
        )
    assert len(chunks) > 50
    chunk_ends = [c.chunk_start_offset + c.chunk_length for c in chunks]
    cut = tmp_path / "cut.mcap"
    rng = np.random.default_rng(1)
    offsets = sorted(
        {
            *rng.integers(chunks[0].chunk_start_offset, len(data), 40).tolist(),
            *chunk_ends[:3],
            chunk_ends[-1],
            len(data) - 1,
        }
    )
    cut.write_bytes(data[: chunks[0].chunk_start_offset])  # metadata, no chunk yet
    assert read_run(cut).n_episodes == 0 and not read_run(cut).clean
    cut.write_bytes(data[:20])  # inside the header: nothing to recover
    with pytest.raises(LogError, match="cut before its metadata"):
        read_run(cut)
    recovered_before = 0
    for offset in offsets:
        cut.write_bytes(data[:offset])
        log = read_run(cut)
        assert not log.clean
        n = log.n_episodes
        # exactly the episodes of the chunks that ended before the cut, in order, whole
        complete = sum(1 for end in chunk_ends if end <= offset)
        assert n >= recovered_before
        recovered_before = n
        assert log.episodes["episode"].tolist() == list(range(n))
        np.testing.assert_array_equal(log.episodes["length"], full.episodes["length"][:n])
        assert set(log.logged_episodes) == set(range(n))
        if complete:
            expected = _episodes_in_first_chunks(path, complete)
            assert n == expected, (offset, complete)
        for j in log.logged_episodes[-3:]:
            np.testing.assert_array_equal(log.trajectory(j).positions, full.trajectory(j).positions)


def _episodes_in_first_chunks(path: Path, chunks: int) -> int:
    """Episodes summarised in the first ``chunks`` chunks (via the mcap library's index)."""
    with open(path, "rb") as fh:
        reader = make_reader(fh)
        index = sorted(reader.get_summary().chunk_indexes, key=lambda c: c.chunk_start_offset)
        last_time = index[chunks - 1].message_end_time
        n = 0
        for _, _, msg in reader.iter_messages(topics=[SUMMARY_TOPIC], ending_at=last_time):
            n += len(json.loads(msg.data)["episode"])
        return n


_CHILD = textwrap.dedent("""
    import sys, numpy as np
    from a2cm_phys.config import load_scenario
    from a2cm_phys.envs.vector import VectorEnv
    from a2cm_phys.record import EpisodeRecorder
    sc = load_scenario("grid"); env = VectorEnv(sc, 8); rng = np.random.default_rng(0)
    rec = EpisodeRecorder(sys.argv[1], sc, {}, flush_seconds=0.1)
    rec.start(env, env.reset(0))
    print("started", flush=True)
    while True:
        a = rng.integers(0, 4, size=(8, 3)); rec.record_step(a, env.step(a))
""")


def test_sigkill_leaves_a_readable_log(tmp_path: Path) -> None:
    path = tmp_path / "killed.mcap"
    child = subprocess.Popen(
        [sys.executable, "-c", _CHILD, str(path)],
        stdout=subprocess.PIPE,
        env={**os.environ, "PYTHONHASHSEED": "0"},
    )
    try:
        assert child.stdout.readline().strip() == b"started"
        time.sleep(1.0)
    finally:
        child.send_signal(signal.SIGKILL)
        child.wait()
    log = read_run(path)
    assert not log.clean
    assert log.n_episodes > 0
    assert log.episodes["episode"].tolist() == list(range(log.n_episodes))
    assert len(log.logged_episodes) == log.n_episodes
