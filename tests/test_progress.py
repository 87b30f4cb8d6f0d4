"""The shared progress reporter (issue 31): a bar of at most 80 columns on a terminal,
plain lines elsewhere (at the start, every interval, at the end), silence on request."""

from __future__ import annotations

import io

import pytest

from a2cm_phys.base.progress import BAR_COLUMNS, Progress, duration


class Terminal(io.StringIO):
    """A text stream that says it is a terminal."""

    def isatty(self) -> bool:
        return True


@pytest.fixture
def every_update(monkeypatch: pytest.MonkeyPatch) -> None:
    """Plain lines as often as the clock allows."""
    monkeypatch.setenv("A2CM_PROGRESS_SECONDS", "1e-9")


def test_plain_lines_say_what_is_done_the_rate_and_the_time_left(every_update) -> None:
    out = io.StringIO()
    with Progress("evaluate", 1000, "ep", file=out) as p:
        p.update(250)
        p.note("mean length 3.1")
        p.update(250)
    lines = out.getvalue().splitlines()
    assert lines[0] == "evaluate: started (1,000 ep)"
    assert lines[1].startswith("evaluate: 250/1,000 ep (25%), ")
    assert "ep/s" in lines[1] and "left" in lines[1]
    assert lines[2].endswith("mean length 3.1")
    assert lines[-1].startswith("evaluate: done, 500/1,000 ep (50%)")
    assert "left" not in lines[-1]


def test_an_upper_bound_says_at_most(every_update) -> None:
    out = io.StringIO()
    with Progress("best response", 100, "steps", file=out, upper_bound=True) as p:
        p.update(10)
    assert "at most ~" in out.getvalue().splitlines()[1]


def test_lines_wait_for_the_interval(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("A2CM_PROGRESS_SECONDS", "3600")
    out = io.StringIO()
    with Progress("solve", None, "sweeps", file=out) as p:
        assert not p.due()
        for _ in range(100):
            p.update()
    assert out.getvalue() == ""  # within the grace: a quick solve says nothing


def test_work_within_the_grace_reports_nothing(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("A2CM_PROGRESS_SECONDS", "30")
    out = io.StringIO()
    with Progress("draw", 7, "frames", file=out) as p:
        p.update(7)
    assert out.getvalue() == ""


@pytest.mark.parametrize("how", ["disabled", "environment"])
def test_silence_on_request(how: str, monkeypatch: pytest.MonkeyPatch, every_update) -> None:
    if how == "environment":
        monkeypatch.setenv("A2CM_PROGRESS", "0")
    out = io.StringIO()
    with Progress("x", 10, file=out, enabled=how != "disabled") as p:
        p.update(10)
    assert out.getvalue() == ""


def test_a_terminal_gets_a_bar_no_wider_than_80_columns() -> None:
    out = Terminal()
    with Progress("cross-play", 1_000_000, "ep", file=out) as p:
        p.note("pairing 3/6")
        p.update(123_456)
        p.bar.refresh()
    frames = [f for f in out.getvalue().replace("\r", "\n").splitlines() if f.strip()]
    assert frames and all(len(f) <= BAR_COLUMNS for f in frames)
    assert any("123456/1000000" in f.replace(",", "") for f in frames)


def test_duration_reads_at_a_glance() -> None:
    assert [duration(s) for s in (4.2, 185, 3725)] == ["4 s", "3 min 05 s", "1 h 02 min"]
