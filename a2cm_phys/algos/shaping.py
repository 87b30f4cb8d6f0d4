"""Progress shaping on the pursuers' distance to the evader (continuous control).

At a fine control rate (continuous control, 0.1 s per step) the team reward is −1 on every
step until a capture: an untrained team that never reaches the evader sees no signal at
all, and one step's command changes the capture time by a fraction of a step. Shaping adds
to each step's reward the team's progress towards the evader, ``F = Φ(s') − Φ(s)`` with
``Φ(s) = −coef · mean_i |p_i − e| / step_length`` (the pursuers' mean distance to the
evader in units of the distance an agent covers in one step at full speed: one cell in
grid mode, ``max_speed · dt`` in physics mode), so ``coef = 1`` pays about +1 per step to a
team closing in at full speed, the size of the step cost. ``s'`` is the state the step
ended in (the episode's final observation where it ended).

This is VMAS's shaping (``pos_shaping_factor · (previous distance − distance)``) rather
than the discounted form ``γ·Φ(s') − Φ(s)`` of Ng, Harada & Russell (1999): with a
negative potential that form also pays ``(1 − γ)·|Φ(s')|`` per step for *being far away*,
about +0.35 a step here, which a team that has not yet caught a fast evader learns to
collect by huddling in a corner (measured on ``phys_cont_flee``). Over an episode the
progress terms sum to ``Φ(s_T) − Φ(s_0)``: how much closer the team ended than it started,
which at a capture is fixed by the bodies' sizes up to the other pursuers' distances.

A learned evader is shaped with the opposite sign (it gains by distance). The shaping is
what the learner sees only: logs and ``evaluate`` keep the raw rewards.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from a2cm_phys.config import Scenario


class DistanceShaping:
    """``F_t = Φ(s'_t) − Φ(s_t)`` over a time-major batch.

    Args:
        scenario: the game (the observation layout, SPEC §5, and the step length).
        coef: the potential's weight (> 0).
        sign: +1 for the pursuers (closing in pays), −1 for a learned evader.
    """

    def __init__(self, scenario: Scenario, coef: float, sign: float = 1.0):
        self.n = scenario.pursuers
        if scenario.mode == "grid":  # obs = cell / (size - 1); one cell per step
            metres, step = scenario.size - 1, 1.0
        else:  # obs = metres / size; max_speed · dt metres per step
            metres, step = scenario.size, scenario.physics.max_speed * scenario.physics.dt
        self.scale = sign * coef * metres / step

    def potential(self, obs: np.ndarray) -> np.ndarray:
        """``Φ`` of observations ``(..., obs_dim)``, float64 of shape ``(...)``."""
        xy = np.asarray(obs, dtype=np.float64)[..., : 2 * (self.n + 1)]
        xy = xy.reshape(*xy.shape[:-1], self.n + 1, 2)
        dist = np.linalg.norm(xy[..., : self.n, :] - xy[..., self.n : self.n + 1, :], axis=-1)
        return -self.scale * dist.mean(-1)

    def __call__(self, batch: Mapping[str, Any]) -> np.ndarray:
        """The shaping term ``(T, B)`` of a rollout batch (keys as the learner's)."""
        obs = np.asarray(batch["obs"])
        ended = np.asarray(batch["terminated"], dtype=bool) | np.asarray(
            batch["truncated"], dtype=bool
        )
        after = np.concatenate([obs[1:], np.asarray(batch["next_obs"])[None]])
        # Where an episode ended the next row is a new episode's start: the state the
        # step ended in is the episode's final observation.
        after = np.where(ended[..., None], np.asarray(batch["final_obs"]), after)
        return self.potential(after) - self.potential(obs)
