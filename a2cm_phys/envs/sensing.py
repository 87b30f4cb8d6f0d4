"""What each agent senses (SPEC §6b): masks, per-agent observations and the team's input.

With ``sensing.radius`` set, every agent (the ``N`` pursuers, then the evader) gets an
observation of its own, built from the global state vector (SPEC §5) and the positions:

- its own ``k`` features: ``x, y`` (grid: cell / ``(size − 1)``), or in physics
  ``x, y, vx, vy`` (metres / ``size``, then m/s / ``max_speed``), scaled as in the state,
  and with differential drive ``cos θ, sin θ`` (a pursuer's heading; the evader's are 0);
- then, for each other body in a fixed order (a pursuer: the other pursuers in index order,
  then the evader; the evader: the pursuers in index order), a mask bit (1.0 when sensed)
  and that body's ``k`` features, all ``+0.0`` when not sensed (never the true value);
- then, with ``sensing.rays = R`` (physics), its range sensor: ``R`` distances to the first
  shape along evenly spaced rays from its heading, as fractions of ``sensing.range``
  (:mod:`.rays`).

``Scenario.obs_dim = k + N (1 + k)``. A body is sensed when its distance is at most the
radius (grid: Chebyshev in cells; physics: metres between centres). With ``share`` the
pursuers pool their sightings: each knows all teammates and the evader when any pursuer
senses it. The evader senses alone.

The trainer's input (:func:`team_observation`) is one flat vector per game: the global state
first (so readers of the state's layout, such as progress shaping, read its prefix), then
the ``N + 1`` agents' observations in order. Each actor reads only its own agent's slice.
"""

from __future__ import annotations

import numpy as np

from ..config import Scenario
from .rays import cast_rays, ray_angles, visible


def features(scenario: Scenario) -> int:
    """Features ``k`` of one body: 2 (x, y) on grids, 4 (x, y, vx, vy) in physics, 6 with
    differential drive (:attr:`~a2cm_phys.config.Scenario.body_features`)."""
    return scenario.body_features


def team_dim(scenario: Scenario) -> int:
    """Length of the trainer's input per game: the state's with sensing off; with sensing
    on the state, then the ``N + 1`` agents' observations."""
    if not scenario.sensing.on:
        return scenario.state_dim
    return scenario.state_dim + (scenario.pursuers + 1) * scenario.obs_dim


def sensed(scenario: Scenario, positions: np.ndarray) -> np.ndarray:
    """Masks ``(B, N + 1, N + 1)`` bool: ``[b, i, j]`` whether agent ``i`` (pursuers, then the
    evader) knows body ``j`` in game ``b``, from positions ``(B, N + 1, 2)`` (cells or metres).
    Every agent knows itself. With ``sensing.occlusion`` a body behind an obstacle (the
    segment between the centres crossing one) is not sensed."""
    xy = np.asarray(positions, dtype=np.float64)
    delta = np.abs(xy[:, :, None, :] - xy[:, None, :, :])
    grid = scenario.mode == "grid"
    dist = delta.max(-1) if grid else np.sqrt((delta * delta).sum(-1))  # Chebyshev, metres
    seen = dist <= float(scenario.sensing.radius)
    if scenario.sensing.occlusion and scenario.obstacles:  # an obstacle in the way hides
        seen &= visible(xy, scenario.obstacles)
    n = scenario.pursuers
    if scenario.sensing.share:
        team = seen[:, :n].any(1)  # (B, N + 1): anything any pursuer senses
        seen[:, :n] = team[:, None, :]
        seen[:, :n, :n] = True  # teammates report their own positions over the radio
    return seen


def _bodies(scenario: Scenario, state: np.ndarray) -> np.ndarray:
    """The state vectors ``(B, state_dim)`` as features ``(B, N + 1, k)``."""
    count = scenario.pursuers + 1
    if scenario.mode == "grid":
        return state.reshape(len(state), count, 2)
    pos = state[:, : 2 * count].reshape(len(state), count, 2)
    vel = state[:, 2 * count : 4 * count].reshape(len(state), count, 2)
    parts = [pos, vel]
    if scenario.differential:  # the pursuers' headings, the evader's zeros
        headings = np.zeros_like(pos)
        headings[:, :-1] = state[:, 4 * count :].reshape(len(state), count - 1, 2)
        parts.append(headings)
    return np.concatenate(parts, axis=-1)


def _others(count: int) -> np.ndarray:
    """``(count, count − 1)``: the other bodies of each agent, in index order."""
    return np.array([[j for j in range(count) if j != i] for i in range(count)], dtype=np.intp)


def agent_observations(scenario: Scenario, state: np.ndarray, positions: np.ndarray) -> np.ndarray:
    """Every agent's own observation ``(B, N + 1, obs_dim)`` float32 (see the module
    docstring) from global states ``(B, state_dim)`` and positions ``(B, N + 1, 2)``."""
    body = _bodies(scenario, np.asarray(state, dtype=np.float32))
    b, count, _ = body.shape
    others = _others(count)
    mask = np.take_along_axis(sensed(scenario, positions), others[None], axis=2)  # (B, C, N)
    seen = body[:, others]  # (B, C, N, k)
    seen = np.where(mask[..., None], seen, np.float32(0.0))
    rows = np.concatenate([mask[..., None].astype(np.float32), seen], axis=-1)
    parts = [body, rows.reshape(b, count, -1)]
    if scenario.sensing.rays:
        parts.append(range_readings(scenario, body, positions))
    return np.concatenate(parts, axis=-1)


def range_readings(scenario: Scenario, body: np.ndarray, positions: np.ndarray) -> np.ndarray:
    """Every agent's range sensor (``sensing.rays``) as fractions of ``sensing.range``,
    ``(B, N + 1, rays)`` float32, from the bodies' features ``(B, N + 1, k)`` (headings with
    differential drive) and positions ``(B, N + 1, 2)`` metres (:func:`~.rays.cast_rays`)."""
    n = scenario.pursuers
    headings = None
    if scenario.differential:
        headings = np.arctan2(body[:, :n, 5].astype(np.float64), body[:, :n, 4])
    return (_reach(scenario, positions, headings) / scenario.sensing.range).astype(np.float32)


def _reach(scenario: Scenario, positions: np.ndarray, headings: np.ndarray | None) -> np.ndarray:
    """:func:`~.rays.cast_rays` in the scenario's arena: readings ``(B, N + 1, rays)`` m
    from positions ``(B, N + 1, 2)`` and the pursuers' angles ``(B, N)`` (or ``None``)."""
    ph, sensing = scenario.physics, scenario.sensing
    return cast_rays(
        positions,
        headings,
        sensing.rays,
        sensing.range,
        scenario.size,
        ph.box_side,
        ph.evader_radius,
        scenario.obstacles,
    )


def ray_segments(
    scenario: Scenario, positions: np.ndarray, headings: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Where each pursuer's rays start and stop in one state, for drawing: ``(starts, ends)``
    ``(N, rays, 2)`` metres, from the centres ``positions`` ``(N + 1, 2)`` (metres) and the
    pursuers' ``headings`` ``(N, 2)`` ``(cos θ, sin θ)`` (differential drive; ``None``:
    holonomic)."""
    n = scenario.pursuers
    xy = np.asarray(positions, dtype=np.float64)
    angle = None
    if headings is not None:
        angle = np.arctan2(np.asarray(headings, dtype=np.float64)[:, 1], headings[:, 0])
    reach = _reach(scenario, xy[None], None if angle is None else angle[None])[0, :n]
    world = ray_angles(scenario.sensing.rays, angle, (n,))
    starts = np.broadcast_to(xy[:n, None, :], (*world.shape, 2))
    ends = starts + reach[..., None] * np.stack([np.cos(world), np.sin(world)], -1)
    return starts, ends


def team_observation(scenario: Scenario, state: np.ndarray, positions: np.ndarray) -> np.ndarray:
    """The trainer's input ``(B, team_dim)`` float32: ``state`` itself with sensing off;
    otherwise the state, then every agent's observation (:func:`agent_observations`)."""
    if not scenario.sensing.on:
        return state
    agents = agent_observations(scenario, state, positions)
    return np.concatenate([state, agents.reshape(len(state), -1)], axis=-1)


def agent_slice(scenario: Scenario, agent: int) -> slice:
    """Where agent ``agent``'s observation lies in a team vector (sensing on)."""
    start = scenario.state_dim + agent * scenario.obs_dim
    return slice(start, start + scenario.obs_dim)
