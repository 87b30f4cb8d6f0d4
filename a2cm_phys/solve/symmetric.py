"""The grid oracle on large arenas: the exact optimum against the random (or static)
evader over the canonical joint states only (issue 35).

The game is invariant under the square's 8 symmetries (with obstacles, those that keep the
blocked cells) and the pursuers' permutations (:mod:`.symmetry`), so the optimal value is
constant on each orbit and a greedy joint action of a canonical state, mapped through the
symmetry, is optimal at every state of its orbit. Storage: the canonical map (one int32 per
joint state, the bulk of the memory) and a few arrays over the ``≈ C^(N+1) / (G · N!)``
canonical states (``G`` maps: 8 without obstacles).

The algorithm is modified policy iteration on that quotient: a *greedy sweep*
(:class:`~.symmetric_sweep.CanonicalBackup`, all ``A^N`` joint actions × evader moves of
every canonical state: the costly part) gives ``T v``, a greedy policy and its
successors; then cheap *evaluation sweeps* (``nb`` look-ups per state) apply that policy's
backup until it settles. It stops when a greedy sweep's residual ``max |T v − v|`` is below
``tol`` (the criterion of :func:`~.dp.solve_dp`'s value iteration) and returns that
sweep's values and policy. The objective is :mod:`.dp`'s: expected total raw reward until
termination, undiscounted; against the random evader every state can force capture.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..base.progress import Progress
from ..config import Scenario
from ..envs.core import default_start
from .policy_chain import CaptureDistribution
from .symmetric_sweep import CHUNK_ENTRIES, CanonicalBackup, Greedy
from .symmetry import CanonicalIndex, Symmetry
from .tables import start_law, state_index
from .transitions import TooLargeError, UnsupportedError, check_supported

MEMORY_BUDGET = 8 * 2**30
"""Largest estimated peak memory (bytes) the symmetric solver attempts."""

EVADERS = ("random", "static")
"""The evaders whose laws are invariant under the symmetries (and that it solves)."""

MAX_EVALUATION_SWEEPS = 100
"""Evaluation sweeps at most between two greedy sweeps (an improper policy never settles)."""


def symmetry_of(scenario: Scenario) -> Symmetry:
    """The symmetry group of a grid scenario: the square's maps that keep its blocked cells
    (all 8 without obstacles) and the pursuers' permutations (:class:`~.symmetry.Symmetry`)."""
    return Symmetry(scenario.size, scenario.pursuers, scenario.blocked_cells())


def memory_estimate(scenario: Scenario) -> float:
    """Estimated peak bytes of :func:`solve_symmetric` on ``scenario``.

    The canonical map (4 bytes per joint state), the canonical states' arrays (cells,
    values, policy, reward, steps, successors; their count estimated as ``S / (G · N!)``
    plus 10 %), one greedy chunk's temporaries and the interpreter's ~150 MB.
    """
    sym = symmetry_of(scenario)
    n, nb = scenario.pursuers, scenario.actions
    canon = 1.1 * sym.n_states / sym.order
    per_canon = 4 * (n + 1) + 8 * 5 + 4 + 8 * nb
    chunk = CHUNK_ENTRIES * (8 * 6 + 9 * nb)
    return float(4 * sym.n_states + canon * per_canon + chunk + 150 * 2**20)


def check_symmetric(scenario: Scenario, memory_budget: float = MEMORY_BUDGET) -> float:
    """Raise unless :func:`solve_symmetric` solves ``scenario``; return its memory estimate.

    :class:`~.transitions.UnsupportedError` (naming the key) for what it does not solve,
    :class:`~.transitions.TooLargeError` (naming size, pursuers and the estimate against
    the budget) above its reach.
    """
    check_supported(scenario)
    if scenario.evader not in EVADERS:
        raise UnsupportedError(
            f"the symmetric oracle needs evader = {' or '.join(map(repr, EVADERS))} (a law "
            f"the symmetries keep), got evader={scenario.evader!r}"
        )
    need = memory_estimate(scenario)
    states = scenario.size ** (2 * (scenario.pursuers + 1))
    if need > memory_budget or states >= 2**31:
        raise TooLargeError(
            f"{scenario.size}x{scenario.size} arena with {scenario.pursuers} pursuers is too "
            f"large for the symmetric oracle: {states:,} joint states need ~{need / 2**30:.1f}"
            f" GiB (budget {memory_budget / 2**30:.1f} GiB; at most 2^31 joint states)"
        )
    return need


@dataclass
class SymmetricResult:
    """The optimum over canonical states: ``value`` (optimal expected return), ``policy``
    (greedy joint action in the canonical frame, pursuers sorted), ``steps`` (expected
    steps to the episode's end under it) per canonical id of ``index`` and ``succ (nb, n)``
    the policy's successor ids per evader move (the sentinel where the episode ends), with
    the solve's sweeps, last greedy residual, seconds and memory estimate (bytes)."""

    scenario: Scenario
    index: CanonicalIndex
    value: np.ndarray
    policy: np.ndarray
    steps: np.ndarray
    succ: np.ndarray
    greedy_sweeps: int
    evaluation_sweeps: int
    residual: float
    seconds: float
    memory_estimate: float

    def ids(self, positions: np.ndarray) -> np.ndarray:
        """Canonical ids of integer positions ``(..., N + 1, 2)`` (the sentinel where a
        pursuer stands on the evader)."""
        return self.index.ids[state_index(self.scenario, positions)]

    def _lookup(self, table: np.ndarray, positions: np.ndarray) -> float | np.ndarray:
        out = np.append(table, 0.0)[self.ids(positions)]
        return float(out) if out.ndim == 0 else out

    def optimal_return(self, positions: np.ndarray) -> float | np.ndarray:
        """Optimal expected raw return from positions (``0`` where already captured)."""
        return self._lookup(self.value, positions)

    def expected_capture_steps(self, positions: np.ndarray) -> float | np.ndarray:
        """Expected steps until the episode ends under the optimal policy, from positions
        ``(N + 1, 2)`` or ``(..., N + 1, 2)`` (``0`` where a pursuer is on the evader)."""
        return self._lookup(self.steps, positions)

    def actions(self, positions: np.ndarray) -> np.ndarray:
        """The optimal policy's per-pursuer actions ``(..., N)`` at positions
        ``(..., N + 1, 2)``, in each state's own frame (any action where captured)."""
        xy = np.asarray(positions, dtype=np.int64)
        flat = xy.reshape(-1, *xy.shape[-2:])
        sym, ids = self.index.symmetry, np.atleast_1d(self.ids(flat))
        joint = np.append(self.policy, 0)[ids]
        canonical = np.stack(np.unravel_index(joint, (self.scenario.actions,) * sym.n), 1)
        cells = (flat[..., 0] + self.scenario.size * flat[..., 1]).T
        return sym.own_actions(cells, canonical).reshape(*xy.shape[:-2], sym.n)

    def start_positions(self) -> np.ndarray:
        """The scenario's default start ``(N + 1, 2)`` (SPEC §1)."""
        return default_start(self.scenario.size, self.scenario.pursuers)

    def end_distribution(
        self, positions: np.ndarray | None = None, max_steps: int | None = None, tail: float = 1e-12
    ) -> tuple[np.ndarray, float]:
        """Law of the episode's end under the optimal policy, from ``positions`` (default:
        over the scenario's start distribution): ``P(ends at step k)`` for ``k = 1, 2, …``
        until ``max_steps`` (default: the scenario's) or until less than ``tail`` is left,
        and the mass left then."""
        n, nb = self.index.n, len(self.succ)
        mass = np.zeros(n + 1)
        if positions is None:
            mass[: n + 1] = self.start_mass
        else:
            mass[self.ids(positions)] = 1.0
        ended, left = [], float(mass[:n].sum())
        for _ in range(self.scenario.max_steps if max_steps is None else max_steps):
            if left < tail:
                break
            share = mass[:n] / nb
            mass = sum(np.bincount(self.succ[b], share, minlength=n + 1) for b in range(nb))
            ended.append(float(mass[n]))
            left = float(mass[:n].sum())
        return np.array(ended), left

    def distribution(self, positions: np.ndarray | None = None) -> CaptureDistribution:
        """:meth:`end_distribution` as the dense oracle's :class:`~.policy_chain.
        CaptureDistribution` (every end counted as a capture: in ``terminate`` mode the
        ends by a collision are among them)."""
        ended, left = self.end_distribution(positions)
        return CaptureDistribution(ended, np.zeros_like(ended), left)

    def to_arrays(self) -> dict[str, np.ndarray]:
        """The solution as named arrays (for an ``.npz`` cache; :meth:`from_arrays`)."""
        stats = [self.greedy_sweeps, self.evaluation_sweeps]
        floats = [self.residual, self.seconds, self.memory_estimate]
        return {
            "keys": self.index.keys, "value": self.value, "policy": self.policy,
            "steps": self.steps, "succ": self.succ, "sweeps": np.array(stats),
            "stats": np.array(floats),
        }  # fmt: skip

    @classmethod
    def from_arrays(cls, scenario: Scenario, arrays: Mapping[str, np.ndarray]) -> SymmetricResult:
        """The solution :meth:`to_arrays` gave, its canonical map rebuilt (seconds at
        10x10); ``ValueError`` if the arrays are not of ``scenario``'s canonical states."""
        index = symmetry_of(scenario).index()
        if not np.array_equal(index.keys, arrays["keys"]):
            raise ValueError("the arrays are not over this scenario's canonical states")
        (greedy, evaluations), (residual, seconds, need) = arrays["sweeps"], arrays["stats"]
        return cls(
            scenario, index, arrays["value"], arrays["policy"], arrays["steps"],
            arrays["succ"], int(greedy), int(evaluations), float(residual), float(seconds),
            float(need),
        )  # fmt: skip

    @cached_property
    def start_mass(self) -> np.ndarray:
        """``(n + 1,)`` the start distribution's probability of each canonical state (the
        last, the captured sentinel, gets none): the starts enumerated as sets of pursuer
        cells (the pursuers here are interchangeable), each mapped to its canonical state."""
        idx, p = start_law(self.scenario, ordered=False)
        return np.bincount(self.index.ids[idx], weights=p, minlength=self.index.n + 1)

    @property
    def start_value(self) -> float:
        """Optimal expected return over the start distribution."""
        return float(self.start_mass @ np.append(self.value, 0.0))

    @property
    def start_steps(self) -> float:
        """Expected steps to the episode's end, playing optimally, over the start
        distribution (exactly: every start enumerated)."""
        return float(self.start_mass @ np.append(self.steps, 0.0))


def evaluate(
    reward: np.ndarray, succ: np.ndarray, v: np.ndarray, tol: float, max_sweeps: int
) -> tuple[np.ndarray, int, float]:
    """Apply a fixed policy's backup ``v ← reward + mean_b v[succ[b]]`` to ``v (n + 1,)``
    (sentinel last, 0) until it moves by less than ``tol`` or ``max_sweeps`` times; return
    ``(v, sweeps, last change)``."""
    n, nb = len(reward), len(succ)
    buf, change = np.empty(n), np.inf
    for sweep in range(1, max_sweeps + 1):
        new = np.take(v, succ[0])
        for b in range(1, nb):
            new += np.take(v, succ[b], out=buf)
        new /= nb
        new += reward
        change = float(np.max(np.abs(new - v[:n]), initial=0.0))
        v[:n] = new
        if change < tol:
            return v, sweep, change
    return v, max_sweeps, change


def solve_symmetric(
    scenario: Scenario,
    tol: float | None = None,
    memory_budget: float = MEMORY_BUDGET,
    max_greedy_sweeps: int = 10_000,
    progress: bool = False,
) -> SymmetricResult:
    """The exact optimum of a grid scenario against the random or static evader, by modified
    policy iteration over canonical states, to a greedy residual below ``tol`` (default
    ``1e-10 · |step|``, :func:`~.dp.solve_dp`'s). ``progress`` reports on stderr.

    Raises what :func:`check_symmetric` raises, and ``RuntimeError`` without convergence.
    """
    start = time.perf_counter()
    need = check_symmetric(scenario, memory_budget)
    tol = 1e-10 * abs(scenario.rewards.step) if tol is None else tol
    index = symmetry_of(scenario).index(progress)
    backup = CanonicalBackup(scenario, index)
    v = np.zeros(index.n + 1)
    greedy = evaluations = 0
    with Progress("policy iteration", unit="sweeps", enabled=progress) as bar:
        while True:
            if greedy == max_greedy_sweeps:
                raise RuntimeError(f"no convergence in {max_greedy_sweeps} greedy sweeps")
            step = backup.sweep(v)
            greedy += 1
            residual = float(np.max(np.abs(step.value - v[:-1]), initial=0.0))
            v[:-1] = step.value
            bar.note(f"greedy residual {residual:.1e} (tol {tol:.0e})")
            bar.update()
            if residual < tol:
                break
            v, sweeps, _ = evaluate(step.reward, step.succ, v, tol / 10, MAX_EVALUATION_SWEEPS)
            evaluations += sweeps
    steps = _steps(scenario, step, tol)
    return SymmetricResult(
        scenario, index, step.value, step.action, steps, step.succ, greedy, evaluations, residual,
        time.perf_counter() - start, need,
    )  # fmt: skip


def _steps(scenario: Scenario, step: Greedy, tol: float) -> np.ndarray:
    """Expected steps to the end under the greedy policy: ``value / step`` when only the
    step reward pays, else that policy's evaluation with reward 1 per step."""
    rw = scenario.rewards
    pays = rw.wall or rw.capture or (rw.collision and scenario.collisions.mode != "off")
    if not pays:
        return step.value / rw.step
    ones = np.ones(len(step.value))
    v, _, _ = evaluate(ones, step.succ, np.zeros(len(ones) + 1), tol, 1_000_000)
    return v[:-1]
