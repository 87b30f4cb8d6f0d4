"""The report's headline figures, and the quotes of them in other documents.

A document quotes a figure of the report between two markers, invisible once rendered::

    <!-- results: main-job -->2.940 steps (…)<!-- /results -->

:func:`fill_quotes` rewrites every quote from ``results.json`` (``experiments --quote-in
README.md,BENCHMARKS.md``), and a test checks that the committed documents equal their
rewrite, so a figure in the README cannot drift from the report. The figures are read
from ``results.json`` alone, so the check needs no run, log or checkpoint.
"""

from __future__ import annotations

import json
import os
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from ...config.parse import ConfigError
from ...training.rundir import write_atomic

QUOTE = re.compile(r"<!-- results: ([a-z0-9_-]+) -->(.*?)<!-- /results -->", re.DOTALL)
"""A quote: its key, then the text the report gives for it."""

PENDING = "not in the report yet (its runs are pending)"
"""What a quote says while the report lacks the runs behind it."""

CONTINUOUS_SCENARIOS = ("phys_cont", "phys_cont_flee", "phys_cont_collision")


def _greedy(results: dict[str, Any], group: str, scenario: str, algo: str, key: str) -> list:
    return [
        float(r["greedy"][key])
        for r in results.get("runs", [])
        if (r["group"], r["scenario"], r["algo"]) == (group, scenario, algo)
        and r.get("greedy")
        and r["greedy"].get(key) is not None
    ]


def _seeds(n: int) -> str:
    return "1 seed" if n == 1 else f"median of {n} seeds"


def main_job(results: dict[str, Any]) -> str:
    """The main job's team (``ours``, ``grid_collision``, A2CM) played greedily: capture
    steps (the median and the worst seed) and collisions per game."""
    steps = _greedy(results, "ours", "grid_collision", "a2cm", "capture_steps")
    if not steps:
        return PENDING
    coll = _greedy(results, "ours", "grid_collision", "a2cm", "collisions")
    worst = f"; worst {max(steps):.3f}" if len(steps) > 1 else ""
    return (
        f"{np.median(steps):.3f} steps ({_seeds(len(steps))}{worst}), "
        f"{max(coll):.3g} collisions a game at most"
    )


def optimum(results: dict[str, Any]) -> str:
    """The exact optimum against the random evader (the reference of ``grid_collision``)."""
    ref = results.get("references", {}).get("grid_collision")
    return f"{ref['length']:.3f} steps" if ref else PENDING


def continuous(results: dict[str, Any], scenario: str) -> str:
    """Continuous A2CM's greedy capture time ÷ ``pursuit``'s on ``scenario`` (median seed)."""
    pursuit = results.get("pursuit", {}).get(scenario)
    steps = _greedy(results, "continuous", scenario, "a2cm", "length")
    if not pursuit or not steps:
        return PENDING
    mid = float(np.median(steps))
    return (
        f"{mid / pursuit['length']:.3f}× `pursuit` ({mid:.2f} against "
        f"{pursuit['length']:.2f} steps, {_seeds(len(steps))})"
    )


def worst_case(results: dict[str, Any], group: str) -> str:
    """A self-play group's pursuers' exact worst case, A2CM then A2C: the median seed and
    the range."""
    parts = []
    for algo in ("a2cm", "a2c"):
        rows = results.get("exploit", {}).get(f"{group}/{algo}") or []
        values = [float(f["exploit_worst_case"]) for f in rows if f]
        if values:
            spread = f", {min(values):.2f}–{max(values):.2f}" if len(values) > 1 else ""
            parts.append(f"{algo.upper()} {np.median(values):.2f}{spread}")
    if not parts:
        return PENDING
    n = max(len(results["exploit"].get(f"{group}/{a}") or []) for a in ("a2cm", "a2c"))
    return f"{'; '.join(parts)} steps ({_seeds(n)}, range over seeds)"


def game_value(results: dict[str, Any]) -> str:
    """The game's value from the standard start (mixed strategies), bracketed by the
    equilibrium evader's and the equilibrium team's exact worst cases."""
    value = results.get("game_value")
    if not value:
        return PENDING
    return f"[{value['lower']:.3f}, {value['upper']:.3f}] steps (horizon {value['horizon']})"


ROWS: dict[str, tuple[str, str, Callable[[dict[str, Any]], str]]] = {
    "main-job": (
        "The main job's team, greedy (`grid_collision`, A2CM)",
        "#ours-grid",
        main_job,
    ),
    "optimum": ("The exact optimum against the random evader", "#ours-grid", optimum),
    **{
        f"continuous-{s}": (
            f"Continuous A2CM ÷ `pursuit`, `{s}`",
            "#continuous",
            lambda r, s=s: continuous(r, s),
        )
        for s in CONTINUOUS_SCENARIOS
    },
    "descent-worst": (
        "Exploitability descent's pursuers, exact worst case (`grid_vs`)",
        "#descent",
        lambda r: worst_case(r, "descent"),
    ),
    "selfplay-worst": (
        "Simultaneous self-play's pursuers, exact worst case (`grid_vs`)",
        "#selfplay",
        lambda r: worst_case(r, "selfplay"),
    ),
    "game-value": ("The game's value (`grid_vs`, mixed strategies)", "#descent", game_value),
}
"""Each headline figure: its key, what it is, its section of the report, how it is read."""


def headline_figures(results: dict[str, Any]) -> dict[str, str]:
    """Every headline figure's text, by key, from ``results.json``'s content."""
    return {key: read(results) for key, (_, _, read) in ROWS.items()}


def headline_table(results: dict[str, Any], report: str = "docs/RESULTS.md") -> str:
    """The headline figures as a Markdown table linking each to its section of ``report``."""
    figures = headline_figures(results)
    lines = ["| figure | the report's value |", "|---|---|"]
    for key, (what, anchor, _) in ROWS.items():
        lines.append(f"| [{what}]({report}{anchor}) | {figures[key]} |")
    meta = results.get("meta", {})
    lines.append("")
    lines.append(
        f"From `{report}` ({meta.get('runs', 0)} runs, {meta.get('date', 'undated')}; "
        "rewritten by `experiments --quote-in`)."
    )
    return "\n" + "\n".join(lines) + "\n"


def quote_text(results: dict[str, Any], key: str, report: str = "docs/RESULTS.md") -> str:
    """What the quote ``key`` says: one figure, or ``headline`` for the whole table."""
    if key == "headline":
        return headline_table(results, report)
    if key not in ROWS:
        known = ", ".join(["headline", *ROWS])
        raise ConfigError(f"no headline figure '{key}' (figures: {known})")
    return headline_figures(results)[key]


def fill_quotes(text: str, results: dict[str, Any], report: str = "docs/RESULTS.md") -> str:
    """``text`` with every quote rewritten from ``results`` (a :class:`ConfigError` names a
    quote of an unknown figure)."""

    def fill(match: re.Match[str]) -> str:
        key = match.group(1)
        return f"<!-- results: {key} -->{quote_text(results, key, report)}<!-- /results -->"

    return QUOTE.sub(fill, text)


def quote_in(paths: list[Path], results_path: Path) -> list[Path]:
    """Rewrite the quotes in each of ``paths`` from ``results_path``; return the files that
    changed (written atomically). The link to the report is relative to each file."""
    results = json.loads(results_path.read_text())
    changed = []
    for path in paths:
        try:
            text = path.read_text()
        except OSError as err:
            raise ConfigError(f"--quote-in: cannot read {path}: {err.strerror}") from None
        report = Path(os.path.relpath(results_path.with_name("RESULTS.md"), path.parent))
        try:
            new = fill_quotes(text, results, report.as_posix())
        except ConfigError as err:
            raise ConfigError(f"{path}: {err}") from None
        if new != text:
            write_atomic(path, new)
            changed.append(path)
    return changed
