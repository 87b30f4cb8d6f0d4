"""The log's learning curve for Foxglove's Plot panel: ``/plot/episodes`` points (means of
``PLOT_EVERY`` episodes) match the summaries they average, ``/plot/update`` the updates;
both in training time, with schemas Foxglove's JSON-schema reader accepts."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from test_record import make_log

from a2cm_phys.record import EpisodeRecorder, read_run
from a2cm_phys.record.schemas import (
    PLOT_EPISODES_TOPIC,
    PLOT_EVERY,
    PLOT_UPDATE_TOPIC,
    SCHEMAS,
    UPDATE_TOPIC,
)


def messages(path: Path, topic: str) -> list[tuple[int, dict]]:
    with open(path, "rb") as fh:
        return [
            (m.log_time, json.loads(m.data))
            for _, c, m in make_reader(fh).iter_messages(topics=[topic], log_time_order=False)
        ]


def foxglove_reads(schema: dict, name: str = "root") -> None:
    """Fail where Foxglove's JSON-schema reader would (``parseJsonSchema`` of its
    ``mcap-support``): every field one plain type, no type lists, no nulls."""
    assert schema["type"] == "object", name
    for field, sub in schema["properties"].items():
        kind = sub.get("type")
        assert isinstance(kind, str), f"{name}.{field}: type {kind!r}"
        if kind == "object":
            foxglove_reads(sub, f"{name}.{field}")
        elif kind == "array":
            assert sub["items"].get("type") in ("boolean", "string", "number", "integer")
        else:
            assert kind in ("boolean", "string", "number", "integer"), f"{name}.{field}"


def check_points(path: Path, every: int) -> list[dict]:
    """Check every curve point against the summaries it averages; the points."""
    log = read_run(path)
    ep = log.episodes
    points = messages(path, PLOT_EPISODES_TOPIC)
    assert sum(p["episodes"] for _, p in points) == log.n_episodes
    weight = log.scenario.rewards.collision if log.scenario.collisions.mode != "off" else 0.0
    start = 0
    for log_time, p in points:
        n = p["episodes"]
        rows = slice(start, start + n)
        assert ep["episode"][start + n - 1] == p["episode"]
        assert n == every or p["episode"] % every == every - 1 or start + n == log.n_episodes
        assert log_time == round(ep["t1"][start + n - 1] * 1e9)  # the end of its last episode
        assert p["length"] == pytest.approx(ep["length"][rows].mean())
        assert p["return"] == pytest.approx(ep["return"][rows].mean())
        assert p["return_collision"] == pytest.approx(weight * ep["collisions"][rows].mean())
        assert p["return_time"] + p["return_collision"] == pytest.approx(p["return"])
        for field in ("captured", "collision_terminated", "truncated", "collisions"):
            assert p[field] == pytest.approx(ep[field][rows].mean()), field
        caught = ep["captured"][rows]
        if caught.any():
            assert p["capture_steps"] == pytest.approx(ep["length"][rows][caught].mean())
        else:
            assert "capture_steps" not in p
        if "evader_return" in ep:
            assert p["evader_return"] == pytest.approx(ep["evader_return"][rows].mean())
        start += n
    times = [t for t, _ in points]
    assert times == sorted(times)
    return [p for _, p in points]


def test_points_match_the_summaries(tmp_path: Path) -> None:
    path = tmp_path / "episodes.mcap"
    make_log(path, "grid_collision", envs=8, steps=400, flush_seconds=0.0)  # many blocks
    points = check_points(path, PLOT_EVERY)
    assert len(points) >= 10 and sum(p["episodes"] == PLOT_EVERY for p in points) >= 9
    assert any(p["collision_terminated"] > 0 for p in points)


def test_points_of_every_episode_and_of_a_learned_evader(tmp_path: Path) -> None:
    path = tmp_path / "episodes.mcap"
    make_log(path, "grid_vs", envs=3, steps=150, plot_every=1)
    points = check_points(path, 1)
    assert all(p["episodes"] == 1 and "evader_return" in p for p in points)


def test_a_resumed_part_starts_with_a_short_point(tmp_path: Path) -> None:
    from a2cm_phys.config import load_scenario
    from a2cm_phys.envs.vector import VectorEnv

    sc = load_scenario("grid")
    env, rng = VectorEnv(sc, 4), np.random.default_rng(0)
    obs = env.reset(0)
    path = tmp_path / "r.mcap"
    with EpisodeRecorder(path, sc, {}, plot_every=7) as rec:
        rec.start(env, obs, step=500, episode=53)
        for _ in range(120):
            actions = rng.integers(0, sc.actions, size=(4, sc.pursuers))
            rec.record_step(actions, env.step(actions))
    points = check_points(path, 7)
    assert points[0]["episode"] == 55 and points[0]["episodes"] == 3  # 53, 54, 55
    assert all(p["episodes"] == 7 for p in points[1:-1])


def test_updates_are_plotted_as_plain_numbers(tmp_path: Path) -> None:
    path = tmp_path / "episodes.mcap"
    make_log(path, steps=80, metrics={2: {"exploit_worst_case": 3.5, "note": "text"}})
    full = messages(path, UPDATE_TOPIC)
    plain = messages(path, PLOT_UPDATE_TOPIC)
    assert [t for t, _ in plain] == [t for t, _ in full] and len(plain) == 10
    for (_, doc), (_, point) in zip(full, plain, strict=True):
        assert point == {
            k: v for k, v in doc.items() if isinstance(v, (int, float)) and not isinstance(v, bool)
        }
        assert "grad_norm" not in point and doc["grad_norm"] is None  # NaN: left out
    assert plain[2][1]["exploit_worst_case"] == 3.5 and "note" not in plain[2][1]


def test_no_points_when_asked_for_none(tmp_path: Path) -> None:
    path = tmp_path / "episodes.mcap"
    make_log(path, steps=60, plot_every=0)
    assert messages(path, PLOT_EPISODES_TOPIC) == messages(path, PLOT_UPDATE_TOPIC) == []
    assert read_run(path).metadata["plot_every"] == 0


@pytest.mark.parametrize("topic", [PLOT_EPISODES_TOPIC, PLOT_UPDATE_TOPIC])
def test_foxglove_reads_the_plot_schemas(topic: str) -> None:
    foxglove_reads(SCHEMAS[topic])


def test_the_check_rejects_what_foxglove_rejects() -> None:
    with pytest.raises(AssertionError):
        foxglove_reads(SCHEMAS[UPDATE_TOPIC])  # "type": ["number", "null"]
