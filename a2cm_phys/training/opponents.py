"""Fictitious self-play: a bounded pool of each team's past actors to train against.

Simultaneous self-play (the default, ``Train.pool_every = 0``) trains the pursuers and a
learned evader on the same games, each against the other's latest policy. With
``pool_every = K > 0`` every K updates the actor weights of both teams are copied into a
pool (:class:`OpponentPool`), and each update draws its **pairing** before the rollout:

- with probability ``pool_latest``: latest against latest; both teams learn from the
  batch (exactly an update of simultaneous self-play);
- otherwise one side, chosen by a fair coin, is replaced by a snapshot of its past drawn
  uniformly from its pool, and only the other, live side learns: the snapshot's actions
  came from an old policy, so its team gets no on-policy data from that batch.

This is fictitious self-play in the sense of a PSRO-lite or of OpenAI Five's "latest
80% / past 20%": each team learns against a mixture of the opponent's current policy and
its recent history, so that it cannot win by exploiting the opponent's last quirk only.
Conditioned on a team learning, its opponent is the latest policy with probability
``2p / (1 + p)`` for ``p = pool_latest`` (0.67 for p = 0.5). Until the first snapshot
exists (``pool_every`` updates) every update is latest against latest.

The pool keeps the ``pool_size`` most recent snapshots of each team (first in, first
out): with the measured ``pool_every = 250`` and ``pool_size = 10`` it spans the last
2,500 updates, half of a default run, so early near-random snapshots drop out (a recency
window like the one of Bansal et al., 2018, "Emergent complexity via multi-agent
competition", who drew opponents from a recent fraction of the history). Snapshots are
copies of the actors' weights (critics are not needed to act); they play through a
separate model per team, so the live models are never touched.

The draws come from the pool's own generator, seeded from the run's seed
(:func:`~a2cm_phys.training.seeding.opponent_rng`, beside the actions'
:func:`~a2cm_phys.training.seeding.policy_rng`), and
:meth:`OpponentPool.state_dict` holds the snapshots and the generator, so ``--resume``
stays bit for bit.

Simultaneous self-play stays the default: on ``grid_vs`` (two seeds each, BENCHMARKS.md,
"Fictitious self-play (pool)") no pool setting lowered the pursuers' exact worst-case
capture time, ``pool_latest = 0.5`` weakened both teams in cross-play, and 0.8 helped
in one seed of two.
"""

from __future__ import annotations

import copy
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Literal

import torch

from ..algos import ActorCritic
from .seeding import opponent_rng

Side = Literal["pursuers", "evader"]
SIDES: tuple[Side, Side] = ("pursuers", "evader")

PairingKind = Literal["latest", "past_evader", "past_pursuers"]
"""``latest``: both teams live; ``past_evader``: the live pursuers against a past evader
(only the pursuers learn); ``past_pursuers``: the live evader against past pursuers."""

PAIRING_CODES: dict[str, int] = {"latest": 0, "past_evader": 1, "past_pursuers": 2}
"""The update metric ``pool_pairing`` of each pairing (``pool_snapshot_update`` is the
update at which the past side's snapshot was taken, -1 when both are latest)."""


def actor_weights(model: ActorCritic) -> dict[str, torch.Tensor]:
    """A copy of the weights ``model.act`` uses (actors and Gaussian log-std; no critics)."""
    return {
        k: v.detach().clone()
        for k, v in model.state_dict().items()
        if k.startswith("actor_") or k == "log_std"
    }


@dataclass(frozen=True)
class Pairing:
    """Who plays an update: ``kind`` and, for a past side, its snapshot's index in the
    pool (0 = oldest kept) and the update at which it was taken."""

    kind: PairingKind
    index: int = -1
    taken_at: int = -1

    def learns(self, side: Side) -> bool:
        """Whether ``side`` plays live (and so learns from the batch)."""
        return self.kind == "latest" or self.kind != f"past_{side}"


LATEST = Pairing("latest")


class OpponentPool:
    """The two teams' snapshots and the per-update draw of who plays whom.

    Args:
        pursuers, evader: the live models (snapshots are taken from them).
        size: snapshots kept per team (the oldest is dropped first).
        latest: probability that an update is latest against latest.
        seed: the run's seed (see :func:`opponent_rng`).
    """

    def __init__(
        self, pursuers: ActorCritic, evader: ActorCritic, size: int, latest: float, seed: int
    ) -> None:
        self.live: dict[Side, ActorCritic] = {"pursuers": pursuers, "evader": evader}
        self.size, self.latest = size, latest
        self.rng = opponent_rng(seed)
        self.snapshots: dict[Side, deque[tuple[int, dict[str, torch.Tensor]]]] = {
            side: deque(maxlen=size) for side in SIDES
        }
        self._players: dict[Side, ActorCritic] = {
            side: copy.deepcopy(model) for side, model in self.live.items()
        }
        self.counts: dict[PairingKind, int] = {"latest": 0, "past_evader": 0, "past_pursuers": 0}

    def __len__(self) -> int:
        return len(self.snapshots["pursuers"])

    def add(self, update: int) -> None:
        """Snapshot both live teams' actors, taken after ``update`` updates."""
        for side in SIDES:
            self.snapshots[side].append((update, actor_weights(self.live[side])))

    def draw(self) -> Pairing:
        """The pairing of the next update (one or two draws of the pool's generator, none
        while the pool is empty); counted in :attr:`counts`."""
        pairing = LATEST
        if len(self) and self.rng.random() >= self.latest:
            past: Side = "evader" if self.rng.random() < 0.5 else "pursuers"
            index = int(self.rng.integers(len(self)))
            pairing = Pairing(f"past_{past}", index, self.snapshots[past][index][0])  # type: ignore[arg-type]
        self.counts[pairing.kind] += 1
        return pairing

    def player(self, side: Side, pairing: Pairing) -> ActorCritic:
        """The model that plays ``side`` under ``pairing``: the live one, or a model holding
        the drawn snapshot's actors."""
        if pairing.learns(side):
            return self.live[side]
        model = self._players[side]
        model.load_state_dict(self.snapshots[side][pairing.index][1], strict=False)
        return model

    # ------------------------------------------------------------------ checkpoint
    def state_dict(self) -> dict[str, Any]:
        """Snapshots, generator and counts, for the run's checkpoint."""
        return {
            "snapshots": {
                side: [{"update": u, "weights": w} for u, w in self.snapshots[side]]
                for side in SIDES
            },
            "rng": self.rng.bit_generator.state,
            "counts": dict(self.counts),
        }

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        """Restore :meth:`state_dict` (snapshots beyond :attr:`size` keep the newest)."""
        for side in SIDES:
            self.snapshots[side].clear()
            for entry in state["snapshots"][side]:
                weights = {k: v.clone() for k, v in entry["weights"].items()}
                self.snapshots[side].append((int(entry["update"]), weights))
        self.rng.bit_generator.state = state["rng"]
        self.counts.update({k: int(v) for k, v in state["counts"].items()})

    def describe(self, pool_every: int) -> str:
        """One line for the summary: the settings and how often each pairing was played."""
        c = self.counts
        return (
            f"pool (every {pool_every}, size {self.size}, latest {self.latest:g}): "
            f"{c['latest']} latest, {c['past_evader']} vs past evader, "
            f"{c['past_pursuers']} vs past pursuers"
        )
