"""Exact solution of the grid game by dynamic programming over the joint state.

:mod:`.model` factorises one step of the game into per-pursuer tables and computes the
Bellman backup over all joint states and joint actions with numpy; :mod:`.dp` runs value
iteration on it (and, for the fleeing evader, finds the states from which capture cannot be
forced); :mod:`.evaluate` replays a fixed policy through the real rule
(:meth:`~a2cm_phys.envs.grid.GridRules.apply`) to evaluate it exactly. The command and the
cached, playable policy live in :mod:`a2cm_phys.oracle`.
"""

from __future__ import annotations

from .dp import DPResult, solve_dp
from .evaluate import PolicyChain, capture_distribution, evaluate_policy, policy_chain
from .model import GridModel, TooLargeError, UnsupportedError

__all__ = [
    "DPResult",
    "GridModel",
    "PolicyChain",
    "TooLargeError",
    "UnsupportedError",
    "capture_distribution",
    "evaluate_policy",
    "policy_chain",
    "solve_dp",
]
