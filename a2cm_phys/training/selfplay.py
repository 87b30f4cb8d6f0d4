"""The self-play machinery a run's options ask for, built beside its teams: the pool of
past opponents (fictitious self-play, :mod:`.opponents`) and exploitability descent against
the exact best response (:mod:`.descent`). Neither: the teams play simultaneously."""

from __future__ import annotations

from ..algos import ActorCritic
from ..config import Scenario, Train
from .descent import ExploitabilityDescent
from .opponents import OpponentPool
from .teams import Team


def make_pool(cfg: Train, pursuers: ActorCritic, evader: Team | None) -> OpponentPool | None:
    """The pool of both teams' past snapshots when ``pool_every`` asks for one (it needs a
    learned evader); ``None``: every update is latest against latest."""
    if not cfg.pool_every or evader is None:
        return None
    return OpponentPool(pursuers, evader.model, cfg.pool_size, cfg.pool_latest, cfg.seed)


def make_descent(
    scenario: Scenario, cfg: Train, pursuers: ActorCritic, evader: Team | None
) -> ExploitabilityDescent | None:
    """Exploitability descent on the grid when ``descent_every`` asks for it; ``None``:
    the teams learn from their rollouts only."""
    if not cfg.descent_every:
        return None
    return ExploitabilityDescent(
        scenario, cfg, pursuers, cfg.seed, None if evader is None else evader.model
    )
