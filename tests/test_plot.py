"""``python -m a2cm_phys.plot``: learning-curve PNGs from run logs alone."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from test_record import make_log
from test_replay import damage_a_chunk

from a2cm_phys.analysis.figures import moving_average
from a2cm_phys.analysis.run_series import load_logged_run, log_files
from a2cm_phys.commands.plot import main
from a2cm_phys.record import read_run
from a2cm_phys.record.parts import new_part


def test_plot_writes_png_figures_for_overlaid_runs(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    for algo in ("a2c", "a2cm"):
        make_log(
            tmp_path / algo / "episodes.mcap",
            steps=150,
            seed=len(algo),
            algo=algo,
            label=None,
            log_every=0,
        )
    out = tmp_path / "figs"
    assert (
        main([str(tmp_path / "a2c"), str(tmp_path / "a2cm"), "--out", str(out), "--window", "10"])
        == 0
    )
    names = {"returns.png", "lengths.png", "collisions.png", "overview.png"}
    assert {p.name for p in out.iterdir()} == names
    for name in names:
        with Image.open(out / name) as im:
            assert im.size[0] > 500 and im.size[1] > 300
            assert len(np.unique(np.asarray(im.convert("L")))) > 10  # something was drawn
    assert load_logged_run(tmp_path / "a2c").label == "A2C"
    assert "wrote" in capsys.readouterr().out


def test_a_runs_log_parts_are_read_in_session_order(tmp_path: Path) -> None:
    """Parts named by older versions (``episodes-from-UUUUUU[-K]``) come first, in their
    order; numbered ones follow by session, whatever update they resumed from (a session
    resumed from a previous checkpoint starts at an earlier update than the one before)."""
    names = ["episodes-from-000010-2.mcap", "episodes-from-000003.mcap", "episodes.mcap",
             "episodes-012-from-000004.mcap", "episodes-from-000010.mcap",
             "episodes-009-from-000020.mcap", "episodes-other.mcap"]  # fmt: skip
    for name in names:
        (tmp_path / name).touch()
    assert [p.name for p in log_files(tmp_path)] == [
        "episodes.mcap",
        "episodes-from-000003.mcap",
        "episodes-from-000010.mcap",
        "episodes-from-000010-2.mcap",
        "episodes-009-from-000020.mcap",
        "episodes-012-from-000004.mcap",
    ]
    assert new_part(tmp_path, 10) == (tmp_path / "episodes-013-from-000010.mcap", 13)
    assert new_part(tmp_path / "new", 0) == (tmp_path / "new" / "episodes.mcap", 0)


def test_an_empty_or_damaged_log_is_an_error_not_an_empty_figure(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    make_log(tmp_path / "empty" / "episodes.mcap", steps=1)  # no episode ends in one step
    assert main([str(tmp_path / "empty"), "--out", str(tmp_path / "figs")]) == 2
    assert "no finished episode" in capsys.readouterr().err
    path = tmp_path / "damaged" / "episodes.mcap"
    make_log(path, steps=400, flush_seconds=0)
    damage_a_chunk(path)
    assert main([str(path.parent), "--out", str(tmp_path / "figs")]) == 2
    assert "damaged" in capsys.readouterr().err
    assert not (tmp_path / "figs").exists() or not any((tmp_path / "figs").iterdir())


def test_out_pointing_at_a_file_is_an_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    make_log(tmp_path / "run" / "episodes.mcap", steps=60)
    (tmp_path / "file.png").write_text("not a folder")
    assert main([str(tmp_path / "run"), "--out", str(tmp_path / "file.png")]) == 2
    err = capsys.readouterr().err
    assert "--out" in err and "is a file" in err and err.count("\n") == 1


def test_moving_average() -> None:
    np.testing.assert_allclose(
        moving_average(np.array([1.0, 3.0, 5.0, 7.0]), 2), [1.0, 2.0, 4.0, 6.0]
    )


def test_missing_run_exits_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main([str(tmp_path / "nope")]) == 2
    assert "error:" in capsys.readouterr().err


def test_exploitability_is_drawn_from_sparse_update_metrics(tmp_path: Path) -> None:
    every = 5  # the trainer computes both best responses every K updates
    metrics = {
        u: {"exploit_worst_case": 9.5 - u / 4, "exploit_pursuers_br": 2.5 + u / 10}
        for u in range(0, 20, every)
    }
    metrics[10]["exploit_pursuers_br"] = float("nan")  # logged as null: skipped
    make_log(tmp_path / "sp" / "episodes.mcap", steps=160, metrics=metrics, log_every=0)
    make_log(tmp_path / "plain" / "episodes.mcap", steps=160, log_every=0)
    updates = read_run(tmp_path / "sp").updates
    assert [u["update"] for u in updates if "exploit_worst_case" in u] == [0, 5, 10, 15]
    assert updates[10]["exploit_pursuers_br"] is None
    run = load_logged_run(tmp_path / "sp")
    steps, values = run.exploit["exploit_worst_case"]
    assert steps.tolist() == [(u + 1) * 8 * 4 for u in (0, 5, 10, 15)]  # env steps, 4 games
    assert values.tolist() == [9.5, 8.25, 7.0, 5.75]
    assert run.exploit["exploit_pursuers_br"][1].tolist() == [2.5, 3.0, 4.0]
    assert load_logged_run(tmp_path / "plain").exploit == {}

    out = tmp_path / "figs"
    assert main([str(tmp_path / "sp"), str(tmp_path / "plain"), "--out", str(out)]) == 0
    with Image.open(out / "exploitability.png") as im:
        pixels = np.asarray(im.convert("RGB")).reshape(-1, 3)
        assert im.size[0] > 500
        # the first run's colour (matplotlib's blue) draws its curves
        assert np.sum(np.all(np.abs(pixels.astype(int) - (31, 119, 180)) < 8, axis=1)) > 200
    main([str(tmp_path / "plain"), "--out", str(tmp_path / "none")])
    assert not (tmp_path / "none" / "exploitability.png").exists()


def test_runs_grouped_by_label_are_plotted_as_seeds_against_env_steps(tmp_path: Path) -> None:
    from a2cm_phys.analysis.figures import binned, seed_band

    for algo in ("a2c", "a2cm"):
        for seed in (0, 1):
            make_log(tmp_path / f"{algo}{seed}" / "episodes.mcap", steps=120, seed=seed,
                     algo=algo, label=None, log_every=0)  # fmt: skip
    run = load_logged_run(tmp_path / "a2c0")
    steps, lengths, games = run.columns["env_steps"], run.columns["length"], 4
    assert steps.max() <= 120 * games and np.all(steps % games == 0)
    assert steps[0] == lengths[0] * games  # the first episode to end, in its game
    out = tmp_path / "figs"
    group = [f"--group=A2C={tmp_path / 'a2c0'},{tmp_path / 'a2c1'}",
             f"--group=A2CM={tmp_path / 'a2cm0'},{tmp_path / 'a2cm1'}"]  # fmt: skip
    assert main([*group, "--out", str(out)]) == 0
    for name in ("lengths_mean.png", "returns_mean.png", "collisions_mean.png"):
        with Image.open(out / name) as im:
            assert im.size[0] > 400 and len(np.unique(np.asarray(im.convert("L")))) > 10
    edges = np.array([0.0, 240.0, 480.0])
    per_bin = binned(run, "length", edges)
    first = steps <= 240
    assert per_bin[0] == pytest.approx(lengths[first].mean())
    mean, lo, hi = seed_band(np.array([[1.0, np.nan], [3.0, 5.0]]))
    assert mean.tolist() == [2.0, 5.0] and np.isnan(lo[1]) and lo[0] < 2.0 < hi[0]


def test_a_bad_group_is_a_one_line_error(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--group", "no-equals-sign"]) == 2
    err = capsys.readouterr().err
    assert "--group" in err and err.count("\n") == 1
    assert main([]) == 2


def test_exploitability_figure_shows_the_cached_game_value(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from matplotlib.figure import Figure

    from a2cm_phys.analysis.exploit_figure import draw_game_values
    from a2cm_phys.config import load_scenario
    from a2cm_phys.solve.cache import cached_value, load_or_solve_value

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    small = {"size": 3, "pursuers": 2, "max_steps": 50}
    metrics = {
        u: {"exploit_worst_case": 9.0 - u / 4, "exploit_pursuers_br": 1.0 + u / 5} for u in (0, 10)
    }
    make_log(tmp_path / "sp" / "episodes.mcap", "grid_vs", steps=160, metrics=metrics,
             log_every=0, overrides=small)  # fmt: skip
    assert main([str(tmp_path / "sp"), "--out", str(tmp_path / "before")]) == 0
    assert "--scenario grid_vs --game-value` solves it" in capsys.readouterr().out

    sc = load_logged_run(tmp_path / "sp").scenario
    value = load_or_solve_value(load_scenario("grid_vs", small))  # what the command caches
    assert not value.cached and cached_value(sc).cached
    assert main([str(tmp_path / "sp"), "--out", str(tmp_path / "after")]) == 0
    assert "not cached" not in capsys.readouterr().out
    ax = Figure().add_subplot()
    draw_game_values(ax, [sc, sc])  # one band a game
    (band,) = ax.patches
    low, high = band.get_path().get_extents(band.get_patch_transform()).intervaly
    assert (low, high) == pytest.approx((value.lower, value.upper))
    labels = ax.get_legend_handles_labels()[1]
    assert labels == [f"grid_vs: the game's value, {value.lower:.4g}–{value.upper:.4g}"]
