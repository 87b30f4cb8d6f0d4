"""The exact solutions' cache: the oracle's optimal policy per scenario and the game's
value, solved once and kept in ``$XDG_CACHE_HOME/a2cm_phys/oracle`` (by default
``~/.cache/a2cm_phys/oracle``), keyed by a hash of the scenario fields that define the game.
``python -m a2cm_phys.oracle`` is the command over it."""

from __future__ import annotations

import hashlib
import json
import os
import sys
import time
import tracemalloc
import zipfile
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..config import Scenario
from ..envs.core import default_start
from . import GridModel, capture_distribution, evaluate_policy, policy_chain, solve_dp
from .policy_chain import CaptureDistribution, PolicyChain
from .symmetric import EVADERS, SymmetricResult, solve_symmetric
from .tables import start_law, state_index
from .transitions import TooLargeError

if TYPE_CHECKING:  # the solver imports torch: only when the game's value is asked for
    from .nash import GameValue


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
    return _hash(scenario, fields)


def _hash(scenario: Scenario, fields: dict) -> str:
    """The key of ``fields``, with the cells the obstacles block (sorted indices) when
    there are any, so that the keys of arenas without obstacles are those of before."""
    if scenario.obstacles:
        fields = {**fields, "blocked": np.flatnonzero(scenario.blocked_cells()).tolist()}
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
        return state_index(self.scenario, positions)

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

    @cached_property
    def start_law(self) -> tuple[np.ndarray, np.ndarray]:
        """The scenario's start distribution: states and probabilities (:func:`start_law`)."""
        return start_law(self.scenario)

    @property
    def start_steps(self) -> float:
        """Expected steps to the episode's end, playing optimally, over the start
        distribution (exactly: every start enumerated)."""
        idx, p = self.start_law
        return float(p @ self.steps[idx])

    @property
    def start_value(self) -> float:
        """Optimal expected return over the start distribution."""
        idx, p = self.start_law
        return float(p @ self.value[idx])

    def distribution(self, positions: np.ndarray | None = None) -> CaptureDistribution:
        """Exact law of the episode's end under the optimal policy, from ``positions``
        (default: over the scenario's start distribution)."""
        start = self.start_law if positions is None else int(self.index(np.asarray(positions)))
        return capture_distribution(self.chain, start, self.scenario.max_steps)


def _write_npz(path: Path, **arrays: np.ndarray) -> None:
    """Write ``arrays`` to ``path`` atomically: a concurrent reader never sees half a file."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    with open(tmp, "wb") as fh:  # a file handle: np.savez would append ".npz" to the name
        np.savez_compressed(fh, **arrays)
    os.replace(tmp, path)


def _save(path: Path, sol: OracleSolution) -> None:
    lose = np.zeros(0, dtype=bool) if sol.lose is None else sol.lose
    _write_npz(
        path, value=sol.value, policy=sol.policy, steps=sol.steps,
        collisions=sol.collisions, lose=lose, meta=np.array(json.dumps(sol.meta)),
    )  # fmt: skip


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
    scenario: Scenario,
    cache_dir: str | Path | None = None,
    use_cache: bool = True,
    progress: bool = False,
) -> OracleSolution:
    """The cached solution of ``scenario``, or solve it (and cache it when ``use_cache``;
    ``progress``: report the value iteration on stderr).

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
        dp = solve_dp(model, progress=progress)
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


def load_or_solve_optimum(
    scenario: Scenario,
    cache_dir: str | Path | None = None,
    use_cache: bool = True,
    progress: bool = False,
) -> OracleSolution | SymmetricResult:
    """The optimum of ``scenario``: :func:`load_or_solve`'s where the dense solver holds
    the arena, else (random and static evaders) the symmetric solver's
    (:mod:`.symmetric`, up to 13x13 with 3 pursuers), cached as ``<key>-symmetric.npz``.
    Both answer ``actions``, ``expected_capture_steps``, ``optimal_return``,
    ``start_positions`` and ``distribution``. Raises what the solvers raise: the symmetric
    solver's limit where it is tried, else the dense one's."""
    try:
        return load_or_solve(scenario, cache_dir, use_cache, progress)
    except TooLargeError:
        if scenario.evader not in EVADERS:
            raise
    path = Path(cache_dir or default_cache_dir()) / f"{cache_key(scenario)}-symmetric.npz"
    if use_cache and path.is_file():
        try:
            with np.load(path, allow_pickle=False) as data:
                return SymmetricResult.from_arrays(scenario, data)
        except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
            pass  # unreadable or stale: solve again and overwrite it
    sol = solve_symmetric(scenario, progress=progress)
    if use_cache:
        try:
            _write_npz(path, **sol.to_arrays())
        except OSError as err:
            print(f"oracle: warning: cannot write cache {path}: {err.strerror}", file=sys.stderr)
    return sol


VALUE_SOLVER_VERSION = 1
"""Bumped whenever a change of :mod:`.solve.nash` invalidates cached game values."""


def value_cache_key(scenario: Scenario) -> str:
    """Hash of the scenario fields that define the game's value: the rules and the horizon
    (not the rewards, nor the evader, whose policy the value is over)."""
    fields = {
        "solver": "game-value",
        "version": VALUE_SOLVER_VERSION,
        "size": scenario.size,
        "pursuers": scenario.pursuers,
        "actions": scenario.actions,
        "collisions": scenario.collisions.mode,
        "max_steps": scenario.max_steps,
    }
    return _hash(scenario, fields)


def _value_path(scenario: Scenario, cache_dir: str | Path | None) -> Path:
    return Path(cache_dir or default_cache_dir()) / f"{value_cache_key(scenario)}-value.npz"


def cached_value(scenario: Scenario, cache_dir: str | Path | None = None) -> GameValue | None:
    """The game's value from the cache (:func:`load_or_solve_value`), or ``None``."""
    path = _value_path(scenario, cache_dir)
    return _load_value(path, scenario) if path.is_file() else None


def load_or_solve_value(
    scenario: Scenario,
    cache_dir: str | Path | None = None,
    use_cache: bool = True,
    progress: bool = False,
) -> GameValue:
    """The game's value bracketed (:func:`~a2cm_phys.solve.nash.game_value`), from the
    cache beside the oracle's or solved (minutes; cached when ``use_cache``; ``progress``:
    report the solve on stderr). A cached value has no ``team`` (100 MB the bracket does
    not need). Raises the solver's TooLargeError or UnsupportedError."""
    value = cached_value(scenario, cache_dir) if use_cache else None
    if value is not None:
        return value
    from .nash import game_value

    value = game_value(scenario, progress=progress)
    if use_cache:
        path = _value_path(scenario, cache_dir)
        meta = {"key": value_cache_key(scenario), "start": value.start}
        meta.update(sweeps=value.sweeps, seconds=value.seconds)
        try:
            _write_npz(
                path, lower=np.array(value.lower), upper=np.array(value.upper),
                estimate=value.estimate, evader=value.evader, meta=np.array(json.dumps(meta)),
            )  # fmt: skip
        except OSError as err:
            print(f"oracle: warning: cannot write cache {path}: {err.strerror}", file=sys.stderr)
    return value


def _load_value(path: Path, scenario: Scenario) -> GameValue | None:
    from .nash import GameValue
    from .tables import n_states

    try:
        with np.load(path, allow_pickle=False) as data:
            meta = json.loads(str(data["meta"]))
            evader = data["evader"]
            if meta.get("key") != value_cache_key(scenario) or len(evader) != n_states(scenario):
                return None
            return GameValue(
                float(data["lower"]), float(data["upper"]), data["estimate"], evader, None,
                int(meta["start"]), int(meta["sweeps"]), float(meta["seconds"]), cached=True,
            )  # fmt: skip
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
        return None  # unreadable or stale: solve again and overwrite it
