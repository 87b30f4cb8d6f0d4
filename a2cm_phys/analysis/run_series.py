"""A run's per-episode series, read from its log alone (what :mod:`.figures` draws).

A run folder's log parts are read as one run, each episode once
(:mod:`a2cm_phys.record.parts`); a damaged or empty log is an error, not an empty series
(:func:`load_logged_run`). Each episode is placed on the run's environment steps
(:func:`episode_env_steps`), its return split into its time and collision parts
(:func:`return_parts`), and the exact exploitability a run logged every K updates is kept
beside its episodes (:data:`EXPLOIT_SERIES`). A run is labelled as :func:`run_label_of`
says: ``A2CM``, or ``A2CM (paper)`` for a run of a preset.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..config import Scenario
from ..record.parts import read_run
from ..record.runlog import LogError, RunLog

EXPLOIT_SERIES = (
    ("exploit_worst_case", "evader's best response (pursuers' worst case)", "-"),
    ("exploit_pursuers_br", "pursuers' best response to the learned evader", "--"),
    ("descent_value", "best response the descent trains against (discounted)", ":"),
    ("evader_descent_value", "pursuers' best response the evader's descent meets", "-."),
)
"""(update metric, legend text, line style) of the exploitability figure."""


@dataclass
class Run:
    """One run's per-episode series, read from its log(s)."""

    label: str
    title: str
    columns: dict[str, np.ndarray]
    clean: bool
    exploit: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    """Sparse update metrics of :data:`EXPLOIT_SERIES`: ``(env_steps, values)`` where logged."""
    scenario: Scenario | None = None
    """The run's resolved scenario (from its log's metadata)."""
    problems: list[str] = field(default_factory=list)
    """Parts of its log that could not be read though no episode is missing (to report)."""


def log_files(path: Path) -> list[Path]:
    """The log files of a run: ``path`` itself, or a run folder's parts in session order."""
    from ..record.parts import part_files

    if path.is_dir():
        files = part_files(path)
        if not files:
            raise LogError(f"{path}: no episodes.mcap in this folder")
        return files
    if not path.exists():
        raise LogError(f"{path}: no such file or folder")
    return [path]


def load_logged_run(path: Path) -> Run:
    """Read a run (every part of a run folder's log, each episode once) or one log file.

    A :class:`LogError` if the log is damaged, misses episodes or holds no finished
    episode: a figure of nothing, or of a silently shortened run, would mislead. A part that
    cannot be read while every episode is still there (a later part holds them) is named in
    :attr:`Run.problems`.
    """
    if not path.exists():
        raise LogError(f"{path}: no such file or folder")
    log = read_run(path)
    if log.damaged:
        raise LogError(f"{path}: the log is damaged ({log.error}); see python -m a2cm_phys.replay")
    if not log.n_episodes:
        raise LogError(f"{path}: the log holds no finished episode")
    ids = log.episodes["episode"]
    if log.problems and not np.array_equal(ids, np.arange(len(ids))):
        raise LogError(f"{path}: episodes are missing ({'; '.join(log.problems)})")
    columns = {k: log.episodes[k] for k in ("return", "length", "collisions", "captured")}
    columns["env_steps"] = episode_env_steps(log)
    sc = log.scenario
    columns["time"], columns["collision_part"] = return_parts(sc, columns)
    title = f"{sc.name} ({sc.mode}, collisions {sc.collisions.mode}, {sc.evader} evader)"
    return Run(
        label=run_label_of(path, log),
        title=title,
        columns=columns,
        clean=log.clean,
        exploit=_exploit(log),
        scenario=sc,
        problems=list(log.problems),
    )


CURVE_BINS = 400
"""Env-step bins of a :func:`thinned` series: ~7 per bin of a 60-bin figure."""

CURVE_COLUMNS = ("length", "return", "collisions", "captured", "time", "collision_part")
"""The per-episode columns a :func:`thinned` series keeps (their means per bin)."""


def thinned(run: Run, bins: int = CURVE_BINS) -> dict[str, list[float]]:
    """``run``'s series in ``bins`` equal env-step bins: each non-empty bin's last env step
    (``env_steps``), its number of episodes (``episodes``) and their mean of each of
    :data:`CURVE_COLUMNS`; a few kilobytes of JSON, kept beside a run whose log may go.
    :func:`thinned_run` reads it back, and :func:`~.figures.binned` weighs its rows by
    ``episodes``, so that a figure of it matches the full series' to within a bin."""
    x = run.columns["env_steps"].astype(np.float64)
    edges = np.linspace(0.0, max(float(x.max(initial=0)), 1.0), bins + 1)
    idx = np.clip(np.searchsorted(edges, x, side="left") - 1, 0, bins - 1)
    counts = np.bincount(idx, minlength=bins)
    keep = counts > 0
    last = np.zeros(bins)
    np.maximum.at(last, idx, x)
    out = {"env_steps": last[keep], "episodes": counts[keep]}
    for key in CURVE_COLUMNS:
        sums = np.bincount(idx, run.columns[key].astype(np.float64), minlength=bins)
        out[key] = sums[keep] / counts[keep]
    return {k: np.asarray(v).tolist() for k, v in out.items()}


def thinned_run(doc: dict[str, list[float]], label: str, title: str) -> Run:
    """A :class:`Run` of a :func:`thinned` series (one row per bin, weighed by
    ``episodes``)."""
    columns = {k: np.asarray(v, dtype=np.float64) for k, v in doc.items()}
    return Run(label=label, title=title, columns=columns, clean=True)


def run_label_of(path: Path, log: RunLog) -> str:
    """A run's label in plots: the log's own ``label`` if it has one, else the run folder's
    (:func:`~a2cm_phys.training.runs.run_label`: ``A2CM``, ``A2CM (paper)`` for a run of the
    paper preset), else, for a log without its folder's ``config.json``, the algorithm and
    the preset its logged training config matches (:func:`~a2cm_phys.config.matching_preset`).
    """
    from ..config import ConfigError, matching_preset
    from ..training.runs import run_label

    if log.metadata.get("label"):
        return str(log.metadata["label"])
    folder = path if path.is_dir() else path.parent
    if (folder / "config.json").is_file():  # not the checkpoint: that would need torch
        try:
            return run_label(folder)
        except ConfigError:
            pass
    train = log.metadata.get("train")
    preset = matching_preset(train) if isinstance(train, dict) else None
    return f"{log.label} ({preset})" if preset else log.label


def collision_weight(scenario: Scenario) -> float:
    """The return each pursuer collision costs (0 where collisions are off)."""
    return scenario.rewards.collision if scenario.collisions.mode != "off" else 0.0


def penalised(run: Run) -> bool:
    """Whether the run's scenario gives collisions a penalty (a return with a collision part)."""
    return run.scenario is not None and collision_weight(run.scenario) != 0


def return_parts(scenario: Scenario, columns: dict[str, np.ndarray]) -> tuple[np.ndarray, ...]:
    """Each episode's return split into ``(time, collision)``: the collision part is its
    collisions times the collision penalty, the time part the rest (step, capture and wall
    rewards); they sum to the return."""
    collision = columns["collisions"].astype(np.float64) * collision_weight(scenario)
    return columns["return"].astype(np.float64) - collision, collision


def episode_env_steps(log: RunLog) -> np.ndarray:
    """Environment steps of the whole run (all games) when each episode ended.

    The games step together, so an episode that ends at step ``k`` of its game ends after
    about ``k × num_envs`` steps of the run; ``k`` is the sum of the lengths of its game's
    episodes so far (a game restarted on a physics resume loses its unfinished episode).
    """
    lengths = np.asarray(log.episodes["length"], dtype=np.int64)
    games = np.asarray(log.episodes["env"], dtype=np.int64)
    train = log.metadata.get("train")
    num_envs = int(train.get("num_envs", 1)) if isinstance(train, dict) else 1
    num_envs = max(num_envs, int(games.max(initial=-1)) + 1)
    per_game = np.zeros(len(lengths), dtype=np.int64)
    for g in np.unique(games):
        mask = games == g
        per_game[mask] = np.cumsum(lengths[mask])
    return per_game * num_envs


def _exploit(log: RunLog) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Each exploitability metric's ``(env_steps, values)`` over the updates that logged it
    (a finite value; absent, null or NaN elsewhere)."""
    out = {}
    for key, _, _ in EXPLOIT_SERIES:
        pairs = [
            (u["env_steps"], float(u[key]))
            for u in log.updates
            if isinstance(u.get(key), (int, float)) and np.isfinite(u[key])
        ]
        if pairs:
            steps, values = np.array(pairs, dtype=np.float64).T
            out[key] = (steps, values)
    return out
