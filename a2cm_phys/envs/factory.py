"""Choose the simulation core for a scenario's mode (each core builds the evader it plays
with :func:`a2cm_phys.envs.evaders.make_evader`)."""

from __future__ import annotations

from ..config import Scenario
from .core import Core


def make_core(scenario: Scenario, num_envs: int, workers: int = 1) -> Core:
    """A core of ``num_envs`` games: grid (numpy) or physics (pymunk, optionally in
    ``workers`` processes)."""
    if scenario.mode == "grid":
        from .grid import GridCore

        return GridCore(scenario, num_envs)
    if workers > 1:
        from .workers import ProcessCore

        return ProcessCore(scenario, num_envs, workers)
    from .physics import PhysicsCore

    return PhysicsCore(scenario, num_envs)
