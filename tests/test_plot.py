"""``python -m a2cm_phys.plot``: learning-curve PNGs from run logs alone."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from test_record import make_log

from a2cm_phys.plot import load_run, main, moving_average


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
    assert load_run(tmp_path / "a2c").label == "A2C"
    assert "wrote" in capsys.readouterr().out


def test_a_resumed_run_reads_its_logs_in_order(tmp_path: Path) -> None:
    make_log(tmp_path / "episodes.mcap", steps=60, seed=1)
    make_log(tmp_path / "episodes-from-0000010.mcap", steps=60, seed=2)
    run = load_run(tmp_path)
    first = load_run(tmp_path / "episodes.mcap")
    n = len(first.columns["length"])
    assert len(run.columns["length"]) > n
    np.testing.assert_array_equal(run.columns["length"][:n], first.columns["length"])


def test_moving_average() -> None:
    np.testing.assert_allclose(
        moving_average(np.array([1.0, 3.0, 5.0, 7.0]), 2), [1.0, 2.0, 4.0, 6.0]
    )


def test_missing_run_exits_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main([str(tmp_path / "nope")]) == 2
    assert "plot: error:" in capsys.readouterr().err
