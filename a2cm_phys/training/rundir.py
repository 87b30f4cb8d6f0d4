"""A run directory's files: their names, the one-writer lock, and atomic writes.

A new run's folder is named :func:`run_name` plus the time (:func:`make_run_dir`). A run
directory holds ``config.json``, ``checkpoint.pt`` (and ``checkpoint.prev.pt``, the
previous good one), ``summary.json`` and the log parts ``episodes*.mcap``. Exactly one
process writes a run at a time: :func:`run_lock` takes an exclusive ``fcntl.flock`` on
``RUN_DIR/.lock`` for the writer's whole life; readers take no lock. Every file a user
depends on is replaced atomically (:func:`write_atomic`: a temp file, ``fsync``,
``os.replace``), so a kill or a full disk leaves the old file or the new one, never half of
one, and no temp file behind.

See ``docs/design.md`` (the run directory) for what the lock guarantees on shared file
systems.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import json
import os
import re
from collections.abc import Iterator
from datetime import datetime
from pathlib import Path
from typing import Any

from ..base.errors import UserError
from ..base.versions import library_versions
from ..config import ConfigError, Scenario, Train, to_dict

CONFIG_NAME = "config.json"
"""The resolved scenario and training config, the commands and library versions."""

CHECKPOINT_NAME = "checkpoint.pt"
"""The latest checkpoint."""

PREVIOUS_CHECKPOINT_NAME = "checkpoint.prev.pt"
"""The checkpoint before the latest: the fallback when the latest is damaged."""

SUMMARY_NAME = "summary.json"
"""The run's statistics, written when a session ends."""

LOCK_NAME = ".lock"
"""The file :func:`run_lock` locks (it holds the writer's pid)."""

LOG_PART = re.compile(r"episodes(?:-.*)?\.mcap")
"""Names of the run log's parts (see :mod:`a2cm_phys.record.parts`)."""

RUN_FILES = (CONFIG_NAME, CHECKPOINT_NAME, PREVIOUS_CHECKPOINT_NAME, SUMMARY_NAME)
"""Files of a run besides its log parts."""


_HELD: set[int] = set()  # descriptors of the run locks this process holds


def _drop_inherited_locks() -> None:
    """In a forked child (a physics worker): close the locks' descriptors it inherited, so
    that the lock goes with the writer alone and a resume right after the writer was
    killed never waits for its workers to notice."""
    for fd in list(_HELD):
        with contextlib.suppress(OSError):
            os.close(fd)
    _HELD.clear()


os.register_at_fork(after_in_child=_drop_inherited_locks)


class RunBusy(UserError):
    """Another process writes this run (it holds the run's lock); the message names it."""


def is_run_file(path: str | Path) -> bool:
    """Whether ``path`` names one of a run's own files (config, checkpoints, summary, log
    parts, lock) in a folder that holds a run: outputs must never be written there."""
    path = Path(path).absolute()
    folder = path.parent
    markers = any((folder / name).exists() for name in (CONFIG_NAME, CHECKPOINT_NAME))
    if not markers and not any(folder.glob("episodes*.mcap")):
        return False
    name = path.name
    return name in RUN_FILES or name == LOCK_NAME or bool(LOG_PART.fullmatch(name))


@contextlib.contextmanager
def run_lock(run_dir: str | Path) -> Iterator[None]:
    """Hold the exclusive writer's lock of ``run_dir`` for the block (the folder must exist).

    Raises :class:`RunBusy` at once, naming the run and the holder's pid, when another
    process holds it. The lock is the kernel's: it goes with the process, so a killed
    writer never leaves a stale lock behind.
    """
    run_dir = Path(run_dir)
    path = run_dir / LOCK_NAME
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as err:
            if err.errno not in (errno.EWOULDBLOCK, errno.EACCES):
                raise
            raise RunBusy(
                f"{run_dir}: another process (pid {_holder(fd)}) is writing this run"
            ) from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        _HELD.add(fd)
        yield
    finally:
        _HELD.discard(fd)
        os.close(fd)  # releases the lock


def _holder(fd: int) -> str:
    """The pid the lock's holder wrote, or ``unknown``."""
    text = os.pread(fd, 32, 0).decode(errors="replace").strip()
    return text if text.isdigit() else "unknown"


def write_atomic(path: str | Path, data: bytes | str) -> None:
    """Replace ``path`` with ``data`` atomically and durably: a crash or a full disk leaves
    the old file or the new one, and never a temp file (an ``OSError`` naming ``path`` is
    raised after the temp file is removed)."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp")
    raw = data.encode() if isinstance(data, str) else data
    try:
        with open(tmp, "wb") as fh:
            fh.write(raw)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except OSError as err:
        tmp.unlink(missing_ok=True)
        raise OSError(err.errno, err.strerror or str(err), str(path)) from None
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    fsync_dir(path.parent)


def fsync_dir(folder: str | Path) -> None:
    """Make a rename or a new file in ``folder`` durable (a no-op where folders can't be
    opened)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def remove_stray_temps(run_dir: str | Path) -> list[str]:
    """Remove the temp files a writer killed mid-write left in ``run_dir`` (call it only
    while holding the run's lock); the names removed."""
    removed = []
    for tmp in Path(run_dir).glob(".*.tmp"):
        tmp.unlink(missing_ok=True)
        removed.append(tmp.name)
    return sorted(removed)


def run_name(scenario: str, algo: str, seed: int, preset: str | None = None) -> str:
    """A run's name: ``<scenario>-<algo>[-<preset>]-s<seed>`` (``grid_collision-a2cm-paper-s0``;
    without a preset, ``grid_collision-a2cm-s0``), so that runs of the paper's method and of
    ours are told apart at a glance."""
    middle = f"-{preset}" if preset else ""
    return f"{scenario}-{algo}{middle}-s{seed}"


def make_run_dir(
    logdir: str | Path, scenario: Scenario, cfg: Train, preset: str | None = None
) -> Path:
    """Create ``<logdir>/<run_name>-<YYYYmmdd-HHMMSS>[-k]/`` and return it (``k`` counts
    runs started in the same second); a :class:`UserError` naming ``--logdir`` if the
    folder cannot be made there."""
    stamp = datetime.now().strftime("%Y%m%d-%H%M%S")
    logdir = Path(logdir)
    base = logdir / f"{run_name(scenario.name, cfg.algo, cfg.seed, preset)}-{stamp}"
    if base.resolve().parent != logdir.resolve():  # config.check_limits forbids such names
        raise UserError(f"scenario name {scenario.name!r} would leave --logdir {logdir}")
    for k in range(1000):
        path = base if k == 0 else base.with_name(f"{base.name}-{k}")
        try:
            path.mkdir(parents=True)
            return path
        except FileExistsError:
            if not (path.exists() or path.is_symlink()):  # a parent is in the way, not a run
                raise UserError(f"--logdir {logdir}: cannot create {path}") from None
            continue
    raise FileExistsError(f"{base}: too many runs with this name")


def write_config(
    run_dir: Path, scenario: Scenario, cfg: Train, command: str, preset: str | None = None
) -> None:
    """Write ``config.json`` (atomically): the resolved scenario and training config, the
    preset they started from (its name, or ``null``), the command and the library
    versions."""
    config = {
        "scenario": to_dict(scenario),
        "train": to_dict(cfg),
        "preset": preset,
        "command": command,
        "created": datetime.now().isoformat(timespec="seconds"),
        "versions": library_versions(),
    }
    write_atomic(Path(run_dir) / CONFIG_NAME, json.dumps(config, indent=2) + "\n")


def append_session(
    run_dir: Path, command: str, update: int, scenario: Scenario, cfg: Train
) -> None:
    """Add a resumed session (its command, update and library versions) to ``config.json``,
    with the training config it runs with (the rest, the ``preset`` included, is kept); a
    missing or damaged ``config.json`` is rebuilt from ``scenario`` (the checkpoint's)."""
    path = run_dir / CONFIG_NAME
    try:
        config = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):  # missing or damaged: the checkpoint has the config
        config = None
    if not isinstance(config, dict):
        config = {"scenario": to_dict(scenario), "rebuilt_from_checkpoint": True}
    config["train"] = to_dict(cfg)
    resumed = {"command": command, "at_update": update, "versions": library_versions()}
    if not isinstance(config.get("resumed"), list):
        config["resumed"] = []
    config["resumed"].append(resumed)
    write_atomic(path, json.dumps(config, indent=2) + "\n")


def read_config(run_dir: Path) -> dict[str, Any]:
    """The ``scenario`` and ``train`` dicts of the run's ``config.json``; a
    :class:`~a2cm_phys.config.ConfigError` naming the file if it is missing, unreadable or
    holds no such dicts."""
    path = Path(run_dir) / CONFIG_NAME
    try:
        config = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as err:
        raise ConfigError(f"{path}: unreadable ({err})") from None
    if not (
        isinstance(config, dict)
        and isinstance(config.get("scenario"), dict)
        and isinstance(config.get("train"), dict)
    ):
        raise ConfigError(f"{path}: holds no scenario and train configuration")
    return {"scenario": config["scenario"], "train": config["train"]}
