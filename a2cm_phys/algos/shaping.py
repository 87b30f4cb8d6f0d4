"""Progress shaping: the team's progress towards a capture, added to the learner's reward.

At a fine control rate (continuous control, 0.1 s per step) the team reward is −1 on every
step until a capture: an untrained team that never reaches the evader sees no signal at
all, and one step's command changes the capture time by a fraction of a step. Shaping adds
to each step's reward the progress the step made, ``F = Φ(s') − Φ(s)``, with a potential of
two terms, each in units of steps (the distance an agent covers in one step at full speed:
one cell in grid mode, ``max_speed · dt`` in physics mode):

- **distance** (``Train.distance_shaping``): ``−coef · mean_i |p_i − e| / step``, the
  pursuers' mean distance to the evader, so ``coef = 1`` pays about +1 per step to a team
  closing in at full speed, the size of the step cost (VMAS's ``pos_shaping_factor``);
  with obstacles the distance around them (:func:`~a2cm_phys.envs.paths.around_obstacles`),
  so that no pursuer is paid for pressing against a wall between it and the evader;
- **cell area** (``Train.area_shaping``): ``−coef · A / (side · step)``, ``A`` the area of
  the evader's Voronoi cell in the arena (:mod:`.voronoi`: the region it reaches before any
  pursuer) and ``side`` the arena's side, so a pursuer that advances one step along a
  shared edge as long as the arena's side earns about ``coef / 2``.

Against an evader as fast as a pursuer the distance term says nothing: the evader runs as
fast as the team closes in, so the distance stays put until it is cornered, which a noisy
team never does (measured on ``phys_cont_flee``: the runs of 2,000,000 steps with the
distance term alone that learned nothing, 8 of 10 in the report and 8 of 9 on this
machine, sat at a mean distance of 3.9 m, ``BENCHMARKS.md``). The cell shrinks whenever a
pursuer that borders it advances, whatever the evader does, and shrinks fastest when the
team closes the evader's ways out together: cooperation is paid for step by step.

``s'`` is the state the step ended in (the episode's final observation where it ended).
This is the difference form, not the discounted form ``γ·Φ(s') − Φ(s)`` of Ng, Harada &
Russell (1999): with a negative potential that form also pays ``(1 − γ)·|Φ(s')|`` per step
for *being far away* (about +0.35 a step at 3.5 m), which a team that has not yet caught a
fast evader learns to collect by huddling in a corner (measured on ``phys_cont_flee`` with
the distance term; with the area term it caught the evader in 1.02–1.18× ``pursuit``'s
time, against 0.79–0.99× for the difference form). Over an episode the terms sum to
``Φ(s_T) − Φ(s_0)``: how much closer the team ended than it started, which at a capture
is nearly fixed.

A learned evader is shaped with the opposite sign (it gains by distance and room). The
shaping is what the learner sees only: logs and ``evaluate`` keep the raw rewards.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from ..config import Scenario
from ..envs.paths import around_obstacles
from .voronoi import cell_area


class ProgressShaping:
    """``F_t = Φ(s'_t) − Φ(s_t)`` over a time-major batch, ``Φ`` of distance and cell area.

    Args:
        scenario: the game (the observation layout, SPEC §5, and the step length).
        distance: the distance term's weight (≥ 0).
        area: the cell-area term's weight (≥ 0).
        sign: +1 for the pursuers (closing in pays), −1 for a learned evader.
    """

    def __init__(
        self, scenario: Scenario, distance: float = 1.0, area: float = 0.0, sign: float = 1.0
    ) -> None:
        self.n = scenario.pursuers
        self.scenario = scenario
        if scenario.mode == "grid":  # obs = cell / (size - 1); one cell per step
            self.metres, step = scenario.size - 1, 1.0
            self.low, self.high = -0.5, scenario.size - 0.5  # the cells' outer edges
        else:  # obs = metres / size; max_speed · dt metres per step
            self.metres, step = scenario.size, scenario.physics.max_speed * scenario.physics.dt
            self.low, self.high = 0.0, float(scenario.size)
        self.scale = sign * distance * self.metres / step  # per unit of observed distance
        self.area_scale = sign * area / (scenario.size * step)  # per square metre (cell)

    def potential(self, obs: np.ndarray) -> np.ndarray:
        """``Φ`` of observations ``(..., obs_dim)``, float64 of shape ``(...)``."""
        xy = np.asarray(obs, dtype=np.float64)[..., : 2 * (self.n + 1)]
        xy = xy.reshape(*xy.shape[:-1], self.n + 1, 2)
        if self.scenario.obstacles:
            dist = around_obstacles(self.scenario, xy * self.metres) / self.metres
        else:
            dist = np.linalg.norm(xy[..., : self.n, :] - xy[..., self.n : self.n + 1, :], axis=-1)
        phi = -self.scale * dist.mean(-1)
        if self.area_scale:
            where = xy * self.metres
            area = cell_area(where[..., self.n, :], where[..., : self.n, :], self.low, self.high)
            phi = phi - self.area_scale * area
        return phi

    def __call__(self, batch: Mapping[str, Any]) -> np.ndarray:
        """The shaping term ``(T, B)`` of a rollout batch (keys as the learner's)."""
        obs = np.asarray(batch["obs"])
        steps, games = obs.shape[:2]
        ended = np.asarray(batch["terminated"], dtype=bool) | np.asarray(
            batch["truncated"], dtype=bool
        )
        # One potential call over every state the batch needs (each row on its own): the
        # observations, the observation after the batch, and where an episode ended (the
        # next row is then a new episode's start) the state the step ended in.
        rows = np.concatenate(
            [
                obs.reshape(steps * games, -1),
                np.asarray(batch["next_obs"]),
                np.asarray(batch["final_obs"])[ended],
            ]
        )
        phi = self.potential(rows)
        before = phi[: steps * games].reshape(steps, games)
        after = np.empty_like(before)
        after[:-1] = before[1:]
        after[-1] = phi[steps * games : (steps + 1) * games]
        after[ended] = phi[(steps + 1) * games :]
        return after - before
