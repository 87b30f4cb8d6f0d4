"""Episodes played to be looked at (``evaluate … --render gif|png``): :func:`play_episodes`
plays consecutive episodes of a :class:`~a2cm_phys.analysis.policies.Matchup` in one game
and keeps each as the :class:`~a2cm_phys.record.runlog.Trajectory` a run log would hold, so
that :mod:`.pictures` draws it as ``replay`` draws a logged one; :func:`picture_stem` is the
name its pictures get.

A trajectory is what the recorder keeps (:mod:`a2cm_phys.record.buffers`): the states
after every step before any auto-reset (row 0 the start), the actions as given to the env
(unclipped; the evader's as the core played them), the rewards, captures, collisions, wall
contacts, and in physics the velocities and the contact events. ``replay --verify``'s
re-simulation (:func:`a2cm_phys.record.verify.verify_trajectory`) reproduces it bit for bit.

The games are seeded as ``evaluate``'s: the episode seeds come from ``seed`` as a
:class:`~a2cm_phys.envs.vector.VectorEnv`'s do, and the policies sample from
:func:`~a2cm_phys.training.seeding.policy_rng`; so with greedy policies the first episode
played is the first one the evaluation played in its first game.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..base.progress import Progress
from ..deploy import ONNX_PREFIX, PRETRAINED_PREFIX
from ..envs.vector import VecStep, VectorEnv
from ..record.runlog import Trajectory
from ..record.schemas import step_seconds
from ..training.rollout import episodes_ended
from ..training.seeding import policy_rng
from .names import is_named
from .policies import Matchup


class _Episode:
    """The rows of the episode running in a one-game env, from its start state on."""

    def __init__(self, env: VectorEnv) -> None:
        core = env.core
        self.seed = int(env.episode_seeds()[0])
        self.positions = [core.positions()[0].copy()]
        velocities = core.velocities()
        self.velocities = None if velocities is None else [velocities[0].copy()]
        turning = env.scenario.differential
        self.headings = [core.headings()[0].copy()] if turning else None
        self.actions: list[np.ndarray] = []
        self.reward: list[float] = []
        self.captured: list[bool] = []
        self.collisions: list[int] = []
        self.walls: list[int] = []
        self.evader_reward: list[float] | None = [] if env.learned_evader else None
        self.events: list[tuple] | None = None if velocities is None else []  # physics

    def add(self, actions: np.ndarray, step: VecStep) -> None:
        """One step: the pursuers' ``actions`` given (one game's) and what it returned."""
        out = step.outcome
        self.actions.append(np.concatenate([np.asarray(actions[0]), out.evader_action[:1]]))
        self.positions.append(step.positions[0].copy())
        if self.velocities is not None:
            self.velocities.append(step.velocities[0].copy())
        if self.headings is not None:
            self.headings.append(step.headings[0].copy())
        self.reward.append(float(out.reward[0]))
        self.captured.append(bool(out.captured[0]))
        self.collisions.append(int(out.collisions[0]))
        self.walls.append(int(out.wall_contacts[0]))
        if self.evader_reward is not None:
            self.evader_reward.append(float(step.evader_reward[0]))
        if self.events is not None and out.events is not None:
            self.events += [tuple(e) for e in out.events[0]]

    def trajectory(self, episode: int, t0: float, dt: float, continuous: bool) -> Trajectory:
        """The episode as a run log holds it (id ``episode``, starting at ``t0`` s)."""
        kind = np.float64 if continuous else np.int64
        return Trajectory(
            episode=episode,
            env=0,
            seed=self.seed,
            t0=t0,
            dt=dt,
            positions=np.array(self.positions),
            actions=np.array(self.actions, dtype=kind),
            reward=np.array(self.reward, dtype=np.float64),
            captured=np.array(self.captured, dtype=bool),
            collisions=np.array(self.collisions, dtype=np.int64),
            wall_contacts=np.array(self.walls, dtype=np.int64),
            velocities=None if self.velocities is None else np.array(self.velocities),
            events=self.events,
            evader_reward=None
            if self.evader_reward is None
            else np.array(self.evader_reward, dtype=np.float64),
            headings=None if self.headings is None else np.array(self.headings),
        )


def play_episodes(
    game: Matchup, episodes: int, seed: int = 0, progress: bool = True
) -> list[Trajectory]:
    """Play ``episodes`` consecutive episodes of ``game`` in one game seeded by ``seed``
    (see the module docstring) and return them as trajectories, ids ``0 …``;
    ``progress`` counts them on stderr."""
    scenario = game.scenario
    env = VectorEnv(scenario, 1)
    obs, rng = env.reset(seed), policy_rng(seed)
    dt, clock = step_seconds(scenario), 0
    running = _Episode(env)
    played: list[Trajectory] = []
    try:
        with Progress("playing", episodes, "ep", enabled=progress) as bar:
            while len(played) < episodes:
                actions = game.pursuers(obs, rng)
                if game.evader is None:
                    step = env.step(actions, validate=False)
                else:
                    step = env.step(actions, game.evader(obs, rng)[:, 0], validate=False)
                running.add(actions, step)
                obs = step.obs
                if step.episodes:
                    ended = step.terminated | step.truncated
                    episodes_ended(game.pursuers, ended)
                    if game.evader is not None:
                        episodes_ended(game.evader, ended)
                    traj = running.trajectory(len(played), clock * dt, dt, scenario.continuous)
                    played.append(traj)
                    clock += traj.length
                    running = _Episode(env)
                    bar.update(1)
    finally:
        env.close()
    return played


def picture_stem(spec: str, scenario: str) -> str:
    """The name of the pictures of episodes that the pursuers ``spec`` play in scenario
    ``scenario`` (the files are ``STEM-epN.gif``): ``pretrained-NAME`` for
    ``pretrained:NAME``, ``onnx-FOLDER`` for ``onnx:DIR``, ``POLICY-SCENARIO`` for a named
    policy, and the run's folder name for a run directory or a file in one."""
    if spec.startswith(PRETRAINED_PREFIX):
        return "pretrained-" + spec.removeprefix(PRETRAINED_PREFIX)
    if spec.startswith(ONNX_PREFIX):
        return "onnx-" + Path(spec.removeprefix(ONNX_PREFIX)).resolve().name
    if is_named(spec, "pursuers"):
        return f"{spec}-{scenario}"
    path = Path(spec).resolve()
    return path.parent.name if path.is_file() else path.name
