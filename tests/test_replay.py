"""``python -m a2cm_phys.replay``: summary, episodes, --verify, --export-foxglove, errors."""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import Writer
from PIL import Image
from test_record import decode_scene, make_log

from a2cm_phys.analysis.episodes import EXPORT_TOPIC
from a2cm_phys.commands.replay import main
from a2cm_phys.record import read_run
from a2cm_phys.record.schemas import SUMMARY_TOPIC, TRAJECTORY_TOPIC


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("replay")
    make_log(path / "episodes.mcap", steps=200)
    return path


def rewrite(
    src: Path,
    dst: Path,
    edit: Callable[[dict], None],
    topic: str = TRAJECTORY_TOPIC,
    every: bool = False,
    metadata: Callable[[dict], None] | None = None,
) -> None:
    """Copy an MCAP file through the mcap library, editing the first message of ``topic``
    (``every``: all of them), and the run's metadata record with ``metadata``."""
    with open(src, "rb") as fh:
        reader = make_reader(fh)
        metadata_records = list(reader.iter_metadata())
    with open(src, "rb") as fh:
        messages = list(make_reader(fh).iter_messages(log_time_order=False))
    schemas: dict[int, int] = {}
    channels: dict[int, int] = {}
    edited = False
    with open(dst, "wb") as out:
        writer = Writer(out)
        writer.start()
        for m in metadata_records:
            values = dict(m.metadata)
            if metadata is not None:
                metadata(values)
            writer.add_metadata(m.name, values)
        for schema, channel, message in messages:
            if schema.id not in schemas:
                schemas[schema.id] = writer.register_schema(
                    schema.name, schema.encoding, schema.data
                )
            if channel.id not in channels:
                channels[channel.id] = writer.register_channel(
                    channel.topic, channel.message_encoding, schemas[schema.id]
                )
            data = message.data
            if channel.topic == topic and (every or not edited):
                doc = json.loads(data)
                edit(doc)
                data, edited = json.dumps(doc).encode(), True
            writer.add_message(channels[channel.id], message.log_time, data, message.publish_time)
        writer.finish()


def damage_a_chunk(path: Path) -> None:
    """Flip a byte in the middle of the middle chunk of a closed log."""
    with open(path, "rb") as fh:
        chunks = sorted(
            make_reader(fh).get_summary().chunk_indexes, key=lambda c: c.chunk_start_offset
        )
    chunk = chunks[len(chunks) // 2]
    data = bytearray(path.read_bytes())
    data[chunk.chunk_start_offset + chunk.chunk_length // 2] ^= 0xFF
    path.write_bytes(bytes(data))


def test_summary_table(run_dir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main([str(run_dir)]) == 0
    out = capsys.readouterr().out
    log = read_run(run_dir)
    assert "closed cleanly" in out and f"{log.n_episodes} episodes" in out
    assert "| 0–10% |" in out and "| 90–100% |" in out
    all_row = next(line for line in out.splitlines() if line.startswith("| all |"))
    assert f"| {log.n_episodes} | {int(log.episodes['length'].sum())} |" in all_row


def test_episode_as_text(run_dir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main([str(run_dir / "episodes.mcap"), "--episode", "2"]) == 0
    out = capsys.readouterr().out
    traj = read_run(run_dir).trajectory(2)
    assert out.startswith("episode 2:")
    assert out.count("\nt=") + out.startswith("t=") == traj.length + 1
    assert "E" in out and "actions 0:" in out


@pytest.mark.parametrize("kind", ["gif", "png"])
def test_episode_pictures(run_dir: Path, tmp_path: Path, kind: str) -> None:
    traj = read_run(run_dir).trajectory(1)
    out = tmp_path / f"ep.{kind}"
    assert (
        main(
            [
                str(run_dir),
                "--episode",
                "1",
                "--render",
                kind,
                "--out",
                str(out),
                "--max-frames",
                "6",
            ]
        )
        == 0
    )
    assert out.stat().st_size > 1000
    with Image.open(out) as im:
        if kind == "gif":
            assert im.n_frames == min(6, traj.length + 1)


def test_verify_passes_on_a_clean_log(run_dir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main([str(run_dir), "--verify"]) == 0
    out = capsys.readouterr().out
    assert f"verify: {read_run(run_dir).n_episodes} episodes" in out and "all match" in out


def test_verify_passes_on_a_physics_log(tmp_path: Path) -> None:
    pytest.importorskip("pymunk")
    make_log(tmp_path / "episodes.mcap", scenario="phys", envs=2, steps=50)
    assert main([str(tmp_path), "--verify"]) == 0


def _flip_pursuer_1_first_move(doc: dict) -> None:
    """Pursuer 1 starts in the bottom-right corner: of up/left (moves) and down/right
    (blocked by walls), swap one kind for the other in the block's first step."""
    row = doc["actions"][0]
    row[1] = 1 if row[1] in (0, 2) else 0


def _flip_evader_move(doc: dict) -> None:
    row = doc["actions"][0]
    row[-1] = (row[-1] + 1) % 4


@pytest.mark.parametrize(
    "edit, what", [(_flip_pursuer_1_first_move, "positions"), (_flip_evader_move, "evader action")]
)
def test_verify_catches_tampered_actions(
    run_dir: Path, tmp_path: Path, edit: Callable, what: str, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "tampered.mcap"
    rewrite(run_dir / "episodes.mcap", bad, edit)
    assert main([str(bad), "--verify"]) == 1
    out = capsys.readouterr().out
    assert "DIVERGED episode 0 " in out and f"{what} differ at step 1" in out
    assert "1 DIVERGED" in out


@pytest.mark.parametrize(
    ("key", "change"),
    [("return", lambda v: v - 1), ("length", lambda v: v + 1), ("captured", lambda v: not v)],
)
def test_verify_checks_the_episode_summaries(
    run_dir: Path, tmp_path: Path, key: str, change: Callable, capsys: pytest.CaptureFixture[str]
) -> None:
    def edit(doc: dict) -> None:
        doc[key][0] = change(doc[key][0])

    bad = tmp_path / "tampered.mcap"
    rewrite(run_dir / "episodes.mcap", bad, edit, topic=SUMMARY_TOPIC)
    assert main([str(bad), "--verify"]) == 1
    out = capsys.readouterr().out
    assert "DIVERGED episode 0 " in out and f"summary {key} is" in out and "1 DIVERGED" in out


def test_a_damaged_chunk_is_reported_as_damage_not_as_a_crash(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "episodes.mcap"
    make_log(path, steps=400, flush_seconds=0)
    whole = read_run(path).n_episodes
    damage_a_chunk(path)
    log = read_run(path)
    assert log.damaged and not log.clean and "1 damaged chunk(s) skipped" in log.error
    assert whole // 2 < log.n_episodes < whole  # the chunks after the damage are read too
    assert main([str(path)]) == 1
    out = capsys.readouterr().out
    assert "DAMAGED" in out and "NOT closed cleanly" not in out
    assert main([str(path), "--verify"]) == 1


@pytest.mark.parametrize(
    "args",
    [["--max-frames", "0"], ["--max-frames", "-3"], ["--fps", "0"], ["--fps", "-1"],
     ["--fps", "nan"], ["--parts", "0"], ["--episode", "-1"]],
)  # fmt: skip
def test_bad_frame_options_exit_2(
    run_dir: Path, args: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    assert main([str(run_dir), "--episode", "0", "--render", "gif", *args]) == 2
    err = capsys.readouterr().err
    assert args[0] in err and err.count("\n") == 1


def test_export_foxglove(run_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "scenes.mcap"
    assert main([str(run_dir), "--export-foxglove", str(out), "--episode", "0", "3"]) == 0
    log = read_run(run_dir)
    times = []
    with open(out, "rb") as fh:
        for schema, channel, message in make_reader(fh).iter_messages():
            assert channel.topic == EXPORT_TOPIC
            scene = decode_scene(schema, channel, message.data)  # the SDK's schema, protobuf
            assert {"arena", "evader", "trails"} <= {e.id for e in scene.entities}
            times.append(message.log_time)
    assert len(times) == sum(log.trajectory(e).length + 1 for e in (0, 3))
    assert np.all(np.diff(times) > 0)


def test_truncated_log_is_reported_not_fatal(
    run_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    data = (run_dir / "episodes.mcap").read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) - 200])
    assert main([str(cut)]) == 0
    out = capsys.readouterr().out
    assert "NOT closed cleanly" in out and "recovered" in out


def test_unlogged_episode_is_an_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    make_log(tmp_path / "episodes.mcap", steps=60, log_every=2)
    assert main([str(tmp_path), "--episode", "1"]) == 2
    assert "episode 1 has no logged trajectory (log_every=2" in capsys.readouterr().err


@pytest.mark.parametrize(
    "args, message",
    [
        (["missing.mcap"], "missing.mcap: no such file"),
        (["not_mcap.mcap"], "not an MCAP file"),
        (["run", "--episode", "100000"], "unknown episode 100000"),
    ],
)
def test_cli_errors_exit_2_with_one_clear_line(
    run_dir: Path, tmp_path: Path, args: list[str], message: str
) -> None:
    (tmp_path / "not_mcap.mcap").write_text("hello, not an mcap file\n")
    (tmp_path / "run").symlink_to(run_dir)
    proc = subprocess.run(
        [sys.executable, "-m", "a2cm_phys.replay", *args],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 2
    assert message in proc.stderr and "Traceback" not in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1
