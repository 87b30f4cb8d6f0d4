"""What became of a sweep's runs (:class:`Outcome`), and its table: per scenario ×
algorithm across seeds (:func:`summarise`), saved in ``--logdir`` (:func:`write_summary`)
and printed (:func:`format_table`)."""

from __future__ import annotations

import contextlib
import csv
import fcntl
import io
import json
import os
from collections.abc import Iterable, Iterator
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from ..analysis.stats import t_interval
from ..training.rundir import write_atomic
from .rundirs import BUSY
from .runspec import RunSpec

SUMMARY_CSV = "sweep_summary.csv"
"""The sweep's table (per scenario × algorithm), in ``--logdir``."""

SUMMARY_JSON = "sweep_summary.json"
"""The table and every run's outcome, in ``--logdir``."""


@dataclass
class Outcome:
    """What became of one run: its summary, the error it failed with, or why it was busy
    (another process writes it)."""

    spec: RunSpec
    summary: dict[str, Any] | None = None
    error: str | None = None
    attempts: int = 1
    busy: str | None = None

    @property
    def name(self) -> str:
        """The run directory's name: where the run was found (a run named before the preset
        was part of the name keeps its name), else the name a new run gets."""
        if self.summary and self.summary.get("run_dir"):
            return Path(self.summary["run_dir"]).name
        return self.spec.name

    @property
    def status(self) -> str:
        """``ran``, ``resumed``, ``skipped``, ``busy`` or ``failed``."""
        if self.busy is not None:
            return BUSY
        if self.error is not None or self.summary is None:
            return "failed"
        return str(self.summary.get("sweep", "ran"))

    def take(self, result: dict[str, Any]) -> None:
        """Record what :func:`execute` returned."""
        if result.get("sweep") == BUSY:
            self.summary, self.error, self.busy = None, None, str(result["busy"])
        else:
            self.summary, self.error, self.busy = result, None, None

    def describe(self) -> str:
        """The outcome in a few words, for the sweep's progress lines."""
        if self.busy is not None:
            return f"busy ({self.busy})"
        if self.error is not None:
            return f"FAILED ({self.error})"
        return self.status


def summarise(outcomes: Iterable[Outcome]) -> list[dict[str, Any]]:
    """Per scenario × algorithm: mean ± 95% CI (Student t across seeds) of episodes
    completed and final mean episode length."""
    groups: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for o in outcomes:
        if o.summary is not None:
            groups.setdefault((Path(o.spec.scenario).stem, o.spec.algo), []).append(o.summary)
    rows = []
    for (scenario, algo), runs in sorted(groups.items()):
        row: dict[str, Any] = {"scenario": scenario, "algo": algo, "seeds": len(runs)}
        for key in ("episodes", "mean_length_last_1000", "collisions_per_episode", "wall_time_s"):
            mean, half = t_interval([r[key] for r in runs])
            row[key], row[f"{key}_ci95"] = mean, half
        rows.append(row)
    return rows


def write_summary(
    rows: list[dict[str, Any]], outcomes: list[Outcome], sweep_dir: Path
) -> list[Path]:
    """Save the table as ``sweep_summary.csv`` (unless no run finished: then an older one is
    removed, it would describe another sweep) and, with every run's outcome,
    ``sweep_summary.json``, each atomically; returns the files written."""
    with _summary_lock(sweep_dir):
        return _write_summary(rows, outcomes, sweep_dir)


@contextlib.contextmanager
def _summary_lock(sweep_dir: Path) -> Iterator[None]:
    """Two sweeps of one ``--logdir`` write its summary files one after the other: their
    temp files share a name. Waits (the other's writes take milliseconds)."""
    fd = os.open(sweep_dir / ".sweep_summary.lock", os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)  # releases the lock


def _write_summary(
    rows: list[dict[str, Any]], outcomes: list[Outcome], sweep_dir: Path
) -> list[Path]:
    written = []
    csv_path = sweep_dir / SUMMARY_CSV
    if rows:
        text = io.StringIO()
        writer = csv.DictWriter(text, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
        write_atomic(csv_path, text.getvalue())
        written.append(csv_path)
    else:
        csv_path.unlink(missing_ok=True)
    runs = [
        {
            "run": o.name,
            "outcome": o.status,
            "error": o.error,
            "busy": o.busy,
            "attempts": o.attempts,
            "summary": o.summary,
            "spec": asdict(o.spec),
        }
        for o in outcomes
    ]
    json_path = sweep_dir / SUMMARY_JSON
    write_atomic(json_path, json.dumps({"table": rows, "runs": runs}, indent=2, default=str) + "\n")
    written.append(json_path)
    return written


def format_table(rows: list[dict[str, Any]]) -> str:
    """The summary as a markdown table."""
    lines = [
        "| scenario | algo | seeds | episodes | mean length (last 1,000) |",
        "|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['scenario']} | {r['algo']} | {r['seeds']} | {r['episodes']:,.0f} ± "
            f"{r['episodes_ci95']:,.0f} | {r['mean_length_last_1000']:.2f} ± "
            f"{r['mean_length_last_1000_ci95']:.2f} |"
        )
    return "\n".join(lines)
