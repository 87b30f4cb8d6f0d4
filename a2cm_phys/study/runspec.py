"""One run of a sweep: its scenario, algorithm, seed and shared options (:class:`RunSpec`),
the run directory it is written to, and the ``train`` command it equals."""

from __future__ import annotations

import shlex
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..config import Scenario, Train, load_scenario, load_train, resolve_train


@dataclass(frozen=True)
class RunSpec:
    """One training run of a sweep: scenario, algorithm, seed and shared options."""

    scenario: str
    algo: str
    seed: int
    train: dict[str, Any] = field(default_factory=dict)  # Train overrides shared by all runs
    overrides: dict[str, Any] = field(default_factory=dict)  # scenario overrides
    record: bool = True
    log_every: int = 1

    @property
    def name(self) -> str:
        """The run directory's name."""
        return f"{Path(self.scenario).stem}-{self.algo}-s{self.seed}"

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
        argv += [f"--set=train.{k}={v}" for k, v in self.train.items()]
        argv += [f"--set={k}={v}" for k, v in self.overrides.items()]
        return shlex.join(argv)
