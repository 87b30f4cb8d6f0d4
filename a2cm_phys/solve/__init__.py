"""Exact solution of the grid game by dynamic programming over the joint state.

:mod:`.model` factorises one step of the game into per-pursuer tables
(:mod:`.transitions`) and computes the Bellman backup over all joint states and joint
actions with numpy (:mod:`.backup`); :mod:`.dp` runs value iteration on it (and, for
evaders that might escape, finds the states from which capture cannot be forced);
:mod:`.policy_chain` replays a fixed policy through the real rule
(:meth:`~a2cm_phys.envs.grid.GridRules.apply`) to evaluate it exactly. Arenas too large
for that (7x7 and up, 3 pursuers) are solved against the random or static evader over one
state per orbit of the game's symmetries (:mod:`.symmetry`; :mod:`.symmetric` over
:mod:`.symmetric_sweep`). The solutions' cache is :mod:`.cache`
(:func:`~.cache.load_or_solve_optimum` picks the solver); the command,
:mod:`a2cm_phys.commands.oracle`.

Exploitability: :mod:`.tables` defines the policy tables over joint states both teams'
fixed policies are given as; :mod:`.best_response` solves the evader's best response to a
pursuer table (finite-horizon backward induction, one step by :mod:`.pursuer_step` and
:mod:`.sparse_step`) and the pursuers' best response to an evader table (the oracle
against it); :mod:`a2cm_phys.analysis.sources` builds tables from names (``random``,
``oracle``, ``flee``, ...) and run directories. :mod:`.worst_case` differentiates both
teams' worst cases (exploitability descent).
The game's value, both teams at their best: :mod:`.minimax` brackets it by the two games of
perfect information, :mod:`.nash` computes it with mixed strategies (Shapley's recursion)
and brackets it by an equilibrium evader's and team's exact worst cases.
"""

from __future__ import annotations

from .best_response import (
    BestResponse,
    Outcome,
    evader_best_response,
    evaluate_tables,
    pursuers_best_response,
)
from .dp import DPResult, solve_dp
from .model import GridModel
from .policy_chain import (
    PolicyChain,
    capture_distribution,
    evaluate_policy,
    policy_chain,
    state_visits,
)
from .tables import (
    TablePolicy,
    joint_observations,
    joint_policy_table,
    model_table,
    scripted_evader_table,
    uniform_table,
)
from .transitions import TooLargeError, UnsupportedError

__all__ = [
    "BestResponse",
    "DPResult",
    "GridModel",
    "Outcome",
    "PolicyChain",
    "TablePolicy",
    "TooLargeError",
    "UnsupportedError",
    "capture_distribution",
    "evader_best_response",
    "evaluate_policy",
    "evaluate_tables",
    "joint_observations",
    "joint_policy_table",
    "model_table",
    "policy_chain",
    "pursuers_best_response",
    "scripted_evader_table",
    "solve_dp",
    "state_visits",
    "uniform_table",
]
