"""From finished runs to ``RESULTS.md``, ``results.json`` and the figures."""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path
from typing import Any

from ...base.versions import __version__
from ...training.rundir import write_atomic
from ..watch import RunsProgress
from .claim import Claim, Data, team_name
from .claims import our_claims, paper_claims
from .markdown import report
from .measure import (
    RunResult,
    cross_play,
    exploit,
    export_parity,
    game_value_bracket,
    measure,
    minimax_bounds,
    oracle_worst_case,
    played_actors,
    reference,
)
from .plan import EXPERIMENTS, SELF_PLAY_GROUPS, PlannedRun
from .work_claims import work_claims


def session_totals(sessions: list[dict[str, Any]]) -> dict[str, Any]:
    """What the recorded sessions of the command add up to.

    ``total_wall``: the sum of their durations; ``clock_wall``: the wall-clock time they
    covered, sessions that ran at the same time counted once (sessions recorded without a
    start time are added whole); ``sessions``; ``parallel``: how their runs were trained
    (older records without it: read from the command).
    """
    spans, clock = [], 0.0
    for s in sessions:
        if "started" in s:
            spans.append((float(s["started"]), float(s["started"]) + float(s["elapsed_s"])))
        else:
            clock += float(s["elapsed_s"])
    end = -math.inf
    for lo, hi in sorted(spans):
        clock += max(0.0, hi - max(lo, end))
        end = max(end, hi)
    ways = []
    for s in sessions:
        if "--report-only" in s["command"]:
            continue  # trained nothing
        how = s.get("training") or ("sequential" if "--sequential" in s["command"] else "on Ray")
        ways.append(how)
    # an older record says only "on Ray" where a newer one says how many at a time
    distinct = [w for w in dict.fromkeys(ways) if not any(o != w and o.startswith(w) for o in ways)]
    return {
        "total_wall": sum(float(s["elapsed_s"]) for s in sessions),
        "clock_wall": clock,
        "sessions": len(sessions),
        "parallel": ", ".join(distinct) or "none: the runs existed already",
    }


def _why_missing(run: PlannedRun, errors: dict[str, str]) -> str:
    key = f"{run.cell.group}/{run.spec.name}"
    if key in errors:
        return f"failed: {errors[key]}"
    if run.state == "partial":
        return "interrupted (its checkpoint is kept: the same command resumes it)"
    return "not run"


def collect(
    runs: list[PlannedRun], errors: dict[str, str], eval_episodes: int
) -> tuple[dict[tuple[str, str, str], list[RunResult]], list[tuple[PlannedRun, str]]]:
    """The finished runs measured, by cell, and the runs that are missing (with why)."""
    by_cell: dict[tuple[str, str, str], list[RunResult]] = {}
    missing = []
    done = [run for run in runs if run.state == "done"]
    for run in runs:
        by_cell.setdefault((run.cell.group, run.cell.scenario, run.cell.algo), [])
        if run.state != "done":
            missing.append((run, _why_missing(run, errors)))
    with RunsProgress("measuring runs", len(done), out=sys.stderr) as progress:
        for run in done:
            name = f"{run.cell.group}/{run.run_dir.name}"
            progress.started(name)
            try:
                summary = json.loads((run.run_dir / "summary.json").read_text())
                key = (run.cell.group, run.cell.scenario, run.cell.algo)
                by_cell[key].append(measure(run, summary, eval_episodes))
            except Exception as err:  # a damaged run must not sink the report
                missing.append((run, f"could not be measured: {type(err).__name__}: {err}"))
            progress.finished(name)
    return {k: v for k, v in by_cell.items() if v}, missing


def _figures(data: Data, out: Path, groups: list[str], modes: list[str]) -> dict[str, Path]:
    from ...analysis.figures import Panel, Reference, plot_aggregate
    from ...analysis.run_series import Run, thinned_run
    from ...training.runs import run_label

    def loaded(results: list[RunResult]) -> list[Run]:
        # a run without a finished episode (e.g. a tiny budget) has no curve: draws nothing
        return [
            thinned_run(r.curve, run_label(r.run.run_dir), r.run.cell.scenario)
            for r in results
            if r.curve
        ]

    def ref_of(scenario: str) -> Reference | None:
        ref = data.references.get(scenario) or data.pursuit.get(scenario)
        if not ref:
            return None
        return Reference(ref["policy"].replace(" (played)", ""), ref["length"], ref["return"])

    def panel(group: str, scenario: str, title: str) -> Panel | None:
        lines = {}
        for algo in ("a2c", "a2cm"):
            results = data.runs(group, scenario, algo)
            runs = loaded(results)
            if runs:  # "A2CM (paper)" for the paper preset's runs: run_label
                lines[run_label(results[0].run.run_dir)] = runs
        return Panel(title, lines, ref_of(scenario)) if lines else None

    layouts: list[tuple[str, str, list[Panel | None]]] = []
    for group in ("paper", "ours"):
        if group in groups:
            for mode in modes:
                panels = [
                    panel(group, sc[mode], f"{exp}: {name}\n({sc[mode]})")
                    for exp, (name, sc) in EXPERIMENTS.items()
                ]
                layouts.append((group, mode, panels))
    if "continuous" in groups:
        from .plan import CONTINUOUS

        layouts.append(("continuous", "physics", [panel("continuous", s, s) for s in CONTINUOUS]))
    for group in SELF_PLAY_GROUPS:
        if group in groups:
            layouts.append((group, "grid", [panel(group, "grid_vs", "grid_vs")]))
    written = {}
    names = {"paper": "paper's method", "ours": "our defaults"}
    for group, mode, panels in layouts:
        panels = [p for p in panels if p is not None]
        if not panels:
            continue
        what = f"{names.get(group, group)}, {mode}"
        for column, kind, title in (
            ("length", "lengths", "Steps per episode"),
            ("return", "returns", "Return ÷ the reference's"),
        ):
            if group in SELF_PLAY_GROUPS and column == "return":
                continue
            path = out / "figures" / f"{group}_{mode}_{kind}.png"
            plot_aggregate(panels, column, path, f"{title} ({what}; mean of seeds, 95% band)")
            written[f"{group}/{mode}/{kind}"] = path
    return written


def build_report(
    runs: list[PlannedRun],
    errors: dict[str, str],
    out: Path,
    logdir: Path,
    meta: dict[str, Any],
    start: float,
    args: argparse.Namespace,
    groups: list[str],
    modes: list[str],
) -> list[tuple[PlannedRun, str]]:
    """Measure the finished runs, write the report; return the runs it lacks."""
    out.mkdir(parents=True, exist_ok=True)
    logdir.mkdir(parents=True, exist_ok=True)
    cache = logdir / "report_cache.json"
    by_cell, missing = collect(runs, errors, args.eval_episodes)
    data = Data(by_cell, {}, modes=modes, groups=groups)
    add_references(data, runs, args.eval_episodes, cache)
    crossplay = add_self_play(data, args, cache) if set(SELF_PLAY_GROUPS) & set(groups) else []
    figures = _figures(data, out, groups, modes)
    add_parity(data)
    records = Path(args.bench_records) if args.bench_records else None
    claims = paper_claims(data) + our_claims(data) + work_claims(records, data.parity)
    elapsed, sessions = record_session(logdir, meta, start)
    runs_measured = sum(len(v) for v in by_cell.values())
    meta = {**meta, "version": __version__, "runs": runs_measured, "elapsed": elapsed}
    meta["bench_records"] = str(records) if records and records.is_dir() else None
    meta.update(session_totals(sessions))
    write_atomic(out / "RESULTS.md", report(data, claims, out, figures, crossplay, missing, meta))
    results = results_json(data, claims, crossplay, missing, meta)
    write_atomic(out / "results.json", json.dumps(results, indent=1, default=str) + "\n")
    return missing


def add_references(data: Data, runs: list[PlannedRun], episodes: int, cache: Path) -> None:
    """The reference of each measured scenario (:func:`~.measure.reference`) into
    ``data``: the preset groups' in ``references``, the continuous group's (``pursuit``)
    in ``pursuit``."""
    overrides = {r.cell.scenario: r.spec.overrides for r in runs}
    into = {"paper": data.references, "ours": data.references, "continuous": data.pursuit}
    todo: dict[tuple[str, str], dict[str, Any]] = {}  # (kind, scenario) → where it goes
    for group, scenario, _ in data.by_cell:
        if group in into:
            todo[("pursuit" if group == "continuous" else "reference", scenario)] = into[group]
    with RunsProgress("references", len(todo), unit="scenarios", out=sys.stderr) as progress:
        for (_, scenario), target in todo.items():
            progress.started(scenario)
            if scenario not in target:
                target[scenario] = reference(scenario, overrides[scenario], episodes, cache)
            progress.finished(scenario)


PARITY_GROUPS = ("ours", "continuous", *SELF_PLAY_GROUPS)
"""The groups whose runs' exported actors are checked (the paper's method's too would
repeat the same graphs)."""


def add_parity(data: Data) -> None:
    """Each run's export parity (:func:`~.measure.export_parity`) into ``data.parity`` by
    ``group/scenario/algo``, for the runs that can be measured."""
    todo = [
        (key, r)
        for key, results in data.by_cell.items()
        if key[0] in PARITY_GROUPS
        for r in results
    ]
    with RunsProgress("export parity", len(todo), out=sys.stderr) as progress:
        for (group, scenario, algo), r in todo:
            name = f"{group}/{r.run.run_dir.name}"
            progress.started(name)
            checked = export_parity(r.run)
            if checked is not None:
                data.parity.setdefault(f"{group}/{scenario}/{algo}", []).append(checked)
            progress.finished(name)


def add_self_play(data: Data, args: argparse.Namespace, cache: Path) -> list[dict[str, Any]]:
    """The self-play groups' exact measures into ``data`` (unless ``--no-exploit``): each
    run's exploitability (``data.exploit``, by ``group/algo``), the oracle's worst case,
    the pure-strategy minimax bounds and the game's value (mixed strategies, bracketed);
    then the cross-play table (also ``data.crossplay``), or ``[]`` with no learned side to
    play."""
    sp = {
        f"{group}/{algo}": data.runs(group, "grid_vs", algo)
        for group in SELF_PLAY_GROUPS
        for algo in ("a2cm", "a2c")
    }
    sp = {key: results for key, results in sp.items() if results}
    horizon = args.exploit_max_steps
    if any(sp.values()) and not args.no_exploit:
        runs = sum(len(results) for results in sp.values())
        with RunsProgress("exact measures", 3 + runs, unit="solves", out=sys.stderr) as progress:
            progress.started("the oracle's worst case")
            data.oracle_worst_case = oracle_worst_case("grid_vs", horizon, cache)
            progress.finished("the oracle's worst case")
            progress.started("minimax")
            data.minimax = minimax_bounds("grid_vs", horizon, cache)
            progress.finished("minimax")
            progress.started("the game's value")
            data.game_value = game_value_bracket("grid_vs", horizon, cache)
            progress.finished("the game's value")
            for key, results in sp.items():
                data.exploit[key] = []
                for r in results:
                    progress.started(r.run.run_dir.name)
                    data.exploit[key].append({**exploit(r.run, horizon), "seed": r.seed})
                    progress.finished(r.run.run_dir.name)
    pursuers, evaders = crossplay_sides(data, sp)
    if len(pursuers) <= 1:
        return []
    data.crossplay = cross_play("grid_vs", pursuers, evaders, args.crossplay_episodes, cache)
    return data.crossplay


def crossplay_sides(
    data: Data, selfplay: dict[str, list[RunResult]]
) -> tuple[dict[str, list[str]], dict[str, list[str]]]:
    """The cross-play's pursuer and evader groups: the named policies, each self-play
    group's algorithms' runs (``selfplay`` keyed by ``group/algo``; seeds in order) on both
    sides, and our A2CM trained against the random evader as pursuers; each run as the
    file it is played from (:func:`~.measure.played_actors`)."""
    pursuers: dict[str, list[str]] = {"oracle": ["oracle"], "minimax": ["minimax"]}
    evaders: dict[str, list[str]] = {"random": ["random"], "flee": ["flee"]}
    for key, results in selfplay.items():
        played = [played_actors(r.run.run_dir) for r in sorted(results, key=lambda r: r.seed)]
        if played:
            pursuers[team_name(key)] = played
            evaders[f"{team_name(key)} evader"] = played
    vs_random = data.runs("ours", "grid", "a2cm")
    if vs_random:
        pursuers["A2CM vs random (ours)"] = [
            played_actors(r.run.run_dir) for r in sorted(vs_random, key=lambda r: r.seed)
        ]
    return pursuers, evaders


def record_session(
    logdir: Path, meta: dict[str, Any], start: float
) -> tuple[float, list[dict[str, Any]]]:
    """Add this session (its command, date and training from ``meta``; started at
    ``start``, :func:`time.perf_counter`) to the log folder's ``report_sessions.json``;
    return its time and every session recorded."""
    sessions_path = logdir / "report_sessions.json"
    try:
        sessions = json.loads(sessions_path.read_text()) if sessions_path.exists() else []
    except (OSError, ValueError):
        sessions = []
    elapsed = time.perf_counter() - start
    sessions.append(
        {
            "command": meta["command"],
            "date": meta["date"],
            "elapsed_s": elapsed,
            "started": time.time() - elapsed,
            "training": meta["parallel"],
        }
    )
    write_atomic(sessions_path, json.dumps(sessions, indent=1) + "\n")
    return elapsed, sessions


def results_json(
    data: Data,
    claims: list[Claim],
    crossplay: list[dict[str, Any]],
    missing: list[tuple[PlannedRun, str]],
    meta: dict[str, Any],
) -> dict[str, Any]:
    """``results.json``: the meta, the claims, every measured run, the references (their
    episodes' lengths left out) and the self-play measures."""
    rows = [
        {
            "group": r.run.cell.group,
            "scenario": r.run.cell.scenario,
            "algo": r.run.cell.algo,
            "seed": r.seed,
            "episodes": r.episodes,
            "env_steps": r.env_steps,
            "late_length": r.late_length,
            "collisions_per_episode": r.collisions_per_episode,
            "wall_time": r.wall_time,
            "greedy": r.greedy,
            "run_dir": str(r.run.run_dir),
        }
        for results in data.by_cell.values()
        for r in results
    ]
    results = {
        "meta": meta,
        "claims": [c.__dict__ for c in claims],
        "runs": rows,
        "references": data.references,
        "pursuit": {
            k: {kk: vv for kk, vv in v.items() if kk != "lengths"} for k, v in data.pursuit.items()
        },
        "exploit": data.exploit,
        "oracle_worst_case": data.oracle_worst_case,
        "minimax": data.minimax,
        "game_value": data.game_value,
        "parity": data.parity,
        "crossplay": crossplay,
        "missing": [{"run": f"{r.cell.group}/{r.run_dir.name}", "why": w} for r, w in missing],
    }
    for ref in results["references"].values():
        if ref:
            ref.pop("lengths", None)
    return results
