"""The cells of the report, their runs in the sweep layout, and the wall-time estimate.

A *cell* is a scenario × algorithm of a group; its runs are one per seed, in the sweep
layout ``<logdir>/<group>/<scenario>-<algo>[-paper]-s<seed>/`` (see :mod:`a2cm_phys.sweep`),
so a finished run is skipped and an unfinished one resumed. An existing run is found by
its resolved configuration, not its name (:func:`~a2cm_phys.study.rundirs.find_run`): the
``paper`` group's runs named before the preset was part of the name are found too.
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ...config import ConfigError, preset
from ..rundirs import check_reusable, execute, existing_runs, find_run, run_state
from ..runspec import RunSpec
from ..watch import RunsProgress

GROUPS = ("paper", "ours", "continuous", "selfplay", "descent")
"""The groups of cells, in report order."""

SELF_PLAY_GROUPS = ("selfplay", "descent")
"""The groups whose evader learns (grid self-play): exact exploitability, cross-play."""

GROUP_TITLES = {
    "paper": "The paper's experiments, its exact method (`--preset paper`)",
    "ours": "The paper's experiments, our defaults",
    "continuous": "Continuous control",
    "selfplay": "The learning evader (grid self-play)",
    "descent": "Grid self-play by exploitability descent (`--preset descent`)",
}

EXPERIMENTS: dict[int, tuple[str, dict[str, str]]] = {
    1: ("no collision", {"grid": "grid", "physics": "phys"}),
    2: ("collision terminates", {"grid": "grid_collision", "physics": "phys_collision"}),
    3: (
        "collision penalised only",
        {"grid": "grid_collision_continue", "physics": "phys_collision_continue"},
    ),
}
"""Experiment number → (name, scenario per mode)."""

CONTINUOUS = ("phys_cont", "phys_cont_flee", "phys_cont_collision")
"""Continuous-control scenarios (against the random, fleeing evader; with collisions)."""

SELFPLAY = ("grid_vs",)
"""Self-play scenarios (the evader learns; exact exploitability on the grid)."""

ALGOS = ("a2c", "a2cm")
MODES = ("grid", "physics")


@dataclass(frozen=True)
class Cell:
    """A scenario × algorithm of a group; ``experiment`` is the paper's number, if any."""

    group: str
    scenario: str
    algo: str
    mode: str
    experiment: int | None = None

    @property
    def key(self) -> str:
        """``group/scenario/algo``."""
        return f"{self.group}/{self.scenario}/{self.algo}"


@dataclass(frozen=True)
class PlannedRun:
    """One run of the report: its cell, its sweep spec, its sweep's folder and its run
    directory there (:func:`~a2cm_phys.study.rundirs.find_run`)."""

    cell: Cell
    spec: RunSpec
    sweep_dir: Path
    run_dir: Path

    @property
    def state(self) -> str:
        """``done``, ``partial`` or ``new`` (:func:`a2cm_phys.sweep.run_state`)."""
        return run_state(self.run_dir)


@dataclass
class GroupOptions:
    """The training options of a group: ``--set`` overrides (scenario, train)."""

    train: dict[str, Any] = field(default_factory=dict)
    scenario: dict[str, Any] = field(default_factory=dict)


def cells(groups: list[str], modes: list[str]) -> list[Cell]:
    """Every cell of the chosen groups (the paper's experiments in the chosen modes)."""
    out = []
    for group in groups:
        if group in ("paper", "ours"):
            for exp, (_, scenarios) in EXPERIMENTS.items():
                for mode in modes:
                    for algo in ALGOS:
                        out.append(Cell(group, scenarios[mode], algo, mode, exp))
        elif group == "continuous":
            out += [Cell(group, s, a, "physics") for s in CONTINUOUS for a in ALGOS]
        elif group in SELF_PLAY_GROUPS:
            out += [Cell(group, s, a, "grid") for s in SELFPLAY for a in ALGOS]
    return out


GROUP_PRESETS = {"paper": "paper", "descent": "descent"}
"""The preset a group's runs start from (the others: our defaults)."""


def group_train(group: str, base: dict[str, Any], options: GroupOptions) -> dict[str, Any]:
    """A group's training options: its preset (:data:`GROUP_PRESETS`) or our defaults,
    then the shared ``--set train.KEY`` values ``base``, then the group's own."""
    name = GROUP_PRESETS.get(group)
    values = preset(name) if name else {}
    return {**values, **base, **options.train}


def plan(
    groups: list[str],
    modes: list[str],
    seeds: list[int],
    logdir: Path,
    base_train: dict[str, Any],
    options: dict[str, GroupOptions],
) -> list[PlannedRun]:
    """The runs of the report, validated (also against run directories already there)."""
    runs = []
    existing: dict[str, dict[Path, dict[str, Any]]] = {}
    for cell in cells(groups, modes):
        opts = options.get(cell.group, GroupOptions())
        train = group_train(cell.group, base_train, opts)
        sweep_dir = logdir / cell.group
        if cell.group not in existing:
            existing[cell.group] = existing_runs(sweep_dir)
        for seed in seeds:
            spec = RunSpec(
                cell.scenario,
                cell.algo,
                seed,
                train,
                dict(opts.scenario),
                preset=GROUP_PRESETS.get(cell.group),
            )
            spec.resolve()  # a bad option fails here, naming the key
            run_dir = find_run(spec, sweep_dir, existing[cell.group])
            check_reusable(spec, run_dir)
            runs.append(PlannedRun(cell, spec, sweep_dir, run_dir))
    return runs


# --------------------------------------------------------------------------- estimate


@dataclass
class Estimate:
    """Seconds per training update of one cell type, measured on a short run."""

    scenario: str
    group: str
    per_update: float
    steps_per_s: float


def time_cells(
    runs: list[PlannedRun], updates: int, cache: Path | None = None
) -> dict[tuple[str, str], Estimate]:
    """One timed short run (``updates`` updates, A2CM, seed 0, in a temporary folder) per
    group × scenario of ``runs``; cached in ``cache`` (a JSON file) by options."""
    known: dict[str, Any] = {}
    if cache is not None and cache.exists():
        try:
            known = json.loads(cache.read_text())
        except (OSError, ValueError):
            known = {}
    out = {}
    first: dict[tuple[str, str], PlannedRun] = {}
    for run in runs:
        first.setdefault((run.cell.group, run.cell.scenario), run)
    with RunsProgress("timing cells", len(first), unit="cells", out=sys.stderr) as progress:
        for key, run in first.items():
            progress.started("/".join(key))
            out[key] = _time_cell(run, updates, known)
            progress.finished("/".join(key))
    if cache is not None:
        try:
            cache.parent.mkdir(parents=True, exist_ok=True)
            cache.write_text(json.dumps(known, indent=1) + "\n")
        except OSError:
            pass
    return out


def _time_cell(run: PlannedRun, updates: int, known: dict[str, Any]) -> Estimate:
    """The estimate of ``run``'s cell type: from ``known`` (the cache), else timed."""
    train = {**run.spec.train, "updates": updates, "exploit_every": 0}
    spec = RunSpec(run.spec.scenario, "a2cm", 0, train, run.spec.overrides)
    tag = json.dumps([spec.scenario, spec.train, spec.overrides], sort_keys=True, default=str)
    if tag in known:
        per_update, sps = known[tag]
    else:
        with tempfile.TemporaryDirectory(prefix="a2cm-estimate-") as tmp:
            start = time.perf_counter()
            summary = execute(spec, tmp)
            wall = time.perf_counter() - start
        per_update = float(summary.get("wall_time_s", wall)) / updates
        sps = float(summary.get("steps_per_s", 0.0))
        known[tag] = (per_update, sps)
    return Estimate(spec.scenario, run.cell.group, per_update, sps)


EVAL_LENGTH = {"discrete": 5.0, "continuous": 60.0}
"""Assumed greedy episode length (steps) of a trained policy, for the evaluation estimate."""

EXPLOIT_FULL_S = 420.0
"""The evader's exact best response to a team that some evader escapes, over the whole
1,000-step horizon: about 7 minutes on the reference machine (``BENCHMARKS.md``)."""


def estimate_seconds(
    run: PlannedRun,
    est: Estimate,
    eval_episodes: int,
    exploit_steps: int | None,
) -> float:
    """Estimated seconds of one run: training (remaining updates), its greedy evaluation
    and, for self-play, the exact exploitability."""
    scenario, cfg = run.spec.resolve()
    seconds = 0.0
    if run.state != "done":
        seconds += est.per_update * cfg.updates
    sps = est.steps_per_s or 1000.0
    seconds += eval_episodes * EVAL_LENGTH[scenario.control] / sps
    if run.cell.group in SELF_PLAY_GROUPS and exploit_steps != 0:
        horizon = exploit_steps or scenario.max_steps
        seconds += EXPLOIT_FULL_S * min(horizon, scenario.max_steps) / 1000.0
    return seconds


def budgets(runs: list[PlannedRun]) -> str:
    """Each group's training budget as its runs resolve it (scenarios sharing one are
    named together): ``paper: 5,000 updates of 128 steps (grid, phys, …); …``."""
    by_group: dict[str, dict[tuple[int, int], list[str]]] = {}
    for run in runs:
        _, cfg = run.spec.resolve()
        names = by_group.setdefault(run.cell.group, {}).setdefault(
            (cfg.updates, cfg.batch_size), []
        )
        if run.cell.scenario not in names:
            names.append(run.cell.scenario)
    parts = []
    for group, shapes in by_group.items():
        each = [
            f"{updates:,} updates of {batch:,} steps ({', '.join(names)})"
            for (updates, batch), names in shapes.items()
        ]
        parts.append(f"{group}: {'; '.join(each)}")
    return ". ".join(parts) + "." if parts else ""


def check_groups(text: str) -> list[str]:
    """``--groups`` as a list (a :class:`ConfigError` naming a wrong or repeated name)."""
    names = [x.strip() for x in text.split(",") if x.strip()]
    if not names:
        raise ConfigError(f"--groups: '{text}' names no group ({', '.join(GROUPS)})")
    for name in names:
        if name not in GROUPS:
            raise ConfigError(f"--groups: unknown group '{name}' (groups: {', '.join(GROUPS)})")
        if names.count(name) > 1:
            raise ConfigError(f"--groups: '{name}' is given twice")
    return [g for g in GROUPS if g in names]
