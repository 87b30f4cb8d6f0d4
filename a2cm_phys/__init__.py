"""a2cm_phys: cooperative multi-agent pursuit–evasion on a grid and in pymunk physics,
with the A2C and A2CM trainers of Paczolay & Harmati (2021).

The data path: ``config`` (scenario) → ``envs`` (game cores and APIs) → ``rollout`` →
``algos`` (models, returns, learner) → ``record`` (MCAP logs) → ``replay`` / ``plot``.
"""

from __future__ import annotations

import gymnasium

from .base.versions import __version__
from .config import ConfigError, Scenario, load_scenario
from .envs.parallel import PursuitParallelEnv, make_env

GYM_ID = "a2cm_phys/Pursuit-v0"
"""Gymnasium id of the joint view (kwarg ``scenario``)."""

if GYM_ID not in gymnasium.registry:
    gymnasium.register(id=GYM_ID, entry_point="a2cm_phys.envs.gym:PursuitEnv")

__all__ = [
    "GYM_ID",
    "ConfigError",
    "PursuitParallelEnv",
    "Scenario",
    "__version__",
    "load_scenario",
    "make_env",
]
