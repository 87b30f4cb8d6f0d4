"""``python -m a2cm_phys.oracle``: the exact optimum of a grid scenario, cached, and as a policy.

The grid game is solved by value iteration over the joint state (every pursuer's cell and
the evader's) with :mod:`a2cm_phys.solve`. The objective is the scenario's own expected
total raw reward until the episode terminates, undiscounted: with the step penalty alone
(experiment 1) that is minus the expected number of steps to capture; with collision
penalties it includes them, and in ``terminate`` mode a collision ends the episode.
Truncation at ``max_steps`` is ignored by the optimisation (its probability is reported).

The solution is cached as ``<cache dir>/<key>.npz``, the key a hash of the fields that
define the game (:func:`cache_key`); the cache directory defaults to
``$XDG_CACHE_HOME/a2cm_phys/oracle`` (``~/.cache/a2cm_phys/oracle``).
:class:`OraclePolicy` plays the optimal policy from observations, so evaluations and replays
can put learned policies next to it.
"""

from __future__ import annotations

import hashlib
import json
import os
import sys
import time
import tracemalloc
import zipfile
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np

from .cli import (
    Parser,
    UsageError,
    add_scenario_options,
    run_cli,
    scenario_from_args,
    writable_dir,
)
from .config import Scenario, load_scenario
from .envs.core import default_start
from .solve import (
    GridModel,
    TooLargeError,
    UnsupportedError,
    capture_distribution,
    evaluate_policy,
    policy_chain,
    solve_dp,
)
from .solve.evaluate import CaptureDistribution, PolicyChain

SOLVER_VERSION = 1
"""Bumped whenever a change of the solver invalidates cached solutions."""


def cache_key(scenario: Scenario) -> str:
    """Hash of the scenario fields that define the solved game (not its name or horizon)."""
    rw = scenario.rewards
    fields = {
        "version": SOLVER_VERSION,
        "size": scenario.size,
        "pursuers": scenario.pursuers,
        "actions": scenario.actions,
        "evader": scenario.evader,
        "collisions": scenario.collisions.mode,
        "rewards": [rw.step, rw.collision, rw.capture, rw.wall],
    }
    return hashlib.sha256(json.dumps(fields, sort_keys=True).encode()).hexdigest()[:16]


def default_cache_dir() -> Path:
    """``$XDG_CACHE_HOME/a2cm_phys/oracle``, by default ``~/.cache/a2cm_phys/oracle``."""
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "a2cm_phys" / "oracle"


@dataclass
class OracleSolution:
    """The solved game: arrays over joint states (index layout of :class:`GridModel`).

    ``value`` is the optimal expected return (``-inf`` where termination cannot be forced),
    ``policy`` a greedy optimal joint action, ``steps`` and ``collisions`` the expected
    episode length (``inf`` where termination cannot be forced) and number of collisions
    (``nan`` there) under that policy, ``lose`` the mask of such states (``None`` if there
    are none). ``meta`` holds the solve's statistics; ``path`` the cache file, ``cached``
    whether it was loaded from it and ``built`` the model, if already built.
    """

    scenario: Scenario
    value: np.ndarray
    policy: np.ndarray
    steps: np.ndarray
    collisions: np.ndarray
    lose: np.ndarray | None
    meta: dict = field(default_factory=dict)
    path: Path | None = None
    cached: bool = False
    built: GridModel | None = field(default=None, repr=False)

    @property
    def model(self) -> GridModel:
        """The factorised model of the scenario (its tables; built on first use)."""
        if self.built is None:
            self.built = GridModel(self.scenario)
        return self.built

    @cached_property
    def chain(self) -> PolicyChain:
        """The Markov chain of :attr:`policy`, replayed through the grid rules."""
        return policy_chain(self.model, self.policy)

    def index(self, positions: np.ndarray) -> np.ndarray:
        """State indices of integer positions ``(..., N + 1, 2)`` (pursuers, then evader)."""
        xy = np.asarray(positions, dtype=np.int64)
        size, n = self.scenario.size, self.scenario.pursuers
        if xy.shape[-2:] != (n + 1, 2):
            raise ValueError(f"positions must have shape (..., {n + 1}, 2), got {xy.shape}")
        if np.any((xy < 0) | (xy >= size)):
            raise ValueError(f"positions off the {size}x{size} arena")
        cells = xy[..., 0] + size * xy[..., 1]
        return np.ravel_multi_index(tuple(np.moveaxis(cells, -1, 0)), self.model.shape)

    def _captured(self, positions: np.ndarray) -> np.ndarray:
        xy = np.asarray(positions)
        return np.any(np.all(xy[..., :-1, :] == xy[..., -1:, :], axis=-1), axis=-1)

    def expected_capture_steps(self, positions: np.ndarray) -> float | np.ndarray:
        """Expected steps until the episode ends under the optimal policy, from positions.

        ``positions`` is ``(N + 1, 2)`` or a batch ``(..., N + 1, 2)`` of ``(x, y)`` cells;
        ``0`` where a pursuer already stands on the evader, ``inf`` where capture cannot be
        forced. In ``terminate`` mode an episode may also end by a collision.
        """
        out = np.where(self._captured(positions), 0.0, self.steps[self.index(positions)])
        return float(out) if out.ndim == 0 else out

    def optimal_return(self, positions: np.ndarray) -> float | np.ndarray:
        """Optimal expected raw return from positions (``0`` where already captured)."""
        out = np.where(self._captured(positions), 0.0, self.value[self.index(positions)])
        return float(out) if out.ndim == 0 else out

    def actions(self, positions: np.ndarray) -> np.ndarray:
        """The optimal policy's actions ``(..., N)`` int64 at positions ``(..., N + 1, 2)``."""
        return self.model.joint_to_actions(self.policy[self.index(positions)])

    def start_positions(self) -> np.ndarray:
        """The scenario's default start ``(N + 1, 2)`` (SPEC §1)."""
        return default_start(self.scenario.size, self.scenario.pursuers)

    def distribution(self, positions: np.ndarray | None = None) -> CaptureDistribution:
        """Exact law of the episode's end under the optimal policy (default: from the start)."""
        pos = self.start_positions() if positions is None else np.asarray(positions)
        return capture_distribution(self.chain, int(self.index(pos)), self.scenario.max_steps)


def _save(path: Path, sol: OracleSolution) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    lose = np.zeros(0, dtype=bool) if sol.lose is None else sol.lose
    with open(tmp, "wb") as fh:  # a file handle: np.savez would append ".npz" to the name
        np.savez_compressed(
            fh, value=sol.value, policy=sol.policy, steps=sol.steps,
            collisions=sol.collisions, lose=lose, meta=np.array(json.dumps(sol.meta)),
        )  # fmt: skip
    os.replace(tmp, path)  # atomic: a concurrent reader never sees half a file


def _load(path: Path, model: GridModel) -> OracleSolution | None:
    scenario = model.scenario
    try:
        with np.load(path, allow_pickle=False) as data:
            meta = json.loads(str(data["meta"]))
            if meta.get("key") != cache_key(scenario) or data["value"].size != model.n_states:
                return None
            lose = data["lose"]
            return OracleSolution(
                scenario, data["value"], data["policy"], data["steps"], data["collisions"],
                lose if lose.size else None, meta, path, cached=True, built=model,
            )  # fmt: skip
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
        return None  # unreadable or stale: solve again and overwrite it


def load_or_solve(
    scenario: Scenario, cache_dir: str | Path | None = None, use_cache: bool = True
) -> OracleSolution:
    """The cached solution of ``scenario``, or solve it (and cache it when ``use_cache``).

    Raises :class:`~a2cm_phys.solve.TooLargeError` or
    :class:`~a2cm_phys.solve.UnsupportedError` for games it will not solve.
    """
    model = GridModel(scenario)
    path = Path(cache_dir or default_cache_dir()) / f"{cache_key(scenario)}.npz"
    if use_cache and path.is_file():
        sol = _load(path, model)
        if sol is not None:
            return sol
    started = time.perf_counter()
    tracing = not tracemalloc.is_tracing()
    if tracing:
        tracemalloc.start()
    try:
        dp = solve_dp(model)
        chain = policy_chain(model, dp.policy)
        check = evaluate_policy(chain, chain.reward, skip=dp.lose)
        steps = evaluate_policy(chain, np.ones(model.n_states), skip=dp.lose)
        if dp.lose is not None:
            steps[dp.lose] = np.inf
        collisions = evaluate_policy(chain, chain.collisions, skip=dp.lose)
        peak = tracemalloc.get_traced_memory()[1] if tracing else None
    finally:
        if tracing:
            tracemalloc.stop()
    ok = model.valid() & np.isfinite(dp.value)
    meta = {
        "key": cache_key(scenario),
        "scenario": scenario.name,
        "states": model.n_states,
        "joint_actions": model.n_joint,
        "sweeps": dp.sweeps,
        "qualitative_sweeps": dp.qualitative_sweeps,
        "residual": dp.residual,
        "policy_check": float(np.max(np.abs(check[ok] - dp.value[ok]), initial=0.0)),
        "losing_states": int(0 if dp.lose is None else (dp.lose & model.valid()).sum()),
        "dp_seconds": dp.seconds,
        "seconds": time.perf_counter() - started,
        "peak_bytes": peak,
    }
    sol = OracleSolution(
        scenario, dp.value, dp.policy, steps, collisions, dp.lose, meta, path, built=model
    )
    if use_cache:
        try:
            _save(path, sol)
        except OSError as err:
            print(f"oracle: warning: cannot write cache {path}: {err.strerror}", file=sys.stderr)
            sol.path = None
    else:
        sol.path = None
    return sol


class OraclePolicy:
    """The optimal joint policy of a grid scenario, acting on global observations.

    ``scenario`` is a :class:`Scenario` or a scenario name/path; the solution is loaded from
    the cache or solved on construction (see :func:`load_or_solve`).
    """

    def __init__(
        self,
        scenario: Scenario | str | Path,
        cache_dir: str | Path | None = None,
        solution: OracleSolution | None = None,
    ) -> None:
        self.scenario = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
        self.solution = solution or load_or_solve(self.scenario, cache_dir)

    def positions(self, obs: np.ndarray) -> np.ndarray:
        """Integer cells ``(B, N + 1, 2)`` decoded from observations ``(B, obs_dim)``."""
        obs = np.asarray(obs, dtype=np.float64)
        n, size = self.scenario.pursuers, self.scenario.size
        return np.rint(obs.reshape(len(obs), n + 1, 2) * (size - 1)).astype(np.int64)

    def act(self, obs: np.ndarray) -> np.ndarray:
        """Optimal actions ``(B, N)`` int64 for observations ``(B, obs_dim)`` float32."""
        return self.solution.actions(self.positions(obs))

    def expected_capture_steps(self, positions: np.ndarray) -> float | np.ndarray:
        """See :meth:`OracleSolution.expected_capture_steps`."""
        return self.solution.expected_capture_steps(positions)


# --------------------------------------------------------------------------- command


def _report(sol: OracleSolution) -> str:
    sc, meta = sol.scenario, sol.meta
    start = sol.start_positions()
    dist = sol.distribution()
    cells = " ".join(f"({x},{y})" for x, y in start[:-1])
    state = "loaded from" if sol.cached else ("saved to" if sol.path else "not cached")
    peak = meta.get("peak_bytes")
    lines = [
        f"oracle: {sc.name}: {sc.size}x{sc.size} grid, {sc.pursuers} pursuer(s), "
        f"{sc.actions} actions, {sc.evader} evader, collisions {sc.collisions.mode}",
        f"  solve: {meta['states']:,} joint states x {meta['joint_actions']} joint actions, "
        f"{meta['sweeps']} sweeps (+{meta['qualitative_sweeps']} reachability), residual "
        f"{meta['residual']:.1e}, {meta['seconds']:.1f} s"
        + (f", peak {peak / 2**20:.0f} MiB" if peak else ""),
        f"  check: greedy policy replayed through GridRules.apply matches the optimum to "
        f"{meta['policy_check']:.1e}",
        f"  cache: {state} {sol.path}" if sol.path else f"  cache: {state}",
    ]
    if meta["losing_states"]:
        lines.append(f"  {meta['losing_states']:,} states from which capture cannot be forced")
    lines += [
        f"  start: pursuers {cells}, evader ({start[-1][0]},{start[-1][1]})",
        f"  optimal expected return: {sol.optimal_return(start):.6f}",
        f"  expected steps to capture: {sol.expected_capture_steps(start):.6f}",
    ]
    if not np.isfinite(sol.optimal_return(start)):
        lines.append("  capture cannot be forced from the start: no finite optimum")
        return "\n".join(lines)
    if sc.collisions.mode != "off":
        lines.append(
            f"  P(capture) {dist.p_capture:.6f}, P(ended by collision) "
            f"{dist.collision.sum():.2e}, expected collisions "
            f"{float(sol.collisions[sol.index(start)]):.2e}"
        )
    median, p95 = dist.quantile(0.5), dist.quantile(0.95)
    lines.append(
        f"  capture steps: mean {dist.mean_length():.6f}, median {median:g}, p95 {p95:g}, "
        f"p99 {dist.quantile(0.99):g}, P(truncated at {sc.max_steps}) {dist.truncated:.1e}"
    )
    top = int(min(dist.quantile(0.999), 20)) if np.isfinite(dist.quantile(0.999)) else 20
    cdf = ", ".join(f"{k}: {dist.cdf(k):.4f}" for k in range(1, top + 1))
    lines.append(f"  P(capture <= k): {cdf}")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """Solve (or load) a grid scenario's optimum and print its statistics; exit code."""
    return run_cli(_main, argv)


def _main(argv: Sequence[str]) -> int:
    parser = Parser(
        prog="python -m a2cm_phys.oracle",
        description="Exact optimal pursuit policy of a grid scenario (value iteration).",
    )
    add_scenario_options(parser, default="grid", train=False)
    parser.add_argument("--cache-dir", type=Path, default=None, help="cache directory")
    parser.add_argument("--no-cache", action="store_true", help="neither read nor write cache")
    args = parser.parse_args(argv)
    scenario = scenario_from_args(args, train=False)
    if args.cache_dir is not None and not args.no_cache:
        writable_dir(args.cache_dir, "--cache-dir")
    try:
        sol = load_or_solve(scenario, args.cache_dir, use_cache=not args.no_cache)
    except (TooLargeError, UnsupportedError) as err:
        raise UsageError(str(err)) from None
    print(_report(sol))
    return 0


if __name__ == "__main__":
    sys.exit(main())
