"""Choose the simulation core for a scenario's mode, and the evader policy it plays."""

from __future__ import annotations

from ..config import Scenario
from .core import Core, EvaderPolicy


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


def make_evader(scenario: Scenario, num_envs: int, low: float, high: float) -> EvaderPolicy:
    """The scenario's evader for ``num_envs`` games whose evader centre stays in
    ``[low, high]²``: scripted discrete moves (:class:`~.evader.Evader`) or, with continuous
    control, velocity commands (:class:`~.evader_continuous.ContinuousEvader`); with
    ``evader = "learned"`` the agent's actions, given with each step
    (:class:`~.evader_learned.LearnedEvader`)."""
    if scenario.evader == "learned":
        from .evader_learned import LearnedEvader

        return LearnedEvader(scenario, num_envs)
    if scenario.continuous:
        from .evader_continuous import ContinuousEvader

        return ContinuousEvader(scenario, num_envs, low, high)
    from .evader import Evader

    return Evader(scenario, num_envs, low, high)
