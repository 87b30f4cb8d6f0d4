"""The named scenarios ship inside the package, so a wheel install has them (issue 15; CI's
.ci/wheel checks a real wheel from outside the repository)."""

from __future__ import annotations

from pathlib import Path

import tomllib

import a2cm_phys
from a2cm_phys.config import SCENARIO_DIR, scenario_names

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = Path(a2cm_phys.__file__).resolve().parent


def test_named_scenarios_are_package_data() -> None:
    assert PACKAGE in SCENARIO_DIR.resolve().parents
    data = tomllib.loads((ROOT / "pyproject.toml").read_text())
    globs = data["tool"]["setuptools"]["package-data"]["a2cm_phys"]
    shipped = {p for g in globs for p in PACKAGE.glob(g)}
    files = set(SCENARIO_DIR.glob("*.toml"))
    assert files and files <= shipped
    assert {"grid", "grid_collision", "phys"} <= set(scenario_names())


def test_the_top_level_scenarios_folder_is_the_packages() -> None:
    top = ROOT / "scenarios"
    assert top.is_dir() and top.resolve() == SCENARIO_DIR.resolve()
