"""Configuration: the scenario and the training settings as frozen, typed dataclasses;
loading them from TOML, presets and ``--set``; and their resolution, done once.

The rooms, in the order a config passes through them: :mod:`.parse` (building a
dataclass from plain data, every error naming its source and key), :mod:`.scenario` and
:mod:`.train` (the dataclasses), :mod:`.load` (files, overrides, stored runs) and
:mod:`.resolve` (a run's settings completed for its scenario and checked, once, before
anything is built). This face names what the rest of the package uses.
"""

from __future__ import annotations

from .load import (
    SCENARIO_DIR,
    STORED_BEFORE,
    load_scenario,
    load_train,
    read_toml,
    resolve_scenario_path,
    scenario_names,
    stored_train,
)
from .parse import (
    ConfigError,
    InvalidKey,
    build,
    check_limits,
    merge_overrides,
    parse_assignments,
    to_dict,
)
from .resolve import (
    CONTROL_DEFAULTS,
    ENTROPY,
    FLEE_DEFAULTS,
    GRID_DEFAULTS,
    MAX_WEIGHTS,
    SHAPING_KEYS,
    WIDE_DEFAULTS,
    check_network_size,
    check_train,
    entropy_game,
    network_inputs,
    network_weights,
    resolve_train,
    step_cost,
)
from .scenario import (
    DEFAULT_DT,
    SCENARIO_LIMITS,
    SCRIPTED_EVADERS,
    CollisionMode,
    Collisions,
    Control,
    EvaderPolicy,
    EvaderReward,
    Mode,
    Physics,
    Rewards,
    Scenario,
    Sensing,
)
from .train import (
    PRESETS,
    TRAIN_LIMITS,
    Algo,
    DescentTeams,
    Encoding,
    Optimizer,
    Schedule,
    Train,
    matching_preset,
    preset,
)

__all__ = [
    "CONTROL_DEFAULTS",
    "DEFAULT_DT",
    "ENTROPY",
    "FLEE_DEFAULTS",
    "GRID_DEFAULTS",
    "MAX_WEIGHTS",
    "PRESETS",
    "SCENARIO_DIR",
    "SCENARIO_LIMITS",
    "SCRIPTED_EVADERS",
    "SHAPING_KEYS",
    "STORED_BEFORE",
    "TRAIN_LIMITS",
    "WIDE_DEFAULTS",
    "Algo",
    "CollisionMode",
    "Collisions",
    "ConfigError",
    "Control",
    "DescentTeams",
    "Encoding",
    "EvaderPolicy",
    "EvaderReward",
    "InvalidKey",
    "Mode",
    "Optimizer",
    "Physics",
    "Rewards",
    "Scenario",
    "Schedule",
    "Sensing",
    "Train",
    "build",
    "check_limits",
    "check_network_size",
    "check_train",
    "entropy_game",
    "load_scenario",
    "load_train",
    "matching_preset",
    "merge_overrides",
    "network_inputs",
    "network_weights",
    "parse_assignments",
    "preset",
    "read_toml",
    "resolve_scenario_path",
    "resolve_train",
    "scenario_names",
    "step_cost",
    "stored_train",
    "to_dict",
]
