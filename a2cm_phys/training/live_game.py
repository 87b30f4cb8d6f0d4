"""One game of a training run shown live, whole episodes at a pace a person can watch.

Training steps far faster than anyone can watch (a grid run plays thousands of steps a
second), so the player shows whole episodes of one game, one after the other, each at
``period`` wall-clock seconds a state: it collects an episode of its game as it is played,
then shows its states as they fall due while training goes on; the episodes the game plays
meanwhile are dropped, and the next one shown is the first to start after the showing
ended. Nothing is queued beyond the one episode being shown (at most ``max_steps + 1``
states), and the player never waits: a frame is sent when a call finds it due, so a late
call shows the frame late, never a backlog.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from ..config import Scenario
from ..envs.vector import VecStep, VectorEnv
from ..record.runlog import Trajectory

_WAIT, _COLLECT, _SHOW = "wait", "collect", "show"
HOLD_FRAMES = 3
"""Periods the last state of a shown episode stays up before the next episode is sought."""


class GamePlayer:
    """Shows episodes of game ``game`` of ``scenario``'s vector env through ``publish(traj,
    k)`` (state ``k`` of episode ``traj``), a state every ``period`` seconds of
    ``clock()``; ``wanted()`` says whether anyone watches (else nothing is collected)."""

    def __init__(
        self,
        scenario: Scenario,
        game: int,
        period: float,
        publish: Callable[[Trajectory, int], None],
        wanted: Callable[[], bool],
        clock: Callable[[], float],
    ) -> None:
        self.scenario, self.game, self.period = scenario, game, period
        self._publish, self._wanted, self._clock = publish, wanted, clock
        self._state = _WAIT
        self._rows: dict[str, list[Any]] = {}
        self._traj: Trajectory | None = None
        self._k, self._due = 0, 0.0
        self.shown = 0  # episodes shown whole

    def begin(self, vec_env: VectorEnv) -> None:
        """Start with the env as it is: its game's episode is collected if it is at its start
        (a new run), else the next one is waited for (a resumed run)."""
        t = np.asarray(getattr(vec_env.core, "t", np.zeros(vec_env.num_envs)))
        if t[self.game] == 0 and self._wanted():
            self._collect(vec_env)

    def step(self, vec_env: VectorEnv, step: VecStep, first_id: int) -> None:
        """Take one vector step (``first_id``: the id of its first finished episode) and
        send a frame if one is due."""
        ended = None
        for j, e in enumerate(step.episodes):
            if e.env == self.game:
                ended = j
                break
        if self._state == _COLLECT:
            self._add(step)
            if ended is not None:
                self._show(first_id + ended, step)
        elif self._state == _WAIT and ended is not None and self._wanted():
            self._collect(vec_env)
        self.tick()

    def tick(self) -> None:
        """Send the shown episode's next state if it is due (none once nobody watches)."""
        if self._state != _SHOW or self._clock() < self._due:
            return
        traj = self._traj
        if self._k <= traj.length and self._wanted():
            self._publish(traj, self._k)
            self._k += 1
            self._due = self._clock() + self.period * (HOLD_FRAMES if self._k > traj.length else 1)
            return
        self._state, self._traj = _WAIT, None
        self.shown += 1

    def _collect(self, vec_env: VectorEnv) -> None:
        """Begin collecting the game's episode from its start state (the env as it is now)."""
        core, g = vec_env.core, self.game
        vel = core.velocities()
        self._rows = {
            "pos": [np.array(core.positions()[g])],
            "vel": None if vel is None else [np.array(vel[g])],
            "rew": [],
            "cap": [],
            "col": [],
            "events": [] if self.scenario.mode == "physics" else None,
        }
        self._state = _COLLECT

    def _add(self, step: VecStep) -> None:
        """Append the game's row of one step."""
        rows, g, out = self._rows, self.game, step.outcome
        rows["pos"].append(np.array(step.positions[g]))
        if rows["vel"] is not None:
            rows["vel"].append(np.array(step.velocities[g]))
        rows["rew"].append(float(out.reward[g]))
        rows["cap"].append(bool(out.captured[g]))
        rows["col"].append(int(out.collisions[g]))
        if rows["events"] is not None and out.events is not None:
            rows["events"] += [tuple(e) for e in out.events[g]]

    def _show(self, episode: int, step: VecStep) -> None:
        """The collected episode becomes the one shown, from its first state on."""
        rows = self._rows
        summary = next(e for e in step.episodes if e.env == self.game)
        n = len(rows["rew"])
        self._traj = Trajectory(
            episode=episode,
            env=self.game,
            seed=int(summary.seed),
            t0=0.0,
            dt=1.0,
            positions=np.array(rows["pos"]),
            actions=np.zeros((n, 0)),
            reward=np.array(rows["rew"], dtype=np.float64),
            captured=np.array(rows["cap"], dtype=bool),
            collisions=np.array(rows["col"], dtype=np.int64),
            wall_contacts=np.zeros(n, dtype=np.int64),
            velocities=None if rows["vel"] is None else np.array(rows["vel"]),
            events=rows["events"],
        )
        self._rows = {}
        self._state, self._k, self._due = _SHOW, 0, self._clock()
