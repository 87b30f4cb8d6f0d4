"""Play pursuers against an evader and measure (the ``evaluate`` command prints it):
:func:`play` runs episodes of any two policies and returns every episode's outcome;
:func:`optimum` is the exact oracle's figures for a grid scenario, and
:func:`reference_of` the one reference every command, figure and the report compare
against (:func:`reference_policy`: the optimum on grids; the oracle driven in physics, or
``pursuit`` under continuous control). :func:`reference_report` is it as ``evaluate``
reports it.

Episodes played can be counted on a :class:`~a2cm_phys.base.progress.Progress` (stderr),
so that a long evaluation is never silent."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..analysis.policies import pursuer_policy
from ..analysis.stats import describe
from ..base.progress import Progress
from ..config import ConfigError, Scenario
from ..envs.vector import VectorEnv
from ..training.rollout import Policy, episodes_ended
from ..training.seeding import policy_rng

__all__ = [
    "REFERENCE_SEED",
    "EvalResult",
    "ReferenceResult",
    "optimum",
    "play",
    "reference_of",
    "reference_policy",
    "reference_report",
]


@dataclass
class EvalResult:
    """Per-episode outcomes of an evaluation, in the order (game, episode)."""

    lengths: np.ndarray
    returns: np.ndarray
    captured: np.ndarray
    truncated: np.ndarray
    collisions: np.ndarray

    def report(self, seed: int = 0) -> dict[str, Any]:
        """Point estimates with bootstrap 95% CIs (``{"value", "lo", "hi"}`` per statistic)."""
        return {
            "episodes": len(self.lengths),
            "length": describe(self.lengths, seed=seed),
            "capture_steps": describe(self.lengths[self.captured], seed=seed),
            "capture_rate": describe(self.captured, ("mean",), seed=seed)["mean"],
            "collisions_per_episode": describe(self.collisions, ("mean",), seed=seed)["mean"],
            "return": describe(self.returns, ("mean",), seed=seed)["mean"],
            "truncated": int(self.truncated.sum()),
        }


def play(
    scenario: Scenario,
    policy: Policy,
    episodes: int,
    num_envs: int = 16,
    seed: int = 0,
    evader: Policy | None = None,
    progress: Progress | None = None,
    status: str | None = None,
) -> EvalResult:
    """Play ``episodes`` episodes of ``policy`` in up to ``num_envs`` games, seeded; a
    learned evader's ``evader`` policy acts where the scenario's evader is learned.

    ``progress`` counts the episodes as they are kept and shows ``status`` beside the
    count (default: the mean length of the episodes so far)."""
    num_envs = max(1, min(num_envs, episodes))
    env = VectorEnv(scenario, num_envs)
    obs, rng = env.reset(seed), policy_rng(seed)
    quota = np.full(num_envs, episodes // num_envs)
    quota[: episodes % num_envs] += 1
    per_env: list[list] = [[] for _ in range(num_envs)]
    remaining, steps = episodes, 0
    if progress is not None and status is not None:
        progress.note(status)
    while remaining:
        actions = policy(obs, rng)
        if evader is None:
            step = env.step(actions, validate=False)
        else:
            step = env.step(actions, evader(obs, rng)[:, 0], validate=False)
        obs = step.obs
        if step.episodes:
            ended = step.terminated | step.truncated
            episodes_ended(policy, ended)
            if evader is not None:
                episodes_ended(evader, ended)
        kept = 0
        for ep in step.episodes:
            if len(per_env[ep.env]) < quota[ep.env]:
                per_env[ep.env].append(ep)
                kept, steps = kept + 1, steps + ep.length
        remaining -= kept
        if progress is not None:  # every step: a line is due by the clock, not by episodes
            if kept and status is None:
                progress.note(f"mean length {steps / (episodes - remaining):.1f}")
            progress.update(kept)
    env.close()
    eps = [ep for game in per_env for ep in game]
    return EvalResult(
        lengths=np.array([e.length for e in eps], dtype=np.int64),
        returns=np.array([e.ret for e in eps], dtype=np.float64),
        captured=np.array([e.captured for e in eps], dtype=bool),
        truncated=np.array([e.truncated for e in eps], dtype=bool),
        collisions=np.array([e.collisions for e in eps], dtype=np.int64),
    )


# ---------------------------------------------------------------------- references


def optimum(scenario: Scenario, progress: bool = False) -> dict[str, float] | None:
    """The exact optimum of a grid scenario over its start distribution (expected capture
    steps and return under the raw reward; with random starts every start enumerated), or
    ``None`` where the oracle does not solve it
    (``progress``: report a solve on stderr)."""
    if scenario.mode != "grid" or scenario.evader == "learned":
        return None
    from ..solve import TooLargeError, UnsupportedError
    from ..solve.cache import load_or_solve_optimum

    try:
        sol = load_or_solve_optimum(scenario, progress=progress)
    except (TooLargeError, UnsupportedError):
        return None
    return {"capture_steps": sol.start_steps, "return": sol.start_value}


REFERENCE_SEED = 10_000
"""Seed of a reference policy's episodes unless the caller gives one (apart from every
training seed)."""


def reference_policy(scenario: Scenario) -> str:
    """The name of a scenario's reference policy: ``oracle`` (on grids its exact optimum;
    in physics the grid oracle driven in the arena, discrete control) or ``pursuit``
    (continuous control)."""
    return "pursuit" if scenario.mode != "grid" and scenario.continuous else "oracle"


@dataclass(frozen=True)
class ReferenceResult:
    """What a scenario's reference policy achieves: its exact optimum (``optimum``), its
    episodes played (``played``), or why it cannot be had (``unavailable``)."""

    policy: str
    """The policy's name (``oracle``, ``pursuit``, …)."""
    optimum: dict[str, float] | None = None
    played: EvalResult | None = None
    unavailable: str | None = None

    @property
    def exact(self) -> bool:
        """Whether the figures are the exact optimum rather than played episodes."""
        return self.optimum is not None

    @property
    def label(self) -> str:
        """``optimum (exact oracle)``, ``NAME (played)``, or the name where unavailable."""
        if self.optimum is not None:
            return "optimum (exact oracle)"
        if self.played is not None:
            return f"{self.policy} (played)"
        return self.policy

    @property
    def length(self) -> float:
        """The mean episode length (the optimum's expected capture steps)."""
        if self.optimum is not None:
            return self.optimum["capture_steps"]
        return float(self.played.lengths.mean())

    @property
    def ret(self) -> float:
        """The mean return under the raw reward (the optimum's expected return)."""
        if self.optimum is not None:
            return self.optimum["return"]
        return float(self.played.returns.mean())


def reference_of(
    scenario: Scenario,
    name: str | None = None,
    episodes: int = 500,
    num_envs: int = 16,
    seed: int = REFERENCE_SEED,
    progress: bool = False,
) -> ReferenceResult | None:
    """The reference beside a result in ``scenario``: the pursuer policy ``name``
    (default: :func:`reference_policy`, and ``pursuit`` where the oracle cannot solve the
    arena; ``none``: no reference, ``None``). The oracle's on a grid is its exact optimum;
    any other is played for ``episodes`` episodes in up to ``num_envs`` games from
    ``seed``. Where the policy asked for cannot be had (an arena too large for the oracle;
    a grid whose evader is learned, which has no single optimum) the result says why in
    ``unavailable``. ``progress``: count the episodes played (and report a solve) on
    stderr."""
    chosen, name = name, name or reference_policy(scenario)
    if name == "none":
        return None
    if name == "oracle" and scenario.mode == "grid":
        best = optimum(scenario, progress)
        if best is not None:
            return ReferenceResult(name, optimum=best)
    if scenario.evader == "learned":  # no fixed evader to play against, nor to solve for
        return ReferenceResult(name, unavailable="no reference against a learned evader")
    try:
        policy = pursuer_policy(name, scenario, progress=progress)
    except ConfigError as err:  # e.g. an arena too large for the oracle
        if chosen is None and name != "pursuit":  # the default: the scripted team instead
            return reference_of(scenario, "pursuit", episodes, num_envs, seed, progress)
        return ReferenceResult(name, unavailable=str(err))
    with Progress(f"reference ({name})", episodes, "ep", enabled=progress) as bar:
        played = play(scenario, policy, episodes, num_envs, seed, progress=bar)
    return ReferenceResult(name, played=played)


def reference_report(
    scenario: Scenario,
    name: str,
    episodes: int,
    num_envs: int,
    seed: int,
    progress: bool = False,
) -> dict[str, Any] | None:
    """:func:`reference_of` as ``evaluate`` reports it: the exact optimum's figures, the
    played policy's statistics with their CIs, or why it is unavailable (``None`` for
    ``none``)."""
    ref = reference_of(scenario, name, episodes, num_envs, seed, progress)
    if ref is None:
        return None
    if ref.unavailable is not None:
        return {"policy": ref.policy, "unavailable": ref.unavailable}
    if ref.exact:
        return {"policy": ref.label, "exact": True, **ref.optimum}
    return {"policy": ref.label, "exact": False, **ref.played.report(seed)}
