"""Exact best responses on the grid: how exploitable a fixed policy of either team is.

**The evader's best response** to a fixed, stationary pursuer policy table
(:mod:`.tables`) maximises the expected episode length ``E[min(T, max_steps)]``, ``T`` the
step that ends the episode. The episode is truncated at ``max_steps``, so the value is
finite even where the evader could escape for ever, and the problem is a finite-horizon
MDP solved by backward induction over the remaining steps::

    V_0 = 0,   V_k(s) = max_b Σ_a P(a | s) · (1 + [the episode goes on] · V_{k-1}(s'))

with ``V_k = 0`` on states where a pursuer stands on the evader. Its value from the default
start is the pursuer policy's **worst-case capture time**. The evader's moves are its own
action space (``actions``, as a learned evader's).

*Collisions.* In ``terminate`` mode a pursuer collision ends the episode too. The evader
then "survives" only until that step: the value counts the episode's length whatever ended
it, and :attr:`Outcome.p_capture` and :attr:`Outcome.p_end` tell capture from collision.

*Early stop.* ``V_k`` grows with ``k`` and its increments ``δ_k = max_s (V_k − V_{k-1})(s)``
never grow (the operator is monotone and moves no state's value by more than the largest
change of its arguments), so ``V_H ≤ V_k + (H − k) · δ_k`` in every state. The induction
stops as soon as that bound is ``≤ tol`` (never with a negative ``tol``); otherwise (an
evader that can escape for ever with positive probability keeps ``δ_k`` away from 0) it
runs all ``max_steps`` steps.

*The policy.* The optimal evader under truncation is non-stationary (it may play
differently with few steps left). :attr:`BestResponse.policy` is the decision rule of the
last step computed: optimal for the first step from every state, and optimal throughout
when the induction stopped early (to within the bound). Among the moves that make the
episode longest it takes the one least likely to be captured (with one step left, being
caught or not lasts one step either way), then the lowest action.

**The pursuers' best response** to a fixed evader policy table is the oracle
(:func:`~.dp.solve_dp`) solved against that evader, its optimal joint policy then evaluated
with the same truncated recursion (``max`` replaced by the evader's law), so both best
responses report ``E[min(T, max_steps)]``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..base.progress import Progress
from ..config import Scenario
from .dp import solve_dp
from .model import GridModel
from .pursuer_step import Kind, PursuerStep
from .tables import check_table, joint_policy_table, start_state

TOLERANCE = 1e-9
"""Default bound on the error of every value when the induction stops early (steps)."""


@dataclass
class Outcome:
    """Truncated episode statistics from every joint state under a pair of policies.

    ``values[s] = E[min(T, max_steps)]`` (``T`` the step ending the episode: capture, or a
    collision in ``terminate`` mode), ``p_capture[s]`` and ``p_end[s]`` the probabilities
    that the evader is captured, and that the episode ends at all, within ``max_steps``
    (``0``, ``1`` and ``1`` where a pursuer stands on the evader). ``iterations`` steps of
    the recursion were computed; every value is within ``error_bound`` of the exact one.
    """

    values: np.ndarray
    p_capture: np.ndarray
    p_end: np.ndarray
    iterations: int
    error_bound: float
    seconds: float
    kind: str


@dataclass
class BestResponse:
    """The best response of ``team`` (``"evader"`` or ``"pursuers"``) to a fixed policy.

    ``policy`` is its policy table (:mod:`.tables`; one-hot rows), ``outcome`` the
    truncated statistics it achieves, ``start`` the index of the default start state and
    ``meta`` solver statistics.
    """

    team: str
    scenario: Scenario
    policy: np.ndarray
    outcome: Outcome
    start: int
    meta: dict = field(default_factory=dict)

    @property
    def values(self) -> np.ndarray:
        """``E[min(T, max_steps)]`` from every joint state under the best response."""
        return self.outcome.values

    @property
    def value_from_start(self) -> float:
        """``E[min(T, max_steps)]`` from the default start: for the evader's best response
        the pursuers' worst-case capture time."""
        return float(self.outcome.values[self.start])

    @property
    def p_capture_from_start(self) -> float:
        """Probability of a capture within ``max_steps`` from the default start."""
        return float(self.outcome.p_capture[self.start])


def _choose(q: np.ndarray) -> np.ndarray:
    """The evader's move ``(S,)``: the longest episode, then the least capture, then the
    lowest action (each to within float tolerance, so rounding decides nothing)."""
    steps, capture = q[..., 0], q[..., 1]
    best = steps >= steps.max(axis=1, keepdims=True) - 1e-9
    capture = np.where(best, capture, np.inf)
    return np.argmax(capture <= capture.min(axis=1, keepdims=True) + 1e-12, axis=1)


def _induction(
    step: PursuerStep, evader: np.ndarray | None, tol: float, bar: Progress
) -> tuple[np.ndarray, np.ndarray | None, int, float]:
    """Backward induction over ``max_steps`` steps; ``evader`` ``(S, nb)`` or ``None``: max.

    Columns of the carried array: expected steps, P(capture), and P(end) when collisions
    can end the episode. Returns it, the last step's evader choice (``None`` for a fixed
    evader), the steps computed and the error bound; ``bar`` counts the steps.
    """
    horizon = step.scenario.max_steps
    columns = [np.ones_like(step.p_capture), step.p_capture]
    if step.terminate:
        columns.append(step.p_end)
    reward = np.stack(columns, axis=-1)  # (S, nb, m)
    invalid = ~step.valid
    x = np.zeros((step.n_states, reward.shape[-1]))
    rows = np.arange(step.n_states)
    choice, bound, k = None, float(horizon), 0
    while k < horizon:
        q = step.expect(x)
        q += reward
        if evader is None:
            choice = _choose(q)
            new = q[rows, choice]
        else:
            new = np.einsum("sb,sbm->sm", evader, q)
        new[invalid] = 0.0
        k += 1
        bound = (horizon - k) * float(np.max(new[:, 0] - x[:, 0], initial=0.0))
        x = new
        bar.note(f"bound {bound:.1e}")
        bar.update()
        if bound <= tol:
            break
    return x, choice, k, max(bound, 0.0)


def _outcome(step: PursuerStep, x: np.ndarray, k: int, bound: float, t0: float) -> Outcome:
    invalid = ~step.valid
    p_end = x[:, 2] if step.terminate else x[:, 1].copy()
    x[invalid, 1] = 1.0
    p_end[invalid] = 1.0
    return Outcome(x[:, 0], x[:, 1], p_end, k, bound, time.perf_counter() - t0, step.kind)


def evader_best_response(
    scenario: Scenario,
    pursuer_probs: np.ndarray,
    tol: float = TOLERANCE,
    kind: Kind = "auto",
    progress: bool = False,
) -> BestResponse:
    """The evader's best response to the pursuers' policy table ``(S, N, A)``.

    ``kind`` forces an implementation of the step (:mod:`.pursuer_step`; for tests);
    ``progress`` reports the steps of the induction and its error bound on stderr (off
    by default: training calls this every few updates). Raises
    :class:`~.model.TooLargeError` for arenas beyond the limits (the message says which).
    """
    t0 = time.perf_counter()
    step = PursuerStep(scenario, pursuer_probs, np.arange(scenario.actions), kind)
    with _steps("best response", scenario, progress) as bar:
        x, choice, k, bound = _induction(step, None, tol, bar)
    policy = np.zeros((step.n_states, 1, scenario.actions))
    policy[np.arange(step.n_states), 0, choice] = 1.0
    policy[~step.valid] = 1.0 / scenario.actions  # never read: any distribution
    outcome = _outcome(step, x, k, bound, t0)
    meta = {"kind": step.kind, "iterations": k, "error_bound": bound}
    return BestResponse("evader", scenario, policy, outcome, start_state(scenario), meta)


def evaluate_tables(
    scenario: Scenario,
    pursuer_probs: np.ndarray,
    evader_probs: np.ndarray,
    tol: float = TOLERANCE,
    kind: Kind = "auto",
    progress: bool = False,
) -> Outcome:
    """Truncated statistics of the pursuers' table ``(S, N, A)`` against the evader's table
    ``(S, 1, A)`` (or ``(S, 1, 5)``, column 4 stay), exactly (``progress``: report the
    steps on stderr)."""
    t0 = time.perf_counter()
    evader = check_table(scenario, evader_probs, "evader")[:, 0]
    step = PursuerStep(scenario, pursuer_probs, np.arange(evader.shape[1]), kind)
    with _steps("evaluation", scenario, progress) as bar:
        x, _, k, bound = _induction(step, evader, tol, bar)
    return _outcome(step, x, k, bound, t0)


def _steps(what: str, scenario: Scenario, progress: bool) -> Progress:
    """The progress of a backward induction over at most ``max_steps`` steps."""
    return Progress(what, scenario.max_steps, "steps", enabled=progress, upper_bound=True)


def pursuers_best_response(
    scenario: Scenario,
    evader_probs: np.ndarray,
    tol: float = TOLERANCE,
    joint_policy: np.ndarray | None = None,
    progress: bool = False,
) -> BestResponse:
    """The pursuers' best response to the evader's table: the oracle against that evader.

    The oracle optimises the scenario's own objective (expected raw return until
    termination; with the step penalty alone, the expected capture time). ``joint_policy``
    is its optimal joint policy if already solved against this evader (e.g. a cached
    :class:`~a2cm_phys.solve.cache.OracleSolution`'s ``policy``); otherwise it is solved here.
    ``progress`` reports the solve and the evaluation on stderr. Raises
    :class:`~.model.TooLargeError` or :class:`~.model.UnsupportedError` as the oracle.
    """
    t0 = time.perf_counter()
    meta: dict = {}
    if joint_policy is None:
        model = GridModel(scenario, evader_probs=evader_probs)
        dp = solve_dp(model, progress=progress)
        joint_policy = dp.policy
        lose = 0 if dp.lose is None else int((dp.lose & model.valid()).sum())
        meta = {"sweeps": dp.sweeps, "losing_states": lose, "dp_seconds": dp.seconds}
    policy = joint_policy_table(scenario, joint_policy)
    outcome = evaluate_tables(scenario, policy, evader_probs, tol, progress=progress)
    meta.update(kind=outcome.kind, iterations=outcome.iterations, seconds=time.perf_counter() - t0)
    return BestResponse("pursuers", scenario, policy, outcome, start_state(scenario), meta)
