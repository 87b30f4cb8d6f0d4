"""Exact evaluation of a fixed joint policy, replayed through the real grid rule.

:func:`policy_chain` applies :meth:`~a2cm_phys.envs.grid.GridRules.apply` to every state
and every evader move under the policy, giving the Markov chain the policy induces; it is
independent of the factorised backup of :mod:`.model`, so evaluating the greedy policy on
it cross-checks the value iteration. :func:`propagate` pushes the state distribution from
a start state through the chain: :func:`capture_distribution` turns it into the exact law
of the episode length, :func:`state_visits` into each state's expected visits.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .model import GridModel


@dataclass
class PolicyChain:
    """The Markov chain of one joint policy (arrays over states ``S`` and evader moves).

    ``cont[s, b]`` is the probability that the evader makes move ``b`` and the episode
    goes on, into state ``next[s, b]``; ``p_capture[s]`` and ``p_collision_end[s]`` the
    probabilities that the step ends it by capture or (``terminate`` mode, no capture) by a
    collision; ``reward[s]`` the expected raw reward of the step and ``collisions[s]`` its
    expected number of colliding pursuer pairs.
    """

    next: np.ndarray
    cont: np.ndarray
    p_capture: np.ndarray
    p_collision_end: np.ndarray
    reward: np.ndarray
    collisions: np.ndarray


def policy_chain(model: GridModel, policy: np.ndarray) -> PolicyChain:
    """The chain of the joint ``policy`` (``(S,)`` joint action indices) on ``model``."""
    sc, s = model.scenario, model.n_states
    cells = model.decode(np.arange(s))
    actions = model.joint_to_actions(policy)
    nb = model.n_moves
    nxt = np.zeros((s, nb), dtype=np.int64)
    cont = np.zeros((s, nb))
    p_capture, p_coll, reward, pairs = np.zeros(s), np.zeros(s), np.zeros(s), np.zeros(s)
    for b, move in enumerate(model.evader_moves):
        w = 1.0 / nb if model.weights is None else model.weights[:, b]
        new, captured, collisions, walls = model.rules.apply(
            cells.copy(), actions, np.full(s, move, dtype=np.int64)
        )
        ended_by_collision = model.terminate & (collisions > 0) & ~captured
        nxt[:, b] = model.encode(new)
        cont[:, b] = w * ~(captured | ended_by_collision)
        p_capture += w * captured
        p_coll += w * ended_by_collision
        r = sc.rewards.step + model.collision_reward * collisions + sc.rewards.capture * captured
        reward += w * (r + sc.rewards.wall * walls)
        pairs += w * collisions
    return PolicyChain(nxt, cont, p_capture, p_coll, reward, pairs)


def evaluate_policy(
    chain: PolicyChain,
    cost: np.ndarray,
    skip: np.ndarray | None = None,
    tol: float = 1e-11,
    max_iter: int = 1_000_000,
) -> np.ndarray:
    """Expected total of per-step ``cost`` (``(S,)``) until termination, for every state.

    Iterative policy evaluation to a sup-norm change below ``tol`` (relative to the largest
    ``|cost|``). States in ``skip`` (from which the policy need not terminate) get ``nan``.
    Raises ``RuntimeError`` if the policy does not terminate from some other state.
    """
    j = np.zeros(len(cost))
    tol = tol * max(1.0, float(np.max(np.abs(cost))))
    keep = slice(None) if skip is None else ~skip
    for _ in range(max_iter):
        new = cost + np.einsum("sb,sb->s", chain.cont, j[chain.next])
        if skip is not None:
            new[skip] = 0.0
        change = float(np.max(np.abs(new[keep] - j[keep]), initial=0.0))
        j = new
        if change < tol:
            break
    else:
        raise RuntimeError("policy evaluation did not converge: the policy does not terminate")
    if skip is not None:
        j[skip] = np.nan
    return j


@dataclass
class CaptureDistribution:
    """Exact law of the episode's end from one start state under one policy.

    ``capture[k - 1]`` and ``collision[k - 1]`` are the probabilities that the episode ends
    at step ``k`` by capture or by a collision (``terminate`` mode); ``truncated`` the
    probability that it is still running after ``max_steps`` steps (or that the remaining
    mass fell below the propagation's threshold first).
    """

    capture: np.ndarray
    collision: np.ndarray
    truncated: float

    @property
    def p_capture(self) -> float:
        """Probability that the episode ends by capture."""
        return float(self.capture.sum())

    def mean_length(self) -> float:
        """Expected episode length in steps (truncated episodes count their length)."""
        k = np.arange(1, len(self.capture) + 1)
        return float(k @ (self.capture + self.collision) + len(k) * self.truncated)

    def cdf(self, k: int) -> float:
        """``P(capture within k steps)``."""
        return float(self.capture[: max(k, 0)].sum())

    def quantile(self, q: float) -> float:
        """Smallest ``k`` with ``P(capture within k steps) >= q`` (``inf`` if never)."""
        hit = np.flatnonzero(np.cumsum(self.capture) >= q - 1e-12)
        return float(hit[0] + 1) if len(hit) else float("inf")


StartLaw = int | tuple[np.ndarray, np.ndarray]
"""Where a propagation starts: one state index, or states and their probabilities
(:func:`~.tables.start_law`)."""


def propagate(
    chain: PolicyChain,
    start: StartLaw,
    max_steps: int,
    visit: Callable[[np.ndarray, np.ndarray], None],
    eps: float = 1e-15,
) -> float:
    """Push the state distribution from ``start`` (a state, or a law over states) through
    ``chain``, step by step.

    ``visit(states, mass)`` sees each step's distribution before the step is taken (unique
    state indices and their probabilities), for up to ``max_steps`` steps or until less than
    ``eps`` of the mass is still running. Returns the mass still running at the end.
    """
    if isinstance(start, tuple):
        idx, inverse = np.unique(np.asarray(start[0]), return_inverse=True)
        mass = np.bincount(inverse, weights=np.asarray(start[1]), minlength=len(idx))
    else:
        idx, mass = np.array([start]), np.array([1.0])
    for _ in range(max_steps):
        visit(idx, mass)
        flow = (mass[:, None] * chain.cont[idx]).ravel()
        target = chain.next[idx].ravel()
        live = flow > 0
        idx, inverse = np.unique(target[live], return_inverse=True)
        mass = np.bincount(inverse, weights=flow[live], minlength=len(idx))
        if mass.sum() < eps:
            break
    return float(mass.sum())


def capture_distribution(
    chain: PolicyChain, start: StartLaw, max_steps: int, eps: float = 1e-15
) -> CaptureDistribution:
    """The law of the episode's end from ``start``, a state or a law (:func:`propagate`)."""
    capture, collision = [], []

    def visit(idx: np.ndarray, mass: np.ndarray) -> None:
        capture.append(float(mass @ chain.p_capture[idx]))
        collision.append(float(mass @ chain.p_collision_end[idx]))

    left = propagate(chain, start, max_steps, visit, eps)
    return CaptureDistribution(np.array(capture), np.array(collision), left)


def state_visits(chain: PolicyChain, start: StartLaw, max_steps: int) -> np.ndarray:
    """Expected visits ``(S,)`` of every state within ``max_steps`` steps from ``start``
    (they sum to the expected episode length, truncated at ``max_steps``)."""
    visits = np.zeros(len(chain.next))

    def visit(idx: np.ndarray, mass: np.ndarray) -> None:
        visits[idx] += mass  # idx is unique

    propagate(chain, start, max_steps, visit)
    return visits
