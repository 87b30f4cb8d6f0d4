"""A trained run, read back: its scenario and the pursuers' (and a learned evader's)
models from its checkpoint, and a model as a rollout policy. Every command that plays a
run's policies (``evaluate``, ``oracle``, the report) reads runs here."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ..algos import ActorCritic, make_model
from ..config import ConfigError, Scenario, build, load_train, stored_train
from . import checkpoint
from .rollout import Policy
from .teams import evader_train_cfg


@dataclass(frozen=True)
class TrainedRun:
    """The scenario and trained models of a run: the pursuers', and a learned evader's."""

    scenario: Scenario
    pursuers: ActorCritic
    evader: ActorCritic | None


def load_trained_run(path: str | Path) -> TrainedRun:
    """The trained models of a run directory or checkpoint file (a :class:`ConfigError`
    naming the path if it is not one)."""
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
    """The actors of ``model`` as a rollout policy (sampled, or the most probable action)."""
    return lambda obs, rng: model.act(obs, rng, greedy=greedy)
