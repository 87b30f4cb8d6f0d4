"""Foxglove's messages from Foxglove's SDK: the log's scenes are the SDK's protobuf
``foxglove.SceneUpdate`` under the SDK's own schema and decode back through ``mcap`` and
``mcap-protobuf-support``; no hand-written Foxglove schema is left; the float rows that
``orjson`` writes read back bit for bit; the layout in ``docs/foxglove`` is the one the
package builds with the SDK's layout types."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from foxglove.messages import SceneUpdate
from mcap.reader import make_reader
from mcap.records import Schema
from mcap_protobuf.decoder import DecoderFactory
from test_record import decode_scene, make_log, stamp_ns

from a2cm_phys.record import read_run, schemas
from a2cm_phys.record.jsontext import json_array, json_float_rows, json_rows
from a2cm_phys.record.layout import SCENE_TOPICS, foxglove_layout
from a2cm_phys.record.scene import TRAIL_STATES, episode_frames

ROOT = Path(__file__).resolve().parents[1]


def scenes_of(path: Path) -> dict[str, list[tuple[int, object]]]:
    """Every scene of a log, decoded (``mcap-protobuf-support``), by topic."""
    out: dict[str, list[tuple[int, object]]] = {}
    with open(path, "rb") as fh:
        for schema, channel, message in make_reader(fh).iter_messages(log_time_order=False):
            if channel.topic.startswith(schemas.SCENE_TOPIC_PREFIX):
                scene = decode_scene(schema, channel, message.data)
                out.setdefault(channel.topic, []).append((message.log_time, scene))
    return out


def entity(scene: object, name: str) -> object:
    return next(e for e in scene.entities if e.id == name)


@pytest.fixture(scope="module")
def grid_scenes(tmp_path_factory: pytest.TempPathFactory):
    path = tmp_path_factory.mktemp("fox") / "episodes.mcap"
    expected = make_log(path, "grid_collision", envs=4, steps=200, scene_every=1)
    return path, expected


def test_grid_scenes_decode_with_the_sdks_schema(grid_scenes) -> None:
    path, expected = grid_scenes
    log = read_run(path)
    sc = expected["scenario"]
    scenes = scenes_of(path)
    assert sum(len(v) for v in scenes.values()) == sum(
        e.length + 1 for e, _ in expected["finished"]
    )
    frames = 0
    for j, (e, data) in enumerate(expected["finished"]):
        mine = [
            s
            for t, s in scenes[f"{schemas.SCENE_TOPIC_PREFIX}{e.env}"]
            if f"episode {j} " in entity(s, "arena").texts[0].text
        ]
        assert len(mine) == e.length + 1
        for k, scene in enumerate(mine):
            pos = np.array(data["pos"][k], dtype=float) + 0.5  # cell centres
            for i in range(sc.pursuers):
                cube = entity(scene, f"pursuer_{i}").cubes[0]
                assert (cube.pose.position.x, cube.pose.position.y) == tuple(pos[i])
                assert cube.pose.orientation.w == 1.0  # never an all-zero quaternion
            sphere = entity(scene, "evader").spheres[0]
            assert (sphere.pose.position.x, sphere.pose.position.y) == tuple(pos[-1])
            trails = entity(scene, "trails").lines
            assert len(trails) == (sc.pursuers + 1 if k else 0)
            if k:
                assert len(trails[0].points) == min(k + 1, TRAIL_STATES)
            contacts = entity(scene, "contacts")
            touched = bool(k and (data["cap"][k - 1] or data["col"][k - 1]))
            assert bool(contacts.lines or contacts.spheres) == touched  # contacts flash
            if k and data["col"][k - 1]:
                assert contacts.spheres  # a marker between the colliding pursuers
            frames += 1
        assert ("captured" in entity(mine[-1], "arena").texts[0].text) == bool(e.captured)
        assert log.trajectory(j).length == e.length
    assert frames > 20
    walls = entity(scenes[f"{schemas.SCENE_TOPIC_PREFIX}0"][0][1], "arena")
    assert len(walls.cubes) == 5 and len(walls.lines[0].points) == 4 * (sc.size - 1)


def test_physics_scenes_draw_velocities_and_decode(tmp_path: Path) -> None:
    pytest.importorskip("pymunk")
    path = tmp_path / "p.mcap"
    expected = make_log(path, "phys", envs=2, steps=60, scene_every=2)
    scenes = scenes_of(path)
    assert sum(len(v) for v in scenes.values()) == sum(
        e.length + 1 for j, (e, _) in enumerate(expected["finished"]) if j % 2 == 0
    )
    arrows = 0
    for topic, frames in scenes.items():
        times = [t for t, _ in frames]
        assert times == sorted(times), topic
        for t, scene in frames:
            assert all(stamp_ns(e) == t for e in scene.entities)
            assert all(e.frame_id == "arena" for e in scene.entities)
            arrows += sum(len(entity(scene, f"pursuer_{i}").arrows) for i in range(3))
    assert arrows > 0


def test_an_old_logs_episodes_draw_as_sdk_scenes() -> None:
    """Episodes of a log written before the SDK (``pre_issue29``) draw as SDK scenes that
    decode with the SDK's schema alone (as a Foxglove client given only the schema would)."""
    log = read_run(ROOT / "tests" / "data" / "pre_issue29" / "phys")
    traj = log.trajectory(log.logged_episodes[0])
    sdk = SceneUpdate.get_schema()
    schema = Schema(id=1, name=sdk.name, encoding=sdk.encoding, data=bytes(sdk.data))
    decode = DecoderFactory().decoder_for("protobuf", schema)
    frames = list(episode_frames(log.scenario, traj))
    assert len(frames) == traj.length + 1
    for k, (time_ns, scene) in enumerate(frames):
        assert isinstance(scene, SceneUpdate)
        decoded = decode(scene.encode())
        sphere = entity(decoded, "evader").spheres[0]
        assert (sphere.pose.position.x, sphere.pose.position.y) == tuple(traj.positions[k, -1])
        assert stamp_ns(decoded.entities[0]) == time_ns


def test_no_hand_written_foxglove_schema_is_left() -> None:
    assert not hasattr(schemas, "SCENE_SCHEMA")
    source = "\n".join(p.read_text() for p in (ROOT / "a2cm_phys").rglob("*.py"))
    assert '"foxglove.CubePrimitive"' not in source and '"foxglove.Pose"' not in source
    assert not (ROOT / "tests" / "data" / "foxglove").exists()


def test_float_rows_read_back_bit_for_bit() -> None:
    rng = np.random.default_rng(7)
    bits = rng.integers(0, 2**64, size=60_000, dtype=np.uint64)
    values = bits.view(np.float64)
    values = values[np.isfinite(values)]
    special = np.array([0.0, -0.0, 5e-324, -5e-324, 2.2250738585072014e-308, 1e16, 0.1, 1 / 3])
    rows = np.concatenate([values, special, rng.normal(size=4000)])[: 2 * 30_000].reshape(-1, 2)
    for text in (json_float_rows(rows), json_rows(rows)):
        back = np.array(json.loads(text), dtype=np.float64)
        np.testing.assert_array_equal(back.view(np.uint64), rows.view(np.uint64))
    floats32 = rng.normal(size=(3000, 4)).astype(np.float32)  # exact float64 values
    back = np.array(json.loads(json_rows(floats32)))
    np.testing.assert_array_equal(back, floats32.astype(np.float64))
    assert json_float_rows(np.array([[np.nan, np.inf, -0.0]])) == b"[[null,null,-0.0]]"
    assert json_array(np.array([2**64 - 1], dtype=np.uint64)) == b'["18446744073709551615"]'


def test_the_layout_in_docs_is_the_packages() -> None:
    path = ROOT / "docs" / "foxglove" / "layout.json"
    assert path.read_text() == foxglove_layout()
    text = path.read_text()
    layout = json.loads(text)
    assert layout["version"] == 1
    for topic in (schemas.PLOT_EPISODES_TOPIC, schemas.PLOT_UPDATE_TOPIC, *SCENE_TOPICS):
        assert f'"{topic}' in text
    for field in ("capture_steps", "return", "collisions"):
        assert f"{schemas.PLOT_EPISODES_TOPIC}.{field}" in text
