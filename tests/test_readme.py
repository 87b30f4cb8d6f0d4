"""Every command line of the README runs as written, shortened (issue 30): each
``python -m a2cm_phys.COMMAND …`` in its code, with the options its paragraph shows in
code beside it, is run through the command's own entry point with fewer updates, episodes
and seeds, its placeholders (``RUN``, ``NAME``, ``DIR``) filled, and must exit 0."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest

from a2cm_phys.commands import run

README = Path(__file__).resolve().parents[1] / "README.md"

COMMAND = re.compile(r"python -m a2cm_phys\.(\w+)((?: [^`#]*?)?)\s*(?:`|#|$)")
OPTIONS = re.compile(r"`(--[a-z][^`|…]*)`")


def readme_commands(text: str) -> list[list[str]]:
    """Every command of the README as an argv (the command's name first): each
    ``python -m a2cm_phys.NAME ARGS`` found in a code block or span, and, where a
    paragraph shows options in code after its command (``--verify``), the command with
    each of them added. Options with placeholders or alternatives (``--seed``,
    ``--algo a2c|a2cm``) are left to the guide."""
    out: list[list[str]] = []
    for line in text.splitlines():
        found = [[m.group(1), *shlex.split(m.group(2))] for m in COMMAND.finditer(line)]
        out += found
        if len(found) == 1:
            extra = [shlex.split(m.group(1)) for m in OPTIONS.finditer(line)]
            out += [found[0] + e for e in extra if e[-1] in FLAGS or not _placeholder(e)]
    unique = []
    for argv in out:
        if argv not in unique:
            unique.append(argv)
    return unique


FLAGS = {"--verify", "--greedy", "--dry-run"}
"""Options that take no value, run alone after their paragraph's command."""


def _placeholder(argv: list[str]) -> bool:
    """Whether an option shown in the README has a placeholder (``N``, ``KEY=VALUE``) or
    no value (a flag that is not in :data:`FLAGS`)."""
    return len(argv) < 2 or any(re.search(r"\b[A-Z]{1,}[0-9]*\b", a) for a in argv[1:])


def shorten(argv: list[str], run_dir: Path, tmp: Path) -> list[str]:
    """``argv`` with its placeholders filled and its work cut to seconds."""
    fill = {"RUN": str(run_dir), "RUN…": str(run_dir), "NAME": "grid", "DIR": str(tmp / "out")}
    argv = [fill.get(a, a.replace("/tmp/", f"{tmp}/")) for a in argv]
    name, rest = argv[0], argv[1:]
    if "--out" in rest and rest[rest.index("--out") + 1].startswith(("figs", "ep")):
        i = rest.index("--out") + 1
        rest[i] = str(tmp / rest[i])
    if name == "train":
        if "--updates" in rest:
            rest[rest.index("--updates") + 1] = "3"
        else:
            rest += ["--updates", "3"]
        if "--run-dir" not in rest:
            rest += ["--logdir", str(tmp / "logs")]
    elif name == "evaluate":
        rest += ["--episodes", "20"]
    elif name == "sweep":
        rest[rest.index("--seeds") + 1] = "0"
        rest += ["--sequential", "--logdir", str(tmp / "sweep"), "--set", "train.updates=2"]
    elif name == "experiments":
        rest += [] if "--dry-run" in rest else ["--dry-run"]
        rest += ["--estimate-updates", "1"]  # one timed update per cell type, not 20
        rest += ["--logdir", str(tmp / "report-runs"), "--out", str(tmp / "report")]
        if "--quote-in" in rest:  # documents of the temporary folder's own
            i = rest.index("--quote-in") + 1
            for document in rest[i].split(","):
                (tmp / document).write_text("<!-- results: optimum -->?<!-- /results -->\n")
    elif name == "replay" and "--export-foxglove" in rest and "--out" not in rest:
        rest += ["--episode", "1", "--out", str(tmp / "episode.mcap")]
    if "--live" in rest:  # any free port: the test may run beside a user's live view
        rest.insert(rest.index("--live") + 1, "0")
    if "--serve" in rest:  # a free port, and no client to wait for
        rest[rest.index("--serve") + 1 : rest.index("--serve") + 1] = ["0", "--wait", "0.1"]
        rest[rest.index("--speed") + 1] = "1000"
    return [name, *rest]


COMMANDS = readme_commands(README.read_text(encoding="utf-8"))


def test_the_readme_shows_every_command_and_its_main_job():
    names = {argv[0] for argv in COMMANDS}
    assert names == {
        "train",
        "evaluate",
        "replay",
        "plot",
        "oracle",
        "export",
        "sweep",
        "experiments",
    }
    assert ["train", "--scenario", "grid_collision"] in COMMANDS
    assert ["replay", "RUN", "--verify"] in COMMANDS


@pytest.fixture(scope="module")
def trained(tmp_path_factory) -> Path:
    """A short run of the main job, logged, for the commands that read one."""
    run_dir = tmp_path_factory.mktemp("readme") / "run"
    argv = ["train", "--scenario", "grid_collision", "--updates", "4", "--run-dir", str(run_dir)]
    assert run(argv) == 0
    return run_dir


@pytest.fixture(scope="module")
def cache(tmp_path_factory) -> Path:
    """One oracle cache for the module's commands (the oracle is solved once)."""
    return tmp_path_factory.mktemp("cache")


@pytest.mark.parametrize("argv", COMMANDS, ids=[" ".join(a) for a in COMMANDS])
def test_a_readme_command_runs_as_written(argv, trained, cache, tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("XDG_CACHE_HOME", str(cache))
    monkeypatch.chdir(tmp_path)
    short = shorten(list(argv), trained, tmp_path)
    assert run(short) == 0, capsys.readouterr().err
