"""``RESULTS.md``: the claims table first, then each group's tables (every row links its
runs), figures, aggregates, the learning evader, wall times and what could not be run."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from ...analysis.stats import iqm_interval, mean_interval
from .claim import Claim, Data, ci_text, claims_table, fmt
from .claims import PAPER, score
from .measure import RunResult
from .plan import CONTINUOUS, EXPERIMENTS, GROUP_TITLES, SELF_PLAY_GROUPS, PlannedRun


def _ci(values: list[float], digits: int = 3, ceiling: float | None = None) -> str:
    m, lo, hi = mean_interval(values, floor=0.0, ceiling=ceiling)  # all tabulated are >= 0
    if not np.isfinite(m):
        return "—"
    if not np.isfinite(lo):
        return fmt(m, digits)
    return f"{fmt(m, digits)} [{fmt(lo, digits)}, {fmt(hi, digits)}]"


def links(runs: list[RunResult], out: Path) -> str:
    """Links to the runs' directories (relative to the report), by seed."""
    return " ".join(
        f"[s{r.seed}]({Path(os.path.relpath(r.run.run_dir.resolve(), out.resolve())).as_posix()})"
        for r in sorted(runs, key=lambda r: r.seed)
    )


def _ref_text(ref: dict[str, Any] | None) -> str:
    if not ref:
        return "—"
    return f"{fmt(ref['length'], 4)} ({ref['policy'].split(' ')[0]})"


def experiment_tables(data: Data, group: str, out: Path, figures: dict[str, Path]) -> list[str]:
    """A preset group's tables, one per mode, with its figures."""
    lines = [f"## {GROUP_TITLES[group]}", ""]
    for mode in data.modes:
        lines += [
            f'<a id="{group}-{mode}"></a>',
            f"### {mode.capitalize()} mode",
            "",
            "| experiment | algo | seeds | episodes | paper episodes | steps, last 10% | greedy "
            "steps | reference | greedy collisions / ep | wall s / run | paper s | runs |",
            "|---|---|---|---|---|---|---|---|---|---|---|---|",
        ]
        for exp, (name, scenarios) in EXPERIMENTS.items():
            ref = data.references.get(scenarios[mode])
            for algo in ("a2c", "a2cm"):
                runs = data.runs(group, scenarios[mode], algo)
                if not runs:
                    continue
                paper_eps, paper_time = PAPER[exp][algo]
                lines.append(
                    f"| {exp}: {name} | {algo.upper()} | {len(runs)} | "
                    f"{_ci([r.episodes for r in runs], 4)} | {paper_eps:,} | "
                    f"{_ci([r.late_length for r in runs])} | "
                    f"{_ci([r.greedy.get('length', np.nan) for r in runs])} | {_ref_text(ref)} | "
                    f"{_ci([r.greedy.get('collisions', np.nan) for r in runs])} | "
                    f"{_ci([r.wall_time for r in runs])} | {paper_time:,.0f} | "
                    f"{links(runs, out)} |"
                )
        lines += [*figure_lines(figures, f"{group}/{mode}", f"{group} {mode}", out), ""]
    return lines


def figure_lines(figures: dict[str, Path], key: str, title: str, out: Path) -> list[str]:
    """Markdown images of the lengths and returns figures of ``key``, linked from ``out``."""
    lines = []
    for kind in ("lengths", "returns"):
        path = figures.get(f"{key}/{kind}")
        if path:
            rel = Path(os.path.relpath(path.resolve(), out.resolve())).as_posix()
            lines += ["", f"![{title} {kind}]({rel})"]
    return lines


def aggregate_section(data: Data) -> list[str]:
    """IQM of the normalised greedy score per group × mode × algorithm (rliable style)."""
    rows = []
    for mode in data.modes:
        for group in ("paper", "ours"):
            if group not in data.groups:
                continue
            for algo in ("a2c", "a2cm"):
                tasks = []
                for _, scenarios in EXPERIMENTS.values():
                    ref = data.references.get(scenarios[mode])
                    runs = data.runs(group, scenarios[mode], algo)
                    if runs:
                        tasks.append([score(r, ref) for r in runs])
                if tasks:
                    value = iqm_interval(tasks)
                    rows.append(
                        f"| {mode} | {group} | {algo.upper()} | {len(tasks)} | "
                        f"{fmt(value[0])} | {ci_text(value)} |"
                    )
    if not rows:
        return []
    anchors = " ".join(f'<a id="aggregate-{m}"></a>' for m in data.modes)
    return [
        anchors,
        "## Aggregate over the three experiments",
        "",
        "Score of a run: the reference's episode length ÷ its greedy episode length (1 = as "
        "fast as the optimum or reference policy, higher better). Interquartile mean over "
        "every run of the three experiments, 95% stratified bootstrap CI (each experiment's "
        "seeds resampled on their own), as in rliable.",
        "",
        "| mode | group | algo | experiments | IQM score | 95% CI |",
        "|---|---|---|---|---|---|",
        *rows,
        "",
    ]


def continuous_section(data: Data, out: Path, figures: dict[str, Path]) -> list[str]:
    """Continuous control beside ``pursuit`` on the same scenarios."""
    lines = [
        '<a id="continuous"></a>',
        f"## {GROUP_TITLES['continuous']}",
        "",
        "Greedy policies over the evaluation episodes; *length* is the mean episode length "
        "(a capture, a collision ending it, or the 1,000-step limit); `pursuit` (every "
        "pursuer straight at the evader) played on the same episodes.",
        "",
        "| scenario | algo | seeds | greedy length | capture rate | collisions / ep | pursuit "
        "length | pursuit collisions / ep | steps, last 10% | wall s / run | runs |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for scenario in CONTINUOUS:
        p = data.pursuit.get(scenario) or {}
        for algo in ("a2c", "a2cm"):
            runs = data.runs("continuous", scenario, algo)
            if not runs:
                continue
            lines.append(
                f"| {scenario} | {algo.upper()} | {len(runs)} | "
                f"{_ci([r.greedy.get('length', np.nan) for r in runs])} | "
                f"{_ci([r.greedy.get('capture_rate', np.nan) for r in runs], ceiling=1.0)} | "
                f"{_ci([r.greedy.get('collisions', np.nan) for r in runs])} | "
                f"{fmt(p.get('length', np.nan))} | {fmt(p.get('collisions', np.nan))} | "
                f"{_ci([r.late_length for r in runs])} | {_ci([r.wall_time for r in runs])} | "
                f"{links(runs, out)} |"
            )
    lines += figure_lines(figures, "continuous/physics", "continuous", out)
    return [*lines, ""]


def _minimax_text(bounds: dict[str, Any] | None, oracle: dict[str, Any] | None) -> str:
    if not bounds:
        return ""
    oracle_worst = (oracle or {}).get("exploit_worst_case", np.nan)
    verdict = (
        ": a team more robust than the oracle exists"
        if bounds["upper"] < oracle_worst
        else ", no better than the oracle's"
    )
    return (
        f" The game's minimax capture time lies in [{fmt(bounds['lower'])}, "
        f"{fmt(bounds['upper'])}] (`python -m a2cm_phys.oracle --scenario grid_vs "
        "--best-response evader --pursuers minimax`: the evader moving first, then the "
        "pursuers), so no team is escaped for less than the lower figure, and the *minimax "
        "team*, deterministic and optimal when the evader sees its move, has worst case "
        f"{fmt(bounds['upper'])}{verdict}."
    )


def _value_text(value: dict[str, Any] | None) -> str:
    if not value:
        return ""
    return (
        f" With mixed strategies the game's value lies in [{value['lower']:.3f}, "
        f"{value['upper']:.3f}] (horizon {value['horizon']}; `python -m a2cm_phys.oracle "
        "--scenario grid_vs --game-value`: the equilibrium evader's and the equilibrium "
        "team's exact worst cases), the floor of every team's worst case."
    )


SELF_PLAY_TEXT = {
    "selfplay": "Pursuers (A2C or A2CM) and an A2C evader learn together on `grid_vs`.",
    "descent": "Pursuers (A2C or A2CM) and an A2C evader learn together on `grid_vs`, both "
    "by exploitability descent (`--preset descent`: every few updates each team steps "
    "towards beating the other's exact best response). The evader's step reads only its own "
    "policy (the pursuers' exact best response to it) and its rollout learner is not "
    "stepped, so runs of one seed share one evader whatever the pursuers' algorithm: the "
    "A2C and A2CM descent evaders are the same policies, and their cross-play columns agree.",
}


def selfplay_section(data: Data, out: Path, figures: dict[str, Path], group: str) -> list[str]:
    """A self-play group's runs and their exact exploitability, beside the game's value
    bracket."""
    lines = [
        f'<a id="{group}"></a>',
        f"## {GROUP_TITLES[group]}",
        "",
        SELF_PLAY_TEXT[group] + " *Worst case*: "
        "the value of the evader's exact best response to the final pursuers, E[min(capture "
        "time, horizon)]; *pursuers' BR*: the exact best response of a pursuer team to the "
        "final learned evader. The oracle optimal against the random evader has worst case "
        f"{fmt((data.oracle_worst_case or {}).get('exploit_worst_case', np.nan), 4)}."
        + _minimax_text(data.minimax, data.oracle_worst_case)
        + _value_text(data.game_value),
        "",
        "| algo | seed | steps, last 10% | greedy vs random evader | worst case | pursuers' BR "
        "| horizon | exploit s | run |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for algo in ("a2c", "a2cm"):
        runs = data.runs(group, "grid_vs", algo)
        figures_ = {f.get("seed"): f for f in data.exploit.get(f"{group}/{algo}", []) if f}
        for r in sorted(runs, key=lambda r: r.seed):
            e = figures_.get(r.seed, {})
            horizon = e.get("horizon")
            h_text = (
                "—" if horizon is None else f"{horizon}{' (truncated)' * bool(e.get('truncated'))}"
            )
            lines.append(
                f"| {algo.upper()} | {r.seed} | {fmt(r.late_length)} | "
                f"{fmt(r.greedy.get('length', np.nan))} | "
                f"{fmt(e.get('exploit_worst_case', np.nan), 4)} | "
                f"{fmt(e.get('exploit_pursuers_br', np.nan), 4)} | {h_text} | "
                f"{fmt(e.get('seconds', np.nan))} | {links([r], out)} |"
            )
    path = figures.get(f"{group}/grid/lengths")
    if path:
        rel = Path(os.path.relpath(path.resolve(), out.resolve())).as_posix()
        lines += ["", f"![{group} lengths]({rel})"]
    return [*lines, ""]


def crossplay_section(crossplay: list[dict[str, Any]]) -> list[str]:
    """Every pursuer team against every evader on ``grid_vs`` (the self-play groups' teams
    on both sides, the oracle, minimax and our A2CM trained against the random evader)."""
    if not crossplay:
        return []
    evaders = list(dict.fromkeys(row["evader"] for row in crossplay))
    lines = [
        "**Cross-play** (`grid_vs`; sampled policies; mean episode length, capped at "
        "max_steps, and capture rate; learned pursuers and evaders of the same seed index "
        "are paired):",
        "",
        "| pursuers | " + " | ".join(f"evader: {e}" for e in evaders) + " |",
        "|---|" + "---|" * len(evaders),
    ]
    by = {(row["pursuers"], row["evader"]): row for row in crossplay}
    for p in dict.fromkeys(row["pursuers"] for row in crossplay):
        cells = []
        for e in evaders:
            row = by.get((p, e))
            if not row or not row["results"]:
                cells.append("—")
                continue
            length = _ci([x["length"] for x in row["results"]])
            rate = np.mean([x["capture_rate"] for x in row["results"]])
            cells.append(f"{length}, {100 * rate:.0f}% caught")
        lines.append(f"| {p} | " + " | ".join(cells) + " |")
    return [*lines, ""]


def wall_section(
    data: Data, missing: list[tuple[PlannedRun, str]], meta: dict[str, Any]
) -> list[str]:
    """Per-cell wall time, total wall time, cells that could not be run."""
    lines = [
        "## Wall time and what is missing",
        "",
        "| group | scenario | algo | runs | wall s / run (training) | total s |",
        "|---|---|---|---|---|---|",
    ]
    for (group, scenario, algo), runs in data.by_cell.items():
        times = [r.wall_time for r in runs]
        lines.append(
            f"| {group} | {scenario} | {algo.upper()} | {len(runs)} | {_ci(times)} | "
            f"{fmt(float(np.nansum(times)), 4)} |"
        )
    overlap = (
        f", some of which ran side by side ({meta['clock_wall']:,.0f} s of wall clock, "
        "overlaps counted once; "
        if meta["clock_wall"] < meta["total_wall"] - 1.0
        else " ("
    )
    lines += [
        "",
        f"Total wall time of the command(s) that made this report: {meta['total_wall']:,.0f} s "
        f"over {meta['sessions']} session(s){overlap}training runs {meta['parallel']}), of "
        f"which this session {meta['elapsed']:,.0f} s.",
        "",
    ]
    if missing:
        lines += ["**Cells that could not be run** (the tables above lack them):", ""]
        lines += [f"- `{run.cell.group}/{run.run_dir.name}`: {why}" for run, why in missing]
    else:
        lines.append("Every planned run finished.")
    return [*lines, ""]


def later_work_section(meta: dict[str, Any]) -> list[str]:
    """Where the claims on the later issues' work come from."""
    records = meta.get("bench_records")
    source = (
        f"the benchmarks' records in `{records}` (each row of a `.jsonl` one run of a "
        "`benchmarks/` script, the script named in the claim's test)"
        if records
        else "no benchmark records (`--bench-records` named no folder), so only export parity"
    )
    return [
        '<a id="later-work"></a>',
        "## Later work: partial observability, export, scale and speed",
        "",
        "The claims that name an issue test that issue's target. Export parity is "
        "measured here: each run whose checkpoint is at hand is exported to ONNX and its "
        "actors compared with torch's on 10,000 observations (cached beside the run). The "
        f"others come from {source}. A target an issue missed is a row like any other, "
        "and its verdict says so.",
        "",
    ]


def report(
    data: Data,
    claims: list[Claim],
    out: Path,
    figures: dict[str, Path],
    crossplay: list[dict[str, Any]],
    missing: list[tuple[PlannedRun, str]],
    meta: dict[str, Any],
) -> str:
    """The Markdown of ``RESULTS.md``."""
    lines = [
        "# Reproduction report: the paper's claims and ours",
        "",
        f"Generated by `{meta['command']}` on {meta['date']}: {meta['machine']}, "
        f"a2cm_phys {meta['version']}; groups {', '.join(data.groups)}; seeds "
        f"{meta['seeds']}; {meta['runs']} runs. {meta['budget']}",
        "",
        "Figures are means across seeds with 95% intervals: Student t for a mean (clipped to "
        "the quantity's range: no count, rate or length is below 0, no rate above 1), "
        "percentile "
        "bootstrap (scipy) for a ratio, stratified bootstrap for aggregates. *Greedy* is the "
        f"final policy taking its most probable actions over {meta['eval_episodes']:,} "
        "evaluation episodes; *steps, last 10%* the mean episode length over the last 10% of "
        "a run's environment steps (sampled actions, as in the paper's curves). References: "
        "the exact optimum (`python -m a2cm_phys.oracle`) on grids; in physics mode the grid "
        "oracle driven in physics (discrete control) or `pursuit` (continuous control), "
        "played greedy on the same episodes. Verdicts: *holds* when the test supports the "
        "claim at the 5% level (or its 95% interval lies on the claimed side), *does not "
        "hold* when it supports the opposite, else *inconclusive*; each names its sample sizes "
        "(*n*, seeds per side), and one seed a side decides nothing: *inconclusive (n = 1)*.",
        "",
        "## Claims",
        "",
        *claims_table(claims),
        "",
    ]
    for group in ("paper", "ours"):
        if group in data.groups:
            lines += experiment_tables(data, group, out, figures)
    lines += aggregate_section(data)
    if "continuous" in data.groups:
        lines += continuous_section(data, out, figures)
    for group in SELF_PLAY_GROUPS:
        if group in data.groups:
            lines += selfplay_section(data, out, figures, group)
    lines += crossplay_section(crossplay)
    lines += later_work_section(meta)
    lines += wall_section(data, missing, meta)
    return "\n".join(lines) + "\n"
