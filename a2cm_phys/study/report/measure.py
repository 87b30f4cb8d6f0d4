"""What each finished run of the report is worth, and the references beside it.

Greedy evaluations, references and exact exploitability take seconds to minutes, so each
is cached as JSON: a run's beside it (``report_eval.json``, ``report_exploit.json``), the
references and the cross-play table in the log folder (``report_cache.json``), keyed by
everything they depend on; re-running the report recomputes nothing that is there.

A run's figures come from its learning curve thinned to a few hundred points, cached with
its training tallies: once measured, a finished run is reported from these small files
alone (its log and checkpoints may be left out of a copy of the report's runs, which is
how the report's runs outlive the machine that trained them).
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import importlib.util
import json
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ...config import Scenario, load_scenario
from ...training.rundir import write_atomic
from .plan import PlannedRun

EVAL_SEED = 10_000
"""Seed of the evaluation episodes (apart from every training seed)."""


def _cache_of(path: Path) -> dict[str, Any]:
    """What the JSON cache ``path`` holds (nothing if it is missing or unreadable)."""
    try:
        return json.loads(path.read_text()) if path.exists() else {}
    except (OSError, ValueError):
        return {}


def _cached(path: Path, key: str, compute: Any) -> Any:
    """``compute()`` unless ``path`` (a JSON object) holds ``key``; stores the result."""
    data = _cache_of(path)
    if key in data:
        return data[key]
    value = compute()
    data[key] = value
    with contextlib.suppress(OSError):
        write_atomic(path, json.dumps(data, separators=(",", ":")) + "\n")  # kept in git: compact
    return value


def _finite(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


@dataclass
class RunResult:
    """The figures of one finished run: training tallies and its greedy evaluation."""

    run: PlannedRun
    episodes: int
    env_steps: int
    late_length: float  # mean episode length over the last 10% of the run's env steps
    late_return: float
    collisions_per_episode: float  # in training
    wall_time: float
    greedy: dict[str, float] = field(default_factory=dict)
    curve: dict[str, list[float]] | None = None  # thinned (run_series.thinned); None: empty

    @property
    def seed(self) -> int:
        """The run's seed."""
        return self.run.spec.seed


def training_figures(run_dir: Path) -> dict[str, float]:
    """Episodes, env steps and the last 10% (by env steps) of a run's log."""
    from ...analysis.run_series import episode_env_steps
    from ...record import read_run

    log = read_run(run_dir)
    steps = episode_env_steps(log)
    lengths = np.asarray(log.episodes["length"], dtype=np.float64)
    returns = np.asarray(log.episodes["return"], dtype=np.float64)
    collisions = np.asarray(log.episodes["collisions"], dtype=np.float64)
    late = steps >= 0.9 * steps.max() if len(steps) else np.zeros(0, dtype=bool)
    return {
        "episodes": len(lengths),
        "env_steps": int(steps.max(initial=0)),
        "late_length": float(lengths[late].mean()) if late.any() else float("nan"),
        "late_return": float(returns[late].mean()) if late.any() else float("nan"),
        "collisions_per_episode": float(collisions.mean()) if len(collisions) else float("nan"),
    }


def training_curve(run_dir: Path) -> dict[str, list[float]] | None:
    """The run's learning curve, thinned (:func:`~a2cm_phys.analysis.run_series.thinned`);
    ``None`` if its log holds no finished episode (a tiny budget) or cannot be read whole."""
    from ...analysis.run_series import load_logged_run, thinned
    from ...record.runlog import LogError

    try:
        return thinned(load_logged_run(run_dir))
    except LogError:
        return None


def greedy_eval(run_dir: Path, episodes: int, scenario: Scenario | None = None) -> dict[str, Any]:
    """The run's pursuers, greedy, over ``episodes`` seeded episodes (a learned evader's
    scenario: against the random evader)."""
    from ...analysis.evaluation import play
    from ...analysis.policies import matchup
    from ...training.runs import load_trained_run

    trained = load_trained_run(run_dir)
    game_scenario = scenario or trained.scenario
    evader = "random" if game_scenario.evader == "learned" else None
    game = matchup(game_scenario, str(run_dir), evader, greedy=True)
    result = play(game.scenario, game.pursuers, episodes, seed=EVAL_SEED, evader=game.evader)
    return _result_dict(result)


def _result_dict(result: Any) -> dict[str, Any]:
    captured = result.captured
    return {
        "length": float(result.lengths.mean()),
        "capture_steps": _finite(result.lengths[captured].mean()) if captured.any() else None,
        "capture_rate": float(captured.mean()),
        "collisions": float(result.collisions.mean()),
        "return": float(result.returns.mean()),
        "lengths": result.lengths.astype(int).tolist(),
    }


def measure(run: PlannedRun, summary: dict[str, Any], eval_episodes: int) -> RunResult:
    """Read a finished run's log and evaluate its final greedy policy (cached)."""
    run_dir = run.run_dir
    stamp = f"{summary.get('updates')}-{summary.get('episodes')}"
    train = _cached(
        run_dir / "report_eval.json", f"train-{stamp}", lambda: training_figures(run_dir)
    )
    greedy = _cached(  # the figures, not each episode's length (the cache is kept in git)
        run_dir / "report_eval.json",
        f"greedy-{stamp}-{eval_episodes}",
        lambda: {k: v for k, v in greedy_eval(run_dir, eval_episodes).items() if k != "lengths"},
    )
    curve = _cached(run_dir / "report_eval.json", f"curve-{stamp}", lambda: training_curve(run_dir))
    greedy.pop("lengths", None)  # caches written before kept them
    return RunResult(
        run=run,
        episodes=int(train["episodes"]),
        env_steps=int(train["env_steps"]),
        late_length=float(train["late_length"]),
        late_return=float(train["late_return"]),
        collisions_per_episode=float(train["collisions_per_episode"]),
        wall_time=float(summary.get("wall_time_s", float("nan"))),
        greedy={k: (float("nan") if v is None else v) for k, v in greedy.items()},
        curve=curve,
    )


PARITY_OBSERVATIONS = 10_000
"""Observations each exported run is checked on (issue 34's figure)."""


def export_parity(run: PlannedRun, observations: int = PARITY_OBSERVATIONS) -> dict | None:
    """The run's actors exported to ONNX (into a temporary folder) against its own on
    ``observations`` observations (:class:`~a2cm_phys.training.export.parity.Parity`'s
    figures), cached beside the run; ``None`` where it cannot be measured: no checkpoint
    (a copy of the report's runs keeps few) and nothing cached, or onnx not installed."""
    path = run.run_dir / "report_eval.json"
    key = f"parity-{observations}"
    cached = _cache_of(path)
    if key in cached:
        return cached[key]
    ready = all(importlib.util.find_spec(m) for m in ("onnx", "onnxruntime"))
    if not ready or not (run.run_dir / "checkpoint.pt").exists():
        return None

    def compute() -> dict[str, Any]:
        from ...deploy.spec import DeployError
        from ...training.export import export_run

        with tempfile.TemporaryDirectory() as folder:
            try:
                done = export_run(run.run_dir, Path(folder) / "team", check=observations)
            except DeployError as err:  # the exported actors differ: a finding, kept
                return {"observations": observations, "error": str(err)}
        return dataclasses.asdict(done.parity)

    return _cached(path, key, compute)


# --------------------------------------------------------------------------- references


def reference(
    scenario_name: str, overrides: dict[str, Any], episodes: int, cache: Path
) -> dict[str, Any] | None:
    """The reference of a scenario (:func:`~a2cm_phys.analysis.evaluation.reference_of`):
    the exact optimum on grids (``exact``), else the oracle driven in physics (discrete
    control) or ``pursuit`` (continuous), played over ``episodes`` episodes with their
    figures; ``None`` if there is none."""
    scenario = load_scenario(scenario_name, overrides)
    key = json.dumps(["reference", scenario_name, overrides, episodes], sort_keys=True)

    def compute() -> dict[str, Any] | None:
        from ...analysis.evaluation import reference_of

        ref = reference_of(scenario, episodes=episodes, seed=EVAL_SEED)
        if ref is None or ref.unavailable is not None:
            return None
        if ref.exact:
            return {"policy": ref.label, "exact": True, **ref.optimum, "length": ref.length}
        return {"policy": ref.label, "exact": False, **_result_dict(ref.played)}

    return _cached(cache, key, compute)


# --------------------------------------------------------------------------- self-play


def exploit(run: PlannedRun, horizon: int | None) -> dict[str, Any]:
    """Exact exploitability of a grid self-play run's final actors (cached): the evader's
    best response to its pursuers (their worst-case capture time) and the pursuers' best
    response to its evader, over ``horizon`` steps (``None``: the scenario's max_steps;
    shorter is a truncated, lower value, ``truncated`` says so)."""
    from ...training.exploitability import exploitability
    from ...training.runs import load_trained_run

    trained = load_trained_run(played_actors(run.run_dir))
    full = trained.scenario.max_steps
    h = min(horizon or full, full)

    def compute() -> dict[str, Any]:
        start = time.perf_counter()
        game = dataclasses.replace(trained.scenario, max_steps=h)
        values = exploitability(game, trained.pursuers, trained.evader)
        return {**values, "horizon": h, "truncated": h < full,
                "seconds": time.perf_counter() - start}  # fmt: skip

    return _cached(run.run_dir / "report_exploit.json", f"h{h}", compute)


def _grid_game(scenario_name: str, horizon: int | None) -> tuple[Scenario, int, bool]:
    """The grid game the solvers play for a scenario (its grid twin, :func:`grid_twin`)
    truncated at ``horizon`` (``None``: its ``max_steps``), the horizon, and whether it
    truncates."""
    from ...analysis.policies import grid_twin

    scenario = load_scenario(scenario_name)
    h = min(horizon or scenario.max_steps, scenario.max_steps)
    return dataclasses.replace(grid_twin(scenario), max_steps=h), h, h < scenario.max_steps


def oracle_worst_case(scenario_name: str, horizon: int | None, cache: Path) -> dict[str, Any]:
    """The worst case of the oracle that is optimal against the random evader (exact)."""
    twin, h, truncated = _grid_game(scenario_name, horizon)
    key = json.dumps(["oracle-worst-case", scenario_name, h])

    def compute() -> dict[str, Any]:
        from ...analysis.sources import pursuer_source
        from ...solve.best_response import evader_best_response

        table = pursuer_source(twin, "oracle").table
        value = evader_best_response(twin, table).value_from_start
        return {"exploit_worst_case": float(value), "horizon": h, "truncated": truncated}

    return _cached(cache, key, compute)


def minimax_bounds(scenario_name: str, horizon: int | None, cache: Path) -> dict[str, Any]:
    """The bounds on the game's minimax capture time and the minimax team's worst case
    (exact, :mod:`a2cm_phys.solve.minimax`): ``{"lower", "upper", "horizon"}``."""
    twin, h, _ = _grid_game(scenario_name, horizon)
    key = json.dumps(["minimax-bounds", scenario_name, h])

    def compute() -> dict[str, Any]:
        from ...solve.minimax import minimax_bounds as solve

        bounds = solve(twin)
        return {"lower": bounds.lower_from_start, "upper": bounds.upper_from_start, "horizon": h}

    return _cached(cache, key, compute)


def game_value_bracket(scenario_name: str, horizon: int | None, cache: Path) -> dict[str, Any]:
    """The game's value with mixed strategies, bracketed by the equilibrium evader's and the
    equilibrium team's exact worst cases (:func:`a2cm_phys.solve.nash.game_value`, as
    ``oracle --game-value``): ``{"lower", "upper", "horizon"}``. Minutes and a few GiB the
    first time; then from the report's cache (and the oracle's)."""
    twin, h, _ = _grid_game(scenario_name, horizon)
    key = json.dumps(["game-value", scenario_name, h])

    def compute() -> dict[str, Any]:
        from ...solve.cache import load_or_solve_value

        value = load_or_solve_value(twin, progress=True)
        return {"lower": value.lower, "upper": value.upper, "horizon": h}

    return _cached(cache, key, compute)


ACTORS_FILE = "report_actors.pt"
"""The checkpoint the cross-play plays a run from: the run's own without what only its
training reads (a descent run's value tables, 7 MB of its 7.7; a self-play run's pool of
past opponents), so that the repository keeps the report's teams at a tenth of the size
(``.gitignore``)."""


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()[:16]


def played_actors(run_dir: Path) -> str:
    """The file the cross-play loads the run from: :data:`ACTORS_FILE`, made from the run's
    checkpoint when it is missing or was made from another one; the run directory itself
    when there is neither (the cross-play then names what is missing)."""
    from ...training import checkpoint

    actors, full = run_dir / ACTORS_FILE, run_dir / checkpoint.CHECKPOINT_NAME
    if full.is_file():
        digest = _digest(full)
        if not actors.is_file() or checkpoint.load(actors).get("made_from") != digest:
            state = checkpoint.load(full)
            slim = {**state, "descent": None, "pool": None, "made_from": digest}
            checkpoint.write(actors, slim)
    return str(actors) if actors.is_file() else str(run_dir)


def _stamped(pair: tuple[str, str]) -> list[str]:
    """A pairing's cache identity: each run's file (:func:`played_actors`) with a digest of
    it, so that a run trained again in the same directory is measured again, and a copy of
    the same run (a clone of the report's runs: new modification times) is not."""
    return [f"{spec}@{_digest(Path(spec))}" if Path(spec).is_file() else spec for spec in pair]


def cross_play(
    scenario_name: str,
    pursuers: dict[str, list[str]],
    evaders: dict[str, list[str]],
    episodes: int,
    cache: Path,
) -> list[dict[str, Any]]:
    """Mean episode length (capped at max_steps) and capture rate of every pursuer group
    against every evader group; groups are lists of run directories (seeds, paired by
    index when both sides are learned) or one named policy. Sampled policies, as trained."""
    from ...analysis.evaluation import play
    from ...analysis.policies import matchup

    scenario = load_scenario(scenario_name)
    rows = []
    for p_label, p_list in pursuers.items():
        for e_label, e_list in evaders.items():
            if len(p_list) > 1 and len(e_list) > 1:
                pairs = list(zip(p_list, e_list, strict=False))
            else:
                pairs = [(p, e) for p in p_list for e in e_list]
            key = json.dumps(["cross", scenario_name, [_stamped(p) for p in pairs], episodes])

            def compute(pairs: list[tuple[str, str]] = pairs) -> list[dict[str, float]]:
                out = []
                for p, e in pairs:
                    game = matchup(scenario, p, e)
                    r = play(game.scenario, game.pursuers, episodes, seed=EVAL_SEED,
                             evader=game.evader)  # fmt: skip
                    out.append({"length": float(r.lengths.mean()),
                                "capture_rate": float(r.captured.mean())})  # fmt: skip
                return out

            results = _cached(cache, key, compute)
            rows.append({"pursuers": p_label, "evader": e_label, "pairs": len(pairs),
                         "results": results})  # fmt: skip
    return rows
