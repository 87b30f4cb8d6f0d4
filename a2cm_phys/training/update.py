"""The two halves of one update besides its bookkeeping (:meth:`.Trainer._one_update`):
the players the update's pairing puts on the field for the rollout, and the learner steps
of the teams that learn from it, with self-play's, descent's and exploitability's metrics."""

from __future__ import annotations

import numpy as np

from .exploitability import exploitability, solvable
from .opponents import PAIRING_CODES, Pairing
from .rollout import Policy
from .state import RunState

EvaderPlayer = tuple[Policy, dict[str, np.ndarray]]
"""A learned evader in a rollout: its policy and its batch (see :func:`.rollout.collect`)."""


def players(run: RunState, pairing: Pairing) -> tuple[Policy, EvaderPlayer | None]:
    """The pursuers' policy and the learned evader's, if any, for a rollout: the live
    models, or a past snapshot from the pool for the side ``pairing`` says. Each side's
    batch notes the memories its rollout starts from (recurrent actors)."""
    pool = run.pool
    run.pursuers.start_rollout()
    pursuers = run.pursuers.policy if pool is None else pool.player("pursuers", pairing).act
    if run.evader is None:
        return pursuers, None
    run.evader.start_rollout()
    evader = run.evader.policy if pool is None else pool.player("evader", pairing).act
    return pursuers, (evader, run.evader.batch)


def learn(run: RunState, pairing: Pairing, metrics: dict[str, float]) -> None:
    """The learner steps of the teams ``pairing`` lets learn (by descent instead, every
    ``descent_every`` updates, when the run descends), then the exploitability every
    ``exploit_every`` updates; each step's metrics go into ``metrics`` as they come."""
    cfg, evader, descent = run.cfg, run.evader, run.descent
    progress = run.update / cfg.updates
    if pairing.learns("pursuers") and descent is None:  # else: by descent, below
        metrics.update(run.learner.update(run.batch, progress))
    if evader is not None and pairing.learns("evader") and not run.evader_descends():
        evader_metrics = evader.learner.update(evader.batch, progress)
        metrics.update({f"evader_{k}": v for k, v in evader_metrics.items()})
    if run.pool is not None:  # who played: see a2cm_phys.training.opponents.PAIRING_CODES
        metrics["pool_pairing"] = PAIRING_CODES[pairing.kind]
        metrics["pool_snapshot_update"] = pairing.taken_at
    if descent is not None and (run.update + 1) % cfg.descent_every == 0:
        metrics.update(descent.step(progress))
    every = cfg.exploit_every
    if every and (run.update + 1) % every == 0 and solvable(run.scenario):
        assert evader is not None
        metrics.update(exploitability(run.scenario, run.model, evader.model))
