"""Importing the package is light (issue 34): ``import a2cm_phys`` loads neither torch nor
gymnasium nor the simulators; its names load on first use, and the Gymnasium id is
registered whichever of the two packages is imported first."""

from __future__ import annotations

import subprocess
import sys

import pytest


def run(code: str) -> str:
    """stdout of ``code`` in a fresh interpreter (nothing imported before it)."""
    proc = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True
    )
    return proc.stdout.strip()


def test_importing_the_package_loads_no_heavy_library() -> None:
    out = run(
        "import sys, a2cm_phys\n"
        "heavy = ('torch', 'gymnasium', 'pymunk', 'numpy', 'a2cm_phys.envs')\n"
        "print(sorted(m for m in heavy if m in sys.modules))"
    )
    assert out == "[]"


@pytest.mark.parametrize("first", ["a2cm_phys", "gymnasium"])
def test_the_gym_id_is_registered_in_either_import_order(first: str) -> None:
    second = "gymnasium" if first == "a2cm_phys" else "a2cm_phys"
    out = run(
        f"import {first}, {second}\n"
        "import gymnasium, a2cm_phys\n"
        "env = gymnasium.make(a2cm_phys.GYM_ID, scenario='grid')\n"
        "print(env.reset(seed=0)[0].shape)"
    )
    assert out.startswith("(")


def test_the_package_names_load_on_first_use() -> None:
    out = run(
        "import a2cm_phys\n"
        "env = a2cm_phys.make_env('grid')\n"
        "print(type(env).__name__, a2cm_phys.Scenario.__name__, sorted(a2cm_phys.__all__)[0])"
    )
    assert out == "PursuitParallelEnv Scenario ConfigError"
    with pytest.raises(subprocess.CalledProcessError):
        run("import a2cm_phys; a2cm_phys.no_such_name")
