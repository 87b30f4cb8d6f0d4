"""One run of a sweep: its scenario, algorithm, seed and shared options (:class:`RunSpec`),
the name of the run directory a new run is written to, and the ``train`` command it
equals. (An existing run is found by its resolved configuration, whatever its name:
:func:`a2cm_phys.study.rundirs.find_run`.)"""

from __future__ import annotations

import shlex
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..config import Scenario, Train, load_scenario, load_train, resolve_train
from ..training.rundir import run_name


@dataclass(frozen=True)
class RunSpec:
    """One training run of a sweep: scenario, algorithm, seed and shared options;
    ``preset`` names the preset ``train`` holds the values of (it goes into the run's name
    and its ``config.json``)."""

    scenario: str
    algo: str
    seed: int
    train: dict[str, Any] = field(default_factory=dict)  # Train overrides shared by all runs
    overrides: dict[str, Any] = field(default_factory=dict)  # scenario overrides
    record: bool = True
    log_every: int = 1
    preset: str | None = None

    @property
    def name(self) -> str:
        """The name of a new run's directory: ``<scenario>-<algo>[-<preset>]-s<seed>``."""
        return run_name(Path(self.scenario).stem, self.algo, self.seed, self.preset)

    def resolve(self) -> tuple[Scenario, Train]:
        """The validated scenario and training config of this run."""
        scenario = load_scenario(self.scenario, self.overrides)
        cfg = load_train({**self.train, "algo": self.algo, "seed": self.seed})
        return scenario, resolve_train(scenario, cfg)

    def command(self, run_dir: Path) -> str:
        """The equivalent ``train`` command line (for the record)."""
        argv = [
            "python",
            "-m",
            "a2cm_phys.train",
            "--scenario",
            self.scenario,
            "--algo",
            self.algo,
            "--seed",
            str(self.seed),
            "--run-dir",
            str(run_dir),
        ]
        argv += ["--preset", self.preset] if self.preset else []
        argv += [f"--set=train.{k}={_value(v)}" for k, v in self.train.items()]
        argv += [f"--set={k}={_value(v)}" for k, v in self.overrides.items()]
        return shlex.join(argv)


def _value(value: Any) -> str:
    """A ``--set`` value as the command line writes it (TOML's ``true``, not ``True``)."""
    return str(value).lower() if isinstance(value, bool) else str(value)
