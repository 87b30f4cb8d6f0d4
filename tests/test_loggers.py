"""``train --logger tensorboard|wandb|csv``: each tool holds the numbers the run's MCAP log
holds (every update's ``/train/update`` metrics, the ``/plot/episodes`` curve points) at
the right environment steps, read back with the tool's own reader; a resume continues
them without a duplicate, also after a session killed past its checkpoint; a logger
changes nothing of the run; a missing library is one line and exit 2; a logger that
cannot write warns and the run goes on."""

from __future__ import annotations

import csv
import importlib.util
import json
import math
import os
import struct
import subprocess
import sys
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import zstandard
from mcap.exceptions import McapError
from mcap.records import Channel, Message
from mcap.stream_reader import StreamReader
from test_train import _assert_same_run

from a2cm_phys.commands.train import main
from a2cm_phys.record import read_run
from a2cm_phys.record.parts import part_files
from a2cm_phys.record.reader import read_file
from a2cm_phys.record.schemas import PLOT_EPISODES_TOPIC as PLOT
from a2cm_phys.record.schemas import step_seconds
from a2cm_phys.training import checkpoint

GRID = ("--scenario", "grid_collision", "--num-envs", "4", "--batch-size", "32", "--seed", "2")
WALL_CLOCK = "steps_per_s"
"""The one number each view measures for itself (the wall-clock rate between updates)."""


def train(run: Path, updates: int, *extra: str) -> int:
    """A short new run into ``run``; its exit status."""
    argv = [*GRID, "--updates", str(updates), "--run-dir", str(run), "--no-progress"]
    return main([*argv, *extra])


def resume(run: Path, updates: int, *extra: str) -> int:
    return main(["--resume", str(run), "--updates", str(updates), "--no-progress", *extra])


# ---------------------------------------------------------------------- the MCAP log's numbers


def log_updates(run: Path) -> list[dict[str, Any]]:
    """The ``/train/update`` documents of the run, each update once (the log's reader)."""
    updates = read_run(run).updates
    assert [u["update"] for u in updates] == list(range(1, len(updates) + 1))
    return updates


def _plot_points(path: Path) -> list[tuple[int, dict[str, Any]]]:
    """``(log_time, point)`` of a log part's ``/plot/episodes`` messages, up to where a
    killed session's part ends."""
    topics, out = {}, []
    with open(path, "rb") as fh:
        try:
            for record in StreamReader(fh, validate_crcs=True).records:
                if isinstance(record, Channel):
                    topics[record.id] = record.topic
                elif isinstance(record, Message) and topics[record.channel_id] == PLOT:
                    out.append((record.log_time, json.loads(record.data)))
        except (McapError, EOFError, ValueError, struct.error, zstandard.ZstdError):
            pass  # a part cut short: its complete chunks are what it holds
    return out


def log_points(run: Path) -> list[tuple[int, dict[str, Any]]]:
    """``(env_steps, point)`` of the run's learning curve as its log has it: each part's
    points before the first episode of every later part (as the log's reader keeps its
    episodes), timed at the end of their last episode, in environment steps."""
    log = read_run(run)
    step_ns = round(step_seconds(log.scenario) * 1e9)
    games = json.loads((run / "config.json").read_text())["train"]["num_envs"]
    parts = part_files(run)
    starts = [read_file(p).metadata["part"]["episode"] for p in parts]
    out = []
    for i, path in enumerate(parts):
        end = min(starts[i + 1 :], default=None)
        for log_time, point in _plot_points(path):
            if end is None or point["episode"] < end:
                assert log_time % step_ns == 0
                out.append((log_time // step_ns * games, point))
    assert out and [p["episode"] for _, p in out] == sorted({p["episode"] for _, p in out})
    return out


def numbers(doc: dict[str, Any]) -> dict[str, float]:
    """The plain finite numbers of a document (what a scalar logger can show)."""
    return {
        k: v
        for k, v in doc.items()
        if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
    }


def assert_same_update(got: dict[str, Any], want: dict[str, Any]) -> None:
    """An update's numbers as a logger has them, against the log's document."""
    assert got.keys() == want.keys(), (got.keys() ^ want.keys(), want["update"])
    for key, value in want.items():
        if key == WALL_CLOCK:
            assert got[key] > 0
        else:
            assert got[key] == value, (want["update"], key)


# ---------------------------------------------------------------------- the tools' readers


def tensorboard_scalars(run: Path) -> dict[str, list[tuple[int, float]]]:
    """Every scalar of ``RUN_DIR/tensorboard`` as TensorBoard reads it: ``tag: [(step, value)]``."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    acc = EventAccumulator(str(run / "tensorboard"), size_guidance={"scalars": 0})
    acc.Reload()
    return {t: [(e.step, e.value) for e in acc.Scalars(t)] for t in acc.Tags()["scalars"]}


def csv_rows(path: Path) -> list[dict[str, float | None]]:
    """A CSV file's rows, numbers parsed (an empty cell: ``None``)."""
    with open(path, newline="", encoding="utf-8") as fh:
        return [{k: float(v) if v else None for k, v in r.items()} for r in csv.DictReader(fh)]


def wandb_records(path: Path) -> list[Any]:
    """The records of an offline W&B run's ``.wandb`` file (a LevelDB-style log of W&B's
    protobuf ``Record``s: 32 KiB blocks of chunks, each ``crc32c, length, type``)."""
    from wandb.proto import wandb_internal_pb2

    data, block = path.read_bytes(), 32768
    assert data[:4] == b":W&B"
    pos, records, pieces = 7, [], b""
    while pos + 7 <= len(data):
        if block - pos % block < 7:  # a block's tail too short for a header is padding
            pos += block - pos % block
            continue
        _, length, kind = struct.unpack("<IHB", data[pos : pos + 7])
        if kind == 0:
            break
        pieces += data[pos + 7 : pos + 7 + length]
        pos += 7 + length
        if kind in (1, 4):  # FULL, LAST
            record = wandb_internal_pb2.Record()
            record.ParseFromString(pieces)
            records.append(record)
            pieces = b""
    return records


def isolate_wandb(monkeypatch: pytest.MonkeyPatch, home: Path) -> None:
    """W&B as a user without an account has it: no mode set, no settings, no network."""
    monkeypatch.delenv("WANDB_MODE", raising=False)
    monkeypatch.delenv("WANDB_API_KEY", raising=False)
    monkeypatch.setenv("WANDB_SILENT", "true")
    monkeypatch.setenv("WANDB_DISABLE_CODE", "true")
    monkeypatch.setenv("WANDB_BASE_URL", "http://127.0.0.1:9")  # nothing listens: no network
    for name in ("WANDB_CONFIG_DIR", "WANDB_CACHE_DIR", "WANDB_DATA_DIR"):
        monkeypatch.setenv(name, str(home))


def _key(item: Any) -> str:
    """A W&B history item's key (a key with a ``/`` is stored as a ``nested_key``)."""
    return item.key or "/".join(item.nested_key)


@pytest.fixture
def offline_wandb(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> Any:
    """``wandb`` (the test is skipped without it), isolated by :func:`isolate_wandb`."""
    wandb = pytest.importorskip("wandb")
    isolate_wandb(monkeypatch, tmp_path / "wandb-home")
    yield wandb
    wandb.teardown()  # stop the W&B service process these runs started


# ---------------------------------------------------------------------- each tool


def test_tensorboard_holds_every_update_and_curve_point_of_the_log(tmp_path: Path) -> None:
    pytest.importorskip("tensorboard")
    run = tmp_path / "run"
    assert train(run, 20, "--logger", "tensorboard") == 0
    assert_tensorboard_matches_the_log(run)


def assert_tensorboard_matches_the_log(run: Path) -> None:
    """TensorBoard's scalars are the log's numbers (float32), at the log's steps, once."""
    got = tensorboard_scalars(run)
    want: dict[str, list[tuple[int, float]]] = defaultdict(list)
    for doc in log_updates(run):
        for key, value in numbers(doc).items():
            want[f"update/{key}"].append((doc["env_steps"], float(np.float32(value))))
    for env_steps, point in log_points(run):
        for key, value in point.items():
            want[f"episodes/{key}"].append((env_steps, float(np.float32(value))))
    assert got.keys() == want.keys()
    for tag, series in want.items():
        if tag == f"update/{WALL_CLOCK}":
            assert [s for s, _ in got[tag]] == [s for s, _ in series]
            assert all(v > 0 for _, v in got[tag])
        else:
            assert got[tag] == series, tag


def test_csv_files_hold_every_update_and_curve_point_of_the_log(tmp_path: Path) -> None:
    run = tmp_path / "run"
    assert train(run, 20, "--logger", "csv") == 0
    assert_csv_matches_the_log(run)
    header = (run / "metrics" / "updates.csv").read_text().splitlines()[0]
    assert header.startswith("update,env_steps,episodes,")


def assert_csv_matches_the_log(run: Path) -> None:
    """``updates.csv`` has a row per update of the log, ``episodes.csv`` a row per curve
    point, with its env_steps; the same numbers, exactly."""
    rows, updates = csv_rows(run / "metrics" / "updates.csv"), log_updates(run)
    assert len(rows) == len(updates)
    for row, doc in zip(rows, updates, strict=True):
        got = {k: v for k, v in row.items() if v is not None}
        assert_same_update(got, {k: v for k, v in doc.items() if v is not None})
    rows, points = csv_rows(run / "metrics" / "episodes.csv"), log_points(run)
    assert [{k: v for k, v in r.items() if v is not None} for r in rows] == [
        {"env_steps": t, **p} for t, p in points
    ]


def test_a_resumed_csv_log_appends_without_duplicates(tmp_path: Path) -> None:
    run = tmp_path / "run"
    assert train(run, 20, "--logger", "csv") == 0
    path = run / "metrics" / "updates.csv"
    before, inode = path.read_text(), path.stat().st_ino
    assert resume(run, 30, "--logger", "csv") == 0
    assert path.stat().st_ino == inode and path.read_text().startswith(before)  # appended
    assert [r["update"] for r in csv_rows(path)] == list(range(1, 31))
    assert_csv_matches_the_log(run)


_KILLED = """
import os, sys
from a2cm_phys.commands.train import main
from a2cm_phys.training.trainer import Trainer

original = Trainer._one_update

def killed(self, on_step):
    if self.update == {kill_at}:
        os._exit(9)  # as SIGKILL: no cleanup, no close
    original(self, on_step)

Trainer._one_update = killed
main({argv!r})
"""


def test_what_a_killed_session_wrote_past_the_checkpoint_is_dropped(tmp_path: Path) -> None:
    """Killed after update 16 with the checkpoint at 10: the CSV rows and TensorBoard's events
    of updates 11–16 are not shown twice once the run is resumed; nor is a row it tore."""
    loggers = ["csv", *(["tensorboard"] if importlib.util.find_spec("tensorboard") else [])]
    run = tmp_path / "run"
    flags = [f for name in loggers for f in ("--logger", name)]
    argv = [*GRID, "--updates", "30", "--run-dir", str(run), "--no-progress",
            "--checkpoint-every", "10", *flags]  # fmt: skip
    code = _KILLED.format(kill_at=16, argv=argv)
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    done = subprocess.run([sys.executable, "-c", code], env=env, timeout=300, capture_output=True)
    assert done.returncode == 9, done.stderr.decode()[-2000:]
    assert checkpoint.load(run)["update"] == 10
    updates_csv = run / "metrics" / "updates.csv"
    written = [r["update"] for r in csv_rows(updates_csv)]
    assert written == list(range(1, 17))  # past the checkpoint
    with open(updates_csv, "a", encoding="utf-8") as fh:
        fh.write("17,544,4")  # a row torn by the kill
    episodes_csv = run / "metrics" / "episodes.csv"
    assert max(r["env_steps"] for r in csv_rows(episodes_csv)) > 10 * 32
    assert main(["--resume", str(run), "--no-progress", *flags]) == 0
    assert [r["update"] for r in csv_rows(updates_csv)] == list(range(1, 31))
    assert_csv_matches_the_log(run)
    if "tensorboard" in loggers:
        assert len(list((run / "tensorboard").iterdir())) == 2  # one events file a session
        assert_tensorboard_matches_the_log(run)


def test_wandb_writes_an_offline_run_holding_the_logs_numbers(
    tmp_path: Path, offline_wandb: Any
) -> None:
    run = tmp_path / "run"
    assert train(run, 19, "--logger", "wandb") == 0
    points, updates = log_points(run), log_updates(run)
    assert points[-1][0] < updates[-1]["env_steps"]  # the last point comes after its step
    run_id = (run / "wandb" / "run-id").read_text().strip()
    files = sorted((run / "wandb").glob(f"offline-run-*-{run_id}/run-{run_id}.wandb"))
    assert len(files) == 1
    records = wandb_records(files[0])
    header = next(r.run for r in records if r.WhichOneof("record_type") == "run")
    assert (header.run_id, header.project, header.display_name) == (run_id, "a2cm_phys", "run")
    config = {u.key: json.loads(u.value_json) for u in header.config.update}
    train_config = json.loads((run / "config.json").read_text())["train"]
    assert {k: v for k, v in config.items() if k in train_config} == train_config
    rows: dict[int, dict[str, Any]] = {}
    for r in records:
        if r.WhichOneof("record_type") == "history":
            row = rows.setdefault(r.history.step.num, {})
            row.update({_key(i): json.loads(i.value_json) for i in r.history.item})
    for doc in updates:
        row = rows[doc["env_steps"]]
        got = {k[len("update/") :]: v for k, v in row.items() if k.startswith("update/")}
        assert_same_update(got, numbers(doc))
    last_at: dict[int, dict[str, Any]] = {}  # a row keeps the last point of its step
    for env_steps, point in points:
        last_at[env_steps] = point
    for env_steps, point in last_at.items():
        assert {k: rows[env_steps][f"episodes/{k}"] for k in point} == point
    assert resume(run, 25, "--logger", "wandb") == 0  # the same W&B run continues
    files = sorted((run / "wandb").glob(f"offline-run-*-{run_id}/run-{run_id}.wandb"))
    assert len(files) == 2
    steps = [
        r.history.step.num
        for r in wandb_records(files[1])
        if r.WhichOneof("record_type") == "history"
    ]
    assert min(steps) > 19 * 32 and 25 * 32 in steps


# ---------------------------------------------------------------------- the run itself


def test_a_logger_changes_nothing_of_the_run(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    loggers = ["csv", *[n for n in ("tensorboard", "wandb") if importlib.util.find_spec(n)]]
    isolate_wandb(monkeypatch, tmp_path / "wandb-home")
    plain, logged = tmp_path / "plain", tmp_path / "logged"
    assert train(plain, 20) == 0
    try:
        assert train(logged, 20, *[f for n in loggers for f in ("--logger", n)]) == 0
    finally:
        if "wandb" in loggers:
            sys.modules["wandb"].teardown()
    _assert_same_run(plain, logged)
    config = [json.loads((r / "config.json").read_text())["train"] for r in (plain, logged)]
    assert config[0] == config[1]
    a, b = checkpoint.load(plain), checkpoint.load(logged)
    assert a["train"] == b["train"] and a["update"] == b["update"]
    assert {k: v for k, v in a["log"].items() if k != "open"} == {
        k: v for k, v in b["log"].items() if k != "open"
    }
    la, lb = read_run(plain), read_run(logged)
    assert la.episodes.keys() == lb.episodes.keys()
    for key, column in la.episodes.items():
        np.testing.assert_array_equal(column, lb.episodes[key], err_msg=key)
    assert la.topic_counts == lb.topic_counts
    assert [{k: v for k, v in u.items() if k != WALL_CLOCK} for u in la.updates] == [
        {k: v for k, v in u.items() if k != WALL_CLOCK} for u in lb.updates
    ]
    assert log_points(plain) == log_points(logged)


def test_the_option_offers_every_logger() -> None:
    from a2cm_phys.commands.train import build_parser
    from a2cm_phys.training.loggers import LOGGERS, make_logger

    option = next(a for a in build_parser()._actions if "--logger" in a.option_strings)
    assert tuple(option.choices) == LOGGERS
    assert make_logger("csv", "run", {}).name == "csv"


@pytest.mark.parametrize(
    ("name", "modules"),
    [("tensorboard", ["tensorboard", "torch.utils.tensorboard"]), ("wandb", ["wandb"])],
)
def test_a_missing_library_is_one_line_and_writes_nothing(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
    name: str,
    modules: list[str],
) -> None:
    run = tmp_path / "run"
    assert train(run, 5) == 0
    config = (run / "config.json").read_text()
    capsys.readouterr()
    for module in modules:
        monkeypatch.setitem(sys.modules, module, None)  # `import module` fails
    message = f'--logger {name}: needs the {name} package (pip install "a2cm_phys[{name}]")'
    new = tmp_path / "new"
    assert train(new, 5, "--logger", name) == 2
    err = capsys.readouterr().err
    assert err.strip() == f"error: {message}" and "Traceback" not in err
    assert not new.exists()
    assert resume(run, 10, "--logger", name) == 2
    assert capsys.readouterr().err.strip() == f"error: {message}"
    assert (run / "config.json").read_text() == config  # no session was added
    assert checkpoint.load(run)["update"] == 5


def test_a_logger_that_cannot_write_warns_and_the_run_goes_on(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    run = tmp_path / "run"
    (run / "metrics" / "updates.csv").mkdir(parents=True)  # where the CSV file should go
    assert train(run, 10, "--logger", "csv") == 0
    err = capsys.readouterr().err
    warnings = [line for line in err.splitlines() if line.startswith("warning: --logger csv:")]
    assert len(warnings) == 1 and "updates.csv" in warnings[0]
    log = read_run(run)
    assert log.clean and len(log.updates) == 10
    assert checkpoint.load(run)["update"] == 10
