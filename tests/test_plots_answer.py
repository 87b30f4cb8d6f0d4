"""Plots that answer their question (issue 31): single runs against environment steps, the
reference dashed where one exists (and why not where none does), the return split into its
time and collision parts, one y-scale rule stated on every axis, a collisions figure for
groups, and preset labels. Figures are inspected as matplotlib objects, not pixels."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from test_record import make_log

from a2cm_phys.analysis.curves import KINDS, runs_figure, smoothed
from a2cm_phys.analysis.figure_parts import Reference, reference_for
from a2cm_phys.analysis.figures import Panel, aggregate_figure
from a2cm_phys.analysis.run_series import Run, load_logged_run
from a2cm_phys.commands.plot import build_parser, main
from a2cm_phys.config import Train, load_scenario, preset
from a2cm_phys.training.rundir import write_config

REPO = Path(__file__).resolve().parents[1]


def _run(tmp_path: Path, name: str, scenario: str = "grid_collision", **kw: object) -> Run:
    make_log(tmp_path / name / "episodes.mcap", scenario, label=None, log_every=0, **kw)
    return load_logged_run(tmp_path / name)


def _dashed(ax: object) -> list[float]:
    """The levels of an axis's horizontal dashed lines."""
    return [float(line.get_ydata()[0]) for line in ax.lines if line.get_linestyle() == "--"]


def _legend(ax: object) -> list[str]:
    return [t.get_text() for t in ax.get_legend().get_texts()]


def test_single_run_curves_are_drawn_against_environment_steps(tmp_path: Path) -> None:
    run = _run(tmp_path, "run", envs=8, steps=200)
    fig = runs_figure([run], ["A2CM"], "lengths", window=10)
    (ax,) = fig.axes
    (curve,) = [line for line in ax.lines if line.get_label().startswith("A2CM")]
    x = np.asarray(curve.get_xdata())
    steps = np.sort(run.columns["env_steps"])
    np.testing.assert_array_equal(x, steps)  # the env steps at which the episodes ended
    assert x[-1] > 4 * len(steps)  # not episode numbers: 8 games, several steps an episode
    assert x[-1] <= 200 * 8 and "environment steps" in ax.get_xlabel()
    # the moving average follows the episodes in the order they ended
    _, y = smoothed(run, "length", 10)
    np.testing.assert_allclose(curve.get_ydata(), y)
    assert f"{len(steps):,} episodes, {int(steps[-1]):,} steps" in curve.get_label()


def test_the_optimum_is_a_dashed_line_on_grid_collision(tmp_path: Path) -> None:
    ref = reference_for(load_scenario("grid_collision"))  # the oracle's solve is cached
    assert ref.unavailable is None and ref.length == pytest.approx(2.939, abs=1e-3)
    assert ref.time == pytest.approx(ref.ret) and ref.collisions == 0.0
    run = _run(tmp_path, "run", steps=120)
    refs = {"grid_collision": ref}
    lengths = runs_figure([run], ["A2CM"], "lengths", 10, refs).axes[0]
    assert _dashed(lengths) == [pytest.approx(2.939, abs=1e-3)]
    assert "optimum (exact oracle): 2.939" in _legend(lengths)
    # the run's gap to the optimum, in steps and per cent
    assert any("steps (" in t and "%) from the reference" in t for t in _legend(lengths))
    time_ax, collision_ax = runs_figure([run], ["A2CM"], "returns", 10, refs).axes
    assert _dashed(time_ax) == [pytest.approx(-2939.3, abs=0.1)]
    assert _dashed(collision_ax) == [0.0]


@pytest.mark.parametrize("scenario", ["grid_vs", "phys_vs"])
def test_no_reference_line_where_none_exists_and_the_legend_says_why(
    tmp_path: Path, scenario: str
) -> None:
    ref = reference_for(load_scenario(scenario), episodes=20)
    assert ref.unavailable is not None and "learned evader" in ref.unavailable
    run = _run(tmp_path, "run", scenario, steps=60)
    for ax in runs_figure([run], ["A2CM"], "overview", 10, {scenario: ref}).axes:
        assert _dashed(ax) == []
        assert f"no reference line: {ref.unavailable}" in _legend(ax)
    no_play = reference_for(load_scenario("phys_collision"), episodes=0)
    assert no_play.unavailable and "0 episodes" in no_play.unavailable


def test_the_return_is_split_into_parts_that_sum_to_it(tmp_path: Path) -> None:
    run = _run(tmp_path, "run", steps=200)
    cols = run.columns
    assert cols["collisions"].any()  # random pursuers on a 5x5 grid collide
    np.testing.assert_allclose(cols["time"] + cols["collision_part"], cols["return"])
    np.testing.assert_allclose(cols["collision_part"], cols["collisions"] * -1.5e8)
    assert np.all(np.abs(cols["time"]) < 1e6)  # the time part is not drowned by the penalty
    time_ax, collision_ax = runs_figure([run], ["A2CM"], "returns", 10).axes
    assert "without the collision penalty" in time_ax.get_ylabel()
    assert "-1.5e+08 a collision" in collision_ax.get_title()
    plain = _run(tmp_path, "plain", "grid", steps=60)  # no penalty: the return drawn whole
    (ax,) = runs_figure([plain], ["A2CM"], "returns", 10).axes
    assert ax.get_ylabel().startswith("return (raw team reward)")


def test_one_y_scale_rule_stated_on_every_axis(tmp_path: Path) -> None:
    """Runs whose returns differ by seven orders of magnitude get the same scales."""
    big = _run(tmp_path, "big", steps=150)
    small = _run(tmp_path, "small", "grid", steps=150)
    assert big.columns["return"].min() < -1e7 and small.columns["return"].min() > -1e3
    scales = []
    for run in (big, small):
        for kind in KINDS:
            for ax in runs_figure([run], ["A2CM"], kind, 10).axes:
                scales.append((ax.get_ylabel().split(" (")[0], ax.get_yscale()))
                assert ax.get_ylabel().endswith(f"({ax.get_yscale()} scale)")
    assert {scale for _, scale in scales} == {"linear"}
    panels = [Panel("big", {"A2CM": [big]}), Panel("small", {"A2CM": [small]})]
    fig = aggregate_figure(panels, ["length", "time", "collision_part", "collisions"], "t")
    assert {ax.get_yscale() for ax in fig.axes} == {"linear"}
    ratio = Reference("optimum", 3.0, -3000.0)  # a ratio to the reference: log, always
    fig = aggregate_figure([Panel("big", {"A2CM": [big]}, ratio)], ["return"], "t")
    (ax,) = fig.axes
    assert ax.get_yscale() == "log" and ax.get_ylabel().endswith("(log scale)")


def test_groups_get_a_collisions_figure(tmp_path: Path) -> None:
    for algo in ("a2c", "a2cm"):
        for seed in (0, 1):
            make_log(tmp_path / f"{algo}{seed}" / "episodes.mcap", "grid_collision", steps=100,
                     seed=seed, algo=algo, label=None, log_every=0)  # fmt: skip
    out = tmp_path / "figs"
    group = [f"--group=A2C={tmp_path / 'a2c0'},{tmp_path / 'a2c1'}",
             f"--group=A2CM={tmp_path / 'a2cm0'},{tmp_path / 'a2cm1'}"]  # fmt: skip
    assert main([*group, "--out", str(out)]) == 0
    names = {"lengths_mean.png", "returns_mean.png", "collisions_mean.png"}
    assert names <= {p.name for p in out.iterdir()}
    runs = {a: [load_logged_run(tmp_path / f"{a}{s}") for s in (0, 1)] for a in ("a2c", "a2cm")}
    ref = reference_for(load_scenario("grid_collision"))
    fig = aggregate_figure([Panel("grid_collision", runs, ref)], ["collisions"], "c")
    (ax,) = fig.axes
    assert ax.get_ylabel() == "pursuer collisions per episode (linear scale)"
    assert {"a2c (2 seeds)", "a2cm (2 seeds)"} <= set(_legend(ax)) and _dashed(ax) == [0.0]
    means = [line for line in ax.lines if "seeds" in line.get_label()]
    assert all(np.all(np.asarray(m.get_ydata()) >= 0) for m in means) and len(means) == 2


def test_a_run_of_a_preset_is_labelled_with_it(tmp_path: Path) -> None:
    sc = load_scenario("grid_collision")
    for name, cfg, stored in (
        ("paper", Train(**preset("paper")), "paper"),
        ("ours", Train(), None),
        ("old_paper", Train(**preset("paper")), "drop"),  # written before "preset" was kept
    ):
        make_log(tmp_path / name / "episodes.mcap", "grid_collision", steps=40, label=None)
        write_config(tmp_path / name, sc, cfg, "test", None if stored == "drop" else stored)
        if stored == "drop":
            path = tmp_path / name / "config.json"
            config = json.loads(path.read_text())
            del config["preset"]
            path.write_text(json.dumps(config))
    labels = {n: load_logged_run(tmp_path / n).label for n in ("paper", "ours", "old_paper")}
    assert labels == {"paper": "A2CM (paper)", "ours": "A2CM", "old_paper": "A2CM (paper)"}


def test_help_is_fast_names_every_default_and_imports_no_torch() -> None:
    parser = build_parser()
    for action in parser._actions:
        if action.dest in ("help", "runs"):
            continue
        assert action.help, action.dest
        shown = parser.formatter_class("x")._get_help_string(action)
        assert "default" in shown, action.dest
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    cmd = [sys.executable, "-X", "importtime", "-m", "a2cm_phys.plot", "--help"]
    start = time.perf_counter()
    done = subprocess.run(cmd, capture_output=True, text=True, env=env, check=True)
    assert time.perf_counter() - start < 1.5  # < 1 s on an idle machine; slack for CI
    imported = {line.split("|")[-1].strip() for line in done.stderr.splitlines()}
    assert not {m for m in imported if m.split(".")[0] in ("torch", "matplotlib", "scipy")}
    assert "--raw" in done.stdout and "(default: 500)" in done.stdout
