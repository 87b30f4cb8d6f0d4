"""``qmdp``: a belief-planning reference team for partially observed grids (SPEC §6b).

Each step, every game's belief over the evader's cell is brought up to date by the Bayes
filter (:class:`~a2cm_phys.solve.belief.EvaderFilter`: the known start or the start
distribution, the evader's known move law, no capture, the pooled sightings), and the team
takes the joint action that is best on average over the belief under the exact oracle's
values (QMDP):

    a* = argmax_a Σ_e b(e) Q(p, e, a),   Q(s, a) = r(s, a) + E_evader[ going on · V(s') ]

``V`` is the oracle's optimal value of the fully observed game (:func:`load_or_solve`, of
its grid twin: against the random evader where the evader is learned) and ``Q`` its own
Bellman backup's, the same objective it optimises: the step reward, the wall, collision
and capture rewards, and termination by a capture (or a collision in ``terminate``
mode). :class:`JointQ` computes it from the solver's per-agent tables
(:class:`~a2cm_phys.solve.model.GridModel`), the rules the oracle was solved with. Ties go
to the lowest joint action index. QMDP assumes the evader's cell becomes known after one
step, so it never plans to look: it is a reference, not the optimum of the partially
observed game (which no team can beat the fully observed optimum of).

The team is centralised: one planner reads every pursuer's sightings, whatever
``sensing.share`` says, and only those (the pursuers' slices of the team vector, never the
state prefix). :class:`QMDPPolicy` keeps each game's belief and pursuer cells between
calls and forgets a game's when its episode ends (:meth:`QMDPPolicy.episodes_ended`).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..config import ConfigError, Scenario
from ..solve.belief import EvaderFilter, pursuer_sightings
from ..solve.cache import OracleSolution, load_or_solve
from .names import oracle_evader

__all__ = ["JointQ", "QMDPPolicy", "qmdp_policy"]


class JointQ:
    """``Q(p, e, a)`` of the oracle's solution for every evader cell and joint action.

    The evader's law must be uniform over its moves (the random and static evaders), as in
    the filter.
    """

    def __init__(self, solution: OracleSolution) -> None:
        m = solution.model
        if m.weights is not None:
            raise ConfigError(
                f"qmdp policy: the evader {m.scenario.evader!r} does not move uniformly at"
                " random; the belief filter models the random and static evaders only"
            )
        self.model = m
        self.value = np.asarray(solution.value, dtype=np.float64)
        self.joint = m.joint_to_actions(np.arange(m.n_joint))  # (J, N)
        self.scale = m.n_cells ** np.arange(m.n, 0, -1)  # a pursuer's place in a state index

    def _reward(self, p: np.ndarray, a: np.ndarray, free: np.ndarray) -> np.ndarray:
        """The expected immediate reward ``(B, J, C)`` (the backup's: step, walls,
        collisions, capture) of pursuers ``p`` and actions ``a`` ``(B, J, N)``."""
        m, rw = self.model, self.model.scenario.rewards
        r = np.full(p.shape[:2], rw.step)
        for i in range(m.n):
            r = r + rw.wall * m.walls[p[..., i], a[..., i]]
            for j in range(i + 1, m.n):
                pair = m.pair_collide[p[..., i], a[..., i], p[..., j], a[..., j]]
                r = r + m.collision_reward * pair
        r = np.broadcast_to(r[..., None], free.shape[:3])
        if rw.capture:
            r = r + rw.capture * (1.0 - free.mean(axis=-1))
        return r

    def q(self, pursuers: np.ndarray) -> np.ndarray:
        """``Q`` ``(B, J, C)`` of pursuers at cells ``(B, N)``: every joint action (index
        ``(a_0 · A + a_1) · A + …``) and every evader cell (pursuers' own cells included,
        whose rows are never weighed: the belief is zero there)."""
        m = self.model
        p = np.broadcast_to(pursuers[:, None, :], (len(pursuers), m.n_joint, m.n))
        a = np.broadcast_to(self.joint[None], p.shape)
        free = np.ones((*p.shape[:2], m.n_cells, m.n_moves))
        for i in range(m.n):
            free = free * m.free[p[..., i], a[..., i]]  # (B, J, C, nb): no capture by i
        base = (m.pmove[p, a] * self.scale).sum(-1)  # (B, J): the pursuers' next cells
        after = self.value[base[..., None, None] + m.emove[None, None]]  # (B, J, C, nb)
        going = (free * after).mean(axis=-1)
        if m.terminate:
            for i in range(m.n):
                for j in range(i + 1, m.n):
                    pair = m.pair_collide[p[..., i], a[..., i], p[..., j], a[..., j]]
                    going = going * (pair == 0)[..., None]
        return self._reward(p, a, free) + going

    def expected(self, pursuers: np.ndarray, belief: np.ndarray) -> np.ndarray:
        """``Σ_e b(e) Q(p, e, a)`` ``(B, J)`` for beliefs ``(B, C)``."""
        return np.einsum("bjc,bc->bj", self.q(pursuers), belief)

    def best(self, pursuers: np.ndarray, belief: np.ndarray) -> np.ndarray:
        """The QMDP joint actions ``(B, N)`` int64: the first maximiser of :meth:`expected`."""
        return self.joint[self.expected(pursuers, belief).argmax(axis=1)]


class QMDPPolicy:
    """The QMDP team of a grid scenario with sensing, a stateful rollout policy:
    ``policy(obs (B, team_dim), rng) -> actions (B, N)`` int64 (deterministic; ``rng`` is
    not used), with :meth:`episodes_ended`. ``solution`` is the oracle's solution of the
    scenario's grid twin (see the module docstring)."""

    def __init__(self, scenario: Scenario, solution: OracleSolution) -> None:
        self.scenario = scenario
        self.filter = EvaderFilter(solution.scenario)
        self.values = JointQ(solution)
        self.belief: np.ndarray | None = None  # (B, C)
        self.cells: np.ndarray | None = None  # (B, N): the pursuers' cells at the last call
        self.fresh: np.ndarray | None = None  # (B,): games whose episode starts at the next call

    def update(self, obs: np.ndarray) -> np.ndarray:
        """Bring every game's belief up to date with team vectors ``obs`` and return the
        pursuers' cells ``(B, N)``."""
        cells, seen = pursuer_sightings(self.scenario, obs)
        b = len(cells)
        if self.belief is None or len(self.belief) != b:
            self.belief = self.filter.initial(cells)
            self.cells, self.fresh = cells, np.ones(b, dtype=bool)
        prior = np.where(
            self.fresh[:, None],
            self.filter.initial(cells),
            self.filter.predict(self.belief, self.cells, cells),
        )
        self.belief = self.filter.observe(prior, cells, seen)
        self.cells, self.fresh = cells, np.zeros(b, dtype=bool)
        return cells

    def __call__(self, obs: np.ndarray, rng: np.random.Generator | None = None) -> np.ndarray:
        """The team's actions ``(B, N)`` int64 for team vectors ``obs`` ``(B, team_dim)``."""
        cells = self.update(obs)
        return self.values.best(cells, self.belief)

    def episodes_ended(self, ended: np.ndarray) -> None:
        """Forget the games whose episode ended (``(B,)`` bool): their next call starts from
        the known start."""
        if self.fresh is not None:
            self.fresh = self.fresh | np.asarray(ended, dtype=bool)


def qmdp_policy(scenario: Scenario, progress: bool = False) -> QMDPPolicy:
    """The QMDP team of ``scenario`` (``progress``: report the oracle's solve on stderr).

    Raises :class:`~a2cm_phys.config.ConfigError` naming the scenario unless it is a grid
    scenario with sensing whose oracle can be solved and whose evader (the random one where
    it is learned) moves uniformly at random or stays.
    """
    from ..solve import TooLargeError, UnsupportedError

    if scenario.mode != "grid":
        raise ConfigError(
            f"qmdp policy: scenario '{scenario.name}' is not a grid (the belief and the"
            " oracle's values are over cells)"
        )
    if not scenario.sensing.on:
        raise ConfigError(
            f"qmdp policy: scenario '{scenario.name}' has no sensing (every pursuer sees the"
            " whole state: use oracle); qmdp needs a [sensing] radius"
        )
    evader = oracle_evader(scenario)
    twin = dataclasses.replace(scenario, evader=evader)
    if evader not in ("random", "static"):
        raise ConfigError(
            f"qmdp policy: scenario '{scenario.name}' has the {evader} evader; the belief"
            " filter models the random and static evaders only"
        )
    try:
        solution = load_or_solve(twin, progress=progress)
    except (TooLargeError, UnsupportedError) as err:
        raise ConfigError(f"qmdp policy: scenario '{scenario.name}': {err}") from None
    return QMDPPolicy(scenario, solution)
