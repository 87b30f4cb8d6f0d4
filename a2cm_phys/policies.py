"""Named pursuer policies, as rollout policies: what learned ones are measured against.

- ``random``: uniform actions (discrete), or uniform commands in the unit square (continuous).
- ``pursuit``: every pursuer heads straight for the evader (:mod:`a2cm_phys.baselines`).
- ``oracle``: the exact optimum of the grid game (:mod:`a2cm_phys.oracle`); in physics
  mode the grid oracle driven in the physics arena: each body's centre is mapped to the
  cell it lies in, and the oracle's move becomes the velocity command in that direction.

Each is a :data:`~a2cm_phys.rollout.Policy`: ``policy(obs (B, obs_dim), rng) -> actions``.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .baselines import pursuit_actions
from .config import ConfigError, Physics, Scenario
from .envs.core import ACTION_DELTAS
from .rollout import Policy

PURSUER_POLICIES = ("random", "pursuit", "oracle")
"""The names :func:`pursuer_policy` knows."""


def positions_from_obs(scenario: Scenario, obs: np.ndarray) -> np.ndarray:
    """Agent positions ``(B, N + 1, 2)`` from observations (SPEC §5): integer cells in
    grid mode, metres in physics mode."""
    obs = np.asarray(obs, dtype=np.float64)
    n = scenario.pursuers + 1
    xy = obs[:, : 2 * n].reshape(len(obs), n, 2)
    if scenario.mode == "grid":
        return np.rint(xy * (scenario.size - 1)).astype(np.int64)
    return xy * scenario.size


def random_policy(scenario: Scenario) -> Policy:
    """Uniformly random actions for every pursuer."""
    shape = (scenario.pursuers,)
    if scenario.continuous:
        return lambda obs, rng: rng.uniform(-1.0, 1.0, size=(len(obs), *shape, 2)).astype(
            np.float32
        )
    return lambda obs, rng: rng.integers(0, scenario.actions, size=(len(obs), *shape))


def pursuit_policy(scenario: Scenario) -> Policy:
    """Every pursuer straight at the evader, on its own (both control types)."""
    return lambda obs, rng: pursuit_actions(scenario, positions_from_obs(scenario, obs))


def grid_twin(scenario: Scenario) -> Scenario:
    """The grid game a physics scenario plays at the resolution of its cells."""
    if scenario.mode == "grid":
        return scenario
    return dataclasses.replace(scenario, mode="grid", control="discrete", physics=Physics())


def oracle_policy(scenario: Scenario) -> Policy:
    """The exact optimum of the (grid twin of the) scenario; see the module docstring.

    Raises :class:`~a2cm_phys.config.ConfigError` when the oracle cannot solve it.
    """
    from .oracle import OraclePolicy
    from .solve import TooLargeError, UnsupportedError

    try:
        oracle = OraclePolicy(grid_twin(scenario))
    except (TooLargeError, UnsupportedError) as err:
        raise ConfigError(f"oracle policy: {err}") from None
    if scenario.mode == "grid":
        return lambda obs, rng: oracle.act(obs)
    top = scenario.size - 1
    directions = ACTION_DELTAS.astype(np.float32)

    def act(obs: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        cells = np.clip(np.floor(positions_from_obs(scenario, obs)), 0, top).astype(np.int64)
        moves = oracle.solution.actions(cells)
        return directions[moves] if scenario.continuous else moves

    return act


def pursuer_policy(name: str, scenario: Scenario) -> Policy:
    """The named pursuer policy for ``scenario`` (one of :data:`PURSUER_POLICIES`)."""
    makers = {"random": random_policy, "pursuit": pursuit_policy, "oracle": oracle_policy}
    if name not in makers:
        raise ConfigError(f"unknown pursuer policy {name!r} (known: {', '.join(makers)})")
    return makers[name](scenario)
