"""A trained run, read back: what it is (:func:`run_identity`: scenario, algorithm, preset,
and its label in plots, :func:`run_label`), the pursuers' (and a learned evader's) models
from its checkpoint, and a model as a rollout policy. Every command that plays a run's
policies (``evaluate``, ``oracle``, the report) or labels it (``plot``) reads runs here.

What a run is comes from its ``config.json`` alone (no torch): reading a label is cheap.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..config import ConfigError, Scenario, build, load_train, matching_preset, stored_train
from .rundir import CHECKPOINT_NAME, CONFIG_NAME

if TYPE_CHECKING:
    from ..algos import ActorCritic
    from .rollout import Policy


@dataclass(frozen=True)
class RunIdentity:
    """What a run is, for labels: its scenario's name, its algorithm and its preset."""

    scenario: str
    algo: str
    preset: str | None

    @property
    def label(self) -> str:
        """``A2CM``, or ``A2CM (paper)`` for a run of a preset."""
        algo = self.algo.upper()
        return f"{algo} ({self.preset})" if self.preset else algo


def run_identity(run_dir: str | Path) -> RunIdentity:
    """The scenario, algorithm and preset of a run directory (or of the folder of a file
    in it), from its ``config.json``, else from its checkpoint. A run written before the
    preset was recorded counts as the preset whose every value its training config holds
    (:func:`~a2cm_phys.config.matching_preset`). A :class:`ConfigError` naming the folder
    if it holds no run."""
    path = Path(run_dir)
    folder = path if path.is_dir() else path.parent
    config = _stored_run_config(folder)
    scenario, train = config.get("scenario"), config.get("train")
    if not isinstance(scenario, dict) or not isinstance(train, dict):
        raise ConfigError(f"{folder}: holds no scenario and train configuration")
    train = stored_train(train)
    if "preset" in config:
        preset = config["preset"] if isinstance(config["preset"], str) else None
    else:
        preset = matching_preset(train)
    return RunIdentity(str(scenario.get("name", folder.name)), str(train["algo"]), preset)


def run_label(run_dir: str | Path) -> str:
    """A run's label in plots and tables: ``A2CM``, or ``A2CM (paper)`` for a run of the
    paper preset (:func:`run_identity`)."""
    return run_identity(run_dir).label


def run_preset(run_dir: str | Path) -> str | None:
    """The preset a run was trained from (its name), or ``None`` (:func:`run_identity`)."""
    return run_identity(run_dir).preset


def _stored_run_config(folder: Path) -> dict[str, Any]:
    """The run's ``config.json``, else its checkpoint's scenario and training config."""
    path = folder / CONFIG_NAME
    if path.is_file():
        try:
            config = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError) as err:
            raise ConfigError(f"{path}: unreadable ({err})") from None
        if isinstance(config, dict):
            return config
        raise ConfigError(f"{path}: holds no scenario and train configuration")
    if not (folder / CHECKPOINT_NAME).is_file():
        raise ConfigError(f"{folder}: not a run directory (no {CONFIG_NAME}, no checkpoint)")
    from . import checkpoint

    try:
        state = checkpoint.load(folder)
    except (OSError, ValueError) as err:
        raise ConfigError(str(err)) from None
    return {"scenario": state["scenario"], "train": state["train"]}


@dataclass(frozen=True)
class TrainedRun:
    """The scenario and trained models of a run: the pursuers', and a learned evader's."""

    scenario: Scenario
    pursuers: ActorCritic
    evader: ActorCritic | None


def load_trained_run(path: str | Path) -> TrainedRun:
    """The trained models of a run directory or checkpoint file (a :class:`ConfigError`
    naming the path if it is not one)."""
    from ..algos import make_model
    from . import checkpoint
    from .teams import evader_train_cfg

    try:
        state = checkpoint.load(path)
    except (OSError, ValueError) as err:
        raise ConfigError(str(err)) from None
    scenario = build(Scenario, state["scenario"], f"{path} (checkpoint)")
    cfg = load_train({**stored_train(state["train"]), "device": "cpu"}, f"{path} (checkpoint)")
    pursuers = make_model(cfg, scenario)
    pursuers.load_state_dict(state["learner"]["model"])
    evader = None
    if state.get("evader_learner") is not None:
        evader = make_model(evader_train_cfg(cfg), scenario, n_agents=1)
        evader.load_state_dict(state["evader_learner"]["model"])
    return TrainedRun(scenario, pursuers, evader)


def load_trained(path: str | Path) -> tuple[Scenario, ActorCritic]:
    """The scenario and trained pursuers of a run directory or checkpoint file."""
    run = load_trained_run(path)
    return run.scenario, run.pursuers


def load_trained_evader(path: str | Path) -> tuple[Scenario, ActorCritic]:
    """The scenario and trained (learned) evader of a self-play run."""
    run = load_trained_run(path)
    if run.evader is None:
        raise ConfigError(f"{path}: the run has no learned evader")
    return run.scenario, run.evader


def model_policy(model: ActorCritic, greedy: bool = False) -> Policy:
    """The actors of ``model`` as a rollout policy (sampled, or the most probable action);
    recurrent actors' keeps their memory between calls (give each rollout its own)."""
    if getattr(model, "recurrent", False):  # a table policy (solve.tables) has no memory
        return model.rollout_policy(greedy)
    return lambda obs, rng: model.act(obs, rng, greedy=greedy)
