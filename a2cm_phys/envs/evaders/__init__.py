"""The evader as a policy the core plays: scripted moves (:mod:`.scripted`), scripted
velocity commands (:mod:`.continuous`), or a learned agent's actions given with each step
(:mod:`.learned`). A core takes the policy :func:`make_evader` builds for its scenario."""

from __future__ import annotations

from ...config import Scenario
from ..core import EvaderPolicy

__all__ = ["make_evader"]


def make_evader(scenario: Scenario, num_envs: int, low: float, high: float) -> EvaderPolicy:
    """The scenario's evader for ``num_envs`` games whose evader centre stays in
    ``[low, high]²``: scripted discrete moves (:class:`~.scripted.Evader`) or, with continuous
    control, velocity commands (:class:`~.continuous.ContinuousEvader`); with
    ``evader = "learned"`` the agent's actions, given with each step
    (:class:`~.learned.LearnedEvader`)."""
    if scenario.evader == "learned":
        from .learned import LearnedEvader

        return LearnedEvader(scenario, num_envs)
    if scenario.continuous:
        from .continuous import ContinuousEvader

        return ContinuousEvader(scenario, num_envs, low, high)
    from .scripted import Evader

    return Evader(scenario, num_envs, low, high)
