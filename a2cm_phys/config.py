"""Scenario and training configuration: frozen dataclasses loaded from TOML and validated.

A scenario is data (VMAS-style): the engine owns the loop. Every value that reaches the
engine goes through :func:`build`, whether it came from a TOML file, from ``make_env``
keyword overrides or from ``--set key=value`` on the command line, so the same checks and
the same error messages apply everywhere. Errors are :class:`ConfigError`, whose message
names the source (file) and the dotted key at fault.
"""

from __future__ import annotations

import dataclasses
import math
import os
import types
import typing
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
import tomllib

from .base.errors import UserError

SCENARIO_DIR = Path(__file__).resolve().parent / "scenarios"
"""Folder of the named scenarios, package data of ``a2cm_phys`` (so a wheel has them too);
the checkout's top-level ``scenarios/`` is a symbolic link to it."""

Mode = Literal["grid", "physics"]
EvaderPolicy = Literal["random", "flee", "static", "learned"]  # learned: an agent (SPEC §1b)
EvaderReward = Literal["zero_sum", "survival"]
CollisionMode = Literal["off", "terminate", "penalize"]
Algo = Literal["a2c", "a2cm"]
Control = Literal["discrete", "continuous"]
Optimizer = Literal["rmsprop", "adam"]
Schedule = Literal["constant", "linear"]
Encoding = Literal["xy", "onehot"]
DescentTeams = Literal["pursuers", "both"]

DEFAULT_DT = {"discrete": 1.0, "continuous": 0.1}
"""The control period ``physics.dt`` (s) of each control type when a scenario omits it."""


class ConfigError(UserError, ValueError):
    """A scenario or training setting is wrong; the message names the source and the key."""


@dataclass(frozen=True)
class Rewards:
    """Team reward terms (SPEC §4); the reward is logged raw, learners may scale it.

    ``evader`` is a learned evader's reward (SPEC §1b): ``zero_sum``, minus the team reward,
    or ``survival``, +1 for every step that does not end in its capture (its return is the
    number of steps it survived). Scripted evaders have no reward.
    """

    step: float = -1.0
    collision: float = 0.0
    capture: float = 0.0
    wall: float = 0.0
    evader: EvaderReward = "zero_sum"


@dataclass(frozen=True)
class Collisions:
    """How pursuer–pursuer collisions count: ``off``, ``terminate`` or ``penalize``."""

    mode: CollisionMode = "off"


@dataclass(frozen=True)
class Physics:
    """Physical parameters of physics mode (SPEC §3); one grid cell is one metre."""

    box_side: float = 0.6
    evader_radius: float = 0.3
    mass: float = 1.0
    max_speed: float = 1.0
    dt: float | None = None  # control period (s); None: DEFAULT_DT of the scenario's control
    substeps: int = 10  # fixed solver steps per control period
    wall_thickness: float = 1.0
    max_force: float = 50.0

    def validate(self) -> None:
        """Raise ``ValueError`` naming the key of the first impossible value."""
        for key in (
            "box_side",
            "evader_radius",
            "mass",
            "max_speed",
            "wall_thickness",
            "max_force",
        ):
            if not getattr(self, key) > 0:
                raise _KeyError(f"physics.{key}", f"must be > 0, got {getattr(self, key)!r}")
        if self.box_side >= 1.0:
            raise _KeyError("physics.box_side", f"must be < 1 (one cell), got {self.box_side!r}")
        if self.evader_radius >= 0.5:
            raise _KeyError("physics.evader_radius", f"must be < 0.5, got {self.evader_radius!r}")
        if self.dt is not None and not self.dt > 0:
            raise _KeyError("physics.dt", f"must be > 0, got {self.dt!r}")
        if self.substeps < 1:
            raise _KeyError("physics.substeps", f"must be >= 1, got {self.substeps!r}")

    def check_substeps(self) -> None:
        """Refuse substeps so long that two bodies closing at ``2 × max_speed`` could pass
        through the smallest body in one substep (``2 · max_speed · dt / substeps``)."""
        smallest = min(self.box_side, 2 * self.evader_radius)
        dt = 1.0 if self.dt is None else self.dt
        reach = 2 * self.max_speed * dt / self.substeps
        if reach >= smallest:
            raise _KeyError(
                "physics.substeps",
                f"physics.substeps = {self.substeps} is too few: two agents closing at "
                f"2 × max_speed would move {reach:g} m per substep (dt = {dt:g} s), enough "
                f"to pass through a {smallest:g} m body; use more than "
                f"{int(2 * self.max_speed * dt / smallest)} substeps",
            )


@dataclass(frozen=True)
class Scenario:
    """One pursuit game: arena, agents, evader, time limit, rewards and collision mode."""

    name: str = "custom"
    mode: Mode = "grid"
    size: int = 5
    pursuers: int = 3
    actions: int = 4
    control: Control = "discrete"  # physics mode: "continuous" steers with velocity commands
    evader: EvaderPolicy = "random"
    max_steps: int = 1000
    rewards: Rewards = field(default_factory=Rewards)
    collisions: Collisions = field(default_factory=Collisions)
    physics: Physics = field(default_factory=Physics)

    def __post_init__(self) -> None:
        if self.physics.dt is None:  # the control type decides the default period
            physics = dataclasses.replace(self.physics, dt=DEFAULT_DT.get(self.control, 1.0))
            object.__setattr__(self, "physics", physics)

    def validate(self) -> None:
        """Raise ``ValueError`` naming the key of the first impossible value."""
        check_limits(self, SCENARIO_LIMITS)
        if self.size < 2:
            raise _KeyError("size", f"must be >= 2, got {self.size}")
        border = 4 * (self.size - 1)
        if not 1 <= self.pursuers <= border:
            raise _KeyError(
                "pursuers",
                f"must be between 1 and {border} (the border cells), got {self.pursuers}",
            )
        if self.pursuers + 1 > self.size * self.size:
            raise _KeyError("pursuers", "leave no free cell for the evader")
        if self.actions not in (4, 5):
            raise _KeyError("actions", f"must be 4 (paper) or 5 (adds stay), got {self.actions}")
        if self.max_steps < 1:
            raise _KeyError("max_steps", f"must be >= 1, got {self.max_steps}")
        self.physics.validate()
        if self.mode == "physics":
            self.physics.check_substeps()
        elif self.control != "discrete":
            raise _KeyError(
                "control", f"{self.control!r} needs mode = 'physics' (grid moves are discrete)"
            )

    @property
    def continuous(self) -> bool:
        """Whether pursuers steer with velocity commands (SPEC §3b) rather than discrete moves."""
        return self.control == "continuous"

    @property
    def agents(self) -> list[str]:
        """Names of the learning pursuers, in order."""
        return [f"pursuer_{i}" for i in range(self.pursuers)]

    @property
    def obs_dim(self) -> int:
        """Length of the global observation vector (SPEC §5)."""
        per_agent = 4 if self.mode == "physics" else 2
        return per_agent * (self.pursuers + 1)


@dataclass(frozen=True)
class Train:
    """Training settings (SPEC §6).

    The paper's hyperparameters are kept (RMSprop 7e-3 as Keras has it, γ 0.99, batch 128,
    5,000 updates, 128 hidden units); what is ours, chosen by the ablation in
    ``BENCHMARKS.md`` so that the collision scenarios are learned: 16 games, the reward
    split into its time and collision components, each valued by its own critic output
    under PopArt normalisation and weighed on its own scale (``split_rewards``,
    ``value_norm``, ``balance_rewards``), advantages normalised per batch, a linear
    learning-rate anneal, and with discrete actions an entropy coefficient of 0.03 instead
    of 1e-4, annealed with the learning rate against a scripted evader (:data:`ENTROPY`),
    and in continuous control progress shaping and gradient clipping (:data:`CONTROL_DEFAULTS`),
    with 32-step rollouts and twice the steps against the fleeing evader
    (:data:`FLEE_DEFAULTS`).
    ``--preset paper`` (:data:`PRESETS`) is the paper's exact method.
    Keys left ``None`` take their scenario's value in :func:`resolve_train` (the number of
    updates, for one: continuous control needs 2,000,000 steps, :data:`CONTROL_DEFAULTS`).
    """

    algo: Algo = "a2cm"
    updates: int | None = None  # None: by the control type (CONTROL_DEFAULTS, resolve_train)
    batch_size: int | None = None  # None: 128, or 512 by the game (resolve_train)
    num_envs: int = 16  # ours; the paper played one game (--preset paper, --num-envs 1)
    seed: int = 0
    lr: float = 7e-3
    rmsprop_alpha: float = 0.9
    rmsprop_eps: float = 1e-7
    gamma: float = 0.99
    entropy_coef: float | None = None  # None: by the game (ENTROPY, resolve_train)
    value_coef: float = 0.5
    hidden: int = 128
    layers: int = 1  # hidden layers of every actor and critic (the paper's: 1)
    encoding: Encoding = "xy"  # the networks' input: the observation, or one-hot cells (grid)
    reward_scale: float = 1.0
    max_grad_norm: float | None = None  # None: by the control type (CONTROL_DEFAULTS); 0: off
    device: str = "cpu"
    threads: int = 1
    workers: int = 1  # physics mode: processes stepping the games (grid ignores it)
    optimizer: Optimizer = "rmsprop"
    adam_eps: float = 1e-5
    gae_lambda: float = 1.0  # 1: the paper's eq. 13 returns
    normalize_advantages: bool = True  # ours
    value_norm: bool = True  # ours: PopArt targets per reward component
    value_norm_beta: float = 0.999
    split_rewards: bool = True  # ours: time and collision components valued apart
    balance_rewards: bool = True  # each component's advantage on its own scale
    collision_weight: float = 1.0
    lr_schedule: Schedule = "linear"  # ours; the paper's is constant
    entropy_schedule: Schedule | None = None  # None: by the game (ENTROPY, resolve_train)
    # Continuous control (ours; None: the value for the scenario's control type, see
    # resolve_train): the Gaussians' initial log-std, a soft bound keeping their means
    # inside the command box (algos/learner.py), and progress shaping on the pursuers'
    # distance to the evader and on the area of the evader's Voronoi cell (algos/shaping.py).
    log_std_init: float | None = None
    mean_bound_coef: float | None = None
    distance_shaping: float | None = None
    area_shaping: float | None = None
    constrain_collisions: bool = False  # collisions as a constraint (Lagrange multiplier)
    collision_budget: float = 0.0
    lagrange_lr: float = 1.0
    exploit_every: int = 0  # grid self-play: exact exploitability every K updates (0: off)
    pool_every: int = 0  # self-play: snapshot both teams every K updates (0: simultaneous)
    pool_size: int = 10  # snapshots kept per team (oldest dropped): training/opponents.py
    pool_latest: float = 0.5  # probability that an update is latest against latest
    # Grid self-play: exploitability descent (training/descent.py). The pursuers' actors
    # learn only by stepping down the discounted value of the evader's exact best response
    # to them, every K updates; the evader learns from the rollouts, or ("both") by
    # stepping up the value of the pursuers' exact best response to it.
    descent_every: int = 0  # 0: off (the pursuers learn from their rollouts)
    descent_steps: int = 1  # actor steps per best response
    descent_lr: float = 1e-3  # Adam's step size for them
    descent_teams: DescentTeams = "pursuers"  # who learns by descent

    def validate(self) -> None:
        """Raise ``ValueError`` naming the key of the first impossible value."""
        check_limits(self, TRAIN_LIMITS)
        for key in (
            "updates", "batch_size", "num_envs", "hidden", "layers", "threads", "workers",
            "descent_steps",
        ):  # fmt: skip
            if getattr(self, key) is not None and getattr(self, key) < 1:
                raise _KeyError(key, f"must be >= 1, got {getattr(self, key)}")
        if self.batch_size is not None and self.batch_size % self.num_envs:
            raise _KeyError(
                "batch_size",
                f"{self.batch_size} is not a multiple of num_envs={self.num_envs}",
            )
        if not 0.0 <= self.gamma <= 1.0:
            raise _KeyError("gamma", f"must be in [0, 1], got {self.gamma}")
        for key in ("lr", "reward_scale", "descent_lr"):
            if not getattr(self, key) > 0:
                raise _KeyError(key, f"must be > 0, got {getattr(self, key)}")
        for key in ("entropy_coef", "value_coef", "max_grad_norm", "rmsprop_eps"):
            value = getattr(self, key)
            if value is not None and value < 0:
                raise _KeyError(key, f"must be >= 0, got {value}")
        if not 0.0 <= self.rmsprop_alpha < 1.0:
            raise _KeyError("rmsprop_alpha", f"must be in [0, 1), got {self.rmsprop_alpha}")
        if not 0.0 < self.value_norm_beta < 1.0:
            raise _KeyError("value_norm_beta", f"must be in (0, 1), got {self.value_norm_beta}")
        if not 0.0 <= self.gae_lambda <= 1.0:
            raise _KeyError("gae_lambda", f"must be in [0, 1], got {self.gae_lambda}")
        if not self.adam_eps > 0:
            raise _KeyError("adam_eps", f"must be > 0, got {self.adam_eps}")
        for key in (
            "collision_budget", "lagrange_lr", "collision_weight", "exploit_every",
            "descent_every",
        ):  # fmt: skip
            if getattr(self, key) < 0:
                raise _KeyError(key, f"must be >= 0, got {getattr(self, key)}")
        for key in ("distance_shaping", "area_shaping", "mean_bound_coef"):
            value = getattr(self, key)
            if value is not None and not 0.0 <= value < float("inf"):
                raise _KeyError(key, f"must be finite and >= 0, got {value}")
        if self.log_std_init is not None and not math.isfinite(self.log_std_init):
            raise _KeyError("log_std_init", f"must be finite, got {self.log_std_init}")
        if self.pool_every < 0:
            raise _KeyError("pool_every", f"must be >= 0, got {self.pool_every}")
        if self.pool_size < 1:
            raise _KeyError("pool_size", f"must be >= 1, got {self.pool_size}")
        if not 0.0 <= self.pool_latest <= 1.0:
            raise _KeyError("pool_latest", f"must be in [0, 1], got {self.pool_latest}")
        if self.constrain_collisions and not (self.split_rewards and self.value_norm):
            raise _KeyError(
                "constrain_collisions",
                "needs split_rewards = true and value_norm = true (the constraint is the"
                " collision component, valued and scaled on its own)",
            )

    @property
    def steps_per_env(self) -> int:
        """Rollout length per environment in one update (of a config from
        :func:`resolve_train`, where ``batch_size`` is set)."""
        return self.batch_size // self.num_envs


PRESETS: dict[str, dict[str, Any]] = {
    "paper": {
        "num_envs": 1,
        "batch_size": 128,
        "updates": 5000,
        "lr": 7e-3,
        "rmsprop_alpha": 0.9,
        "rmsprop_eps": 1e-7,
        "gamma": 0.99,
        "entropy_coef": 1e-4,
        "value_coef": 0.5,
        "hidden": 128,
        "reward_scale": 1.0,
        "max_grad_norm": 0.0,
        "optimizer": "rmsprop",
        "gae_lambda": 1.0,
        "normalize_advantages": False,
        "value_norm": False,
        "split_rewards": False,
        "lr_schedule": "constant",
        "entropy_schedule": "constant",
        "constrain_collisions": False,
        "distance_shaping": 0.0,
        "area_shaping": 0.0,
    },
    "descent": {
        "descent_every": 8,
        "descent_steps": 2,
        "descent_lr": 1e-3,
        "descent_teams": "both",
        "layers": 2,
        "hidden": 128,
        "encoding": "onehot",
        "updates": 2000,
    },
}
"""Named sets of :class:`Train` values (``--preset NAME``). ``paper`` is the paper's exact
method (SPEC §6): RMSprop 7e-3 (Keras rho 0.9, eps 1e-7), one game, plain eq. 13 returns,
raw rewards. ``descent`` is grid self-play whose teams both learn by exploitability
descent (:mod:`a2cm_phys.training.descent`; 250 exact best responses to each, two actor steps each,
on actors of two hidden layers of 128 over one-hot cells; about 25 minutes on
``grid_vs``): pursuers that no evader escapes for long, and an evader that the team which
knows it catches no sooner than it catches the fleeing one (``BENCHMARKS.md``). Explicit
options given beside a preset win over it."""


def preset(name: str) -> dict[str, Any]:
    """The :class:`Train` values of preset ``name``; a :class:`ConfigError` if unknown."""
    if name not in PRESETS:
        raise ConfigError(f"--preset: unknown preset {name!r} (presets: {', '.join(PRESETS)})")
    return dict(PRESETS[name])


SCENARIO_LIMITS: dict[str, tuple[int, str]] = {
    "size": (1000, "the arena's tables and pictures grow with size²"),
    "pursuers": (64, "one actor per pursuer, each observing every agent"),
    "max_steps": (1_000_000, "an episode's log is buffered in memory until it ends"),
    "physics.substeps": (
        10_000,
        "each is a solver step of every game, about 5 µs: 10,000 already make one step take 50 ms",
    ),
}
"""Largest values a scenario may ask for, with the reason: beyond them memory runs out, or
a step takes so long that a run seems to hang. A dotted key is a key of a sub-table."""

TRAIN_LIMITS: dict[str, tuple[int, str]] = {
    "num_envs": (65_536, "every game's state is held in memory"),
    "batch_size": (1 << 20, "a batch is held in memory"),
    "hidden": (16_384, "the networks' weights are held in memory"),
    "layers": (64, "the networks' weights are held in memory"),
    "descent_steps": (10_000, "each step is a pass over the visited states"),
    "threads": (256, "each torch thread needs memory of its own"),
    "workers": (256, "each worker is a process"),
    "seed": (2**64 - 1, "seeds feed 64-bit generators"),
    "lr": (1000, "a step size; far larger ones overflow the optimiser's float32 arithmetic"),
    "descent_lr": (1000, "a step size; far larger ones overflow Adam's float32 arithmetic"),
    "pool_size": (10_000, "every snapshot's weights are held in memory and checkpointed"),
}
"""Largest training values, with the reason."""



def check_limits(obj: Any, limits: Mapping[str, tuple[int, str]]) -> None:
    """Raise ``ValueError`` naming the key of the first value above its limit, or (for a
    scenario) a ``name`` that is not a plain file name (run directories are named after it)."""
    for key, (limit, why) in limits.items():
        value = obj
        for part in key.split("."):
            value = getattr(value, part)
        if value is not None and value > limit:
            raise _KeyError(key, f"must be at most {limit:,} ({why}), got {value:,}")
    name = getattr(obj, "name", None)
    if name is not None and (not name or name[0] == "." or set(name) & set("/\\\0")):
        raise _KeyError("name", f"must be a file name (no /, \\, no leading '.'), got {name!r}")


class _KeyError(ValueError):
    """Internal: a validation failure carrying the dotted key it concerns."""

    def __init__(self, key: str, message: str) -> None:
        super().__init__(message)
        self.key = key


# --------------------------------------------------------------------------- building


def build(cls: type, data: Mapping[str, Any], source: str, prefix: str = "") -> Any:
    """Build dataclass ``cls`` from nested ``data``, checking keys, types and values.

    ``source`` names where the data came from (a file path, ``"overrides"``), and is put
    in front of every error message together with the dotted key at fault.
    """
    try:
        obj = _build(cls, data, prefix)
        if hasattr(obj, "validate"):
            obj.validate()
        return obj
    except _KeyError as err:
        key = f"{prefix}{err.key}" if prefix and not err.key.startswith(prefix) else err.key
        raise ConfigError(f"{source}: key '{key}': {err}") from None


def _build(cls: type, data: Mapping[str, Any], prefix: str) -> Any:
    if not isinstance(data, Mapping):
        raise _KeyError(prefix.rstrip(".") or "<root>", f"expected a table, got {data!r}")
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - set(fields))
    if unknown:
        known = ", ".join(fields)
        raise _KeyError(f"{prefix}{unknown[0]}", f"unknown key (known keys: {known})")
    kwargs = {}
    for name, value in data.items():
        key, hint = f"{prefix}{name}", hints[name]
        if dataclasses.is_dataclass(hint):
            kwargs[name] = _build(hint, value, f"{key}.")
        else:
            kwargs[name] = _coerce(value, hint, key)
    return cls(**kwargs)


_INTEGERS = (int, np.integer)
_REALS = (int, float, np.integer, np.floating)


def _coerce(value: Any, hint: Any, key: str) -> Any:
    origin = typing.get_origin(hint)
    if origin is Literal:
        choices = typing.get_args(hint)
        if value not in choices:
            raise _KeyError(key, f"must be one of {', '.join(map(repr, choices))}, got {value!r}")
        return value
    if origin in (typing.Union, types.UnionType):
        args = [arg for arg in typing.get_args(hint) if arg is not type(None)]
        if len(args) != 1 or len(typing.get_args(hint)) != 2:
            raise TypeError(f"unsupported annotation for {key}: {hint}")
        return None if value is None else _coerce(value, args[0], key)  # X | None
    # numpy scalars (np.int64, np.float32, np.bool_) are taken as the Python values they
    # hold, so that values computed with numpy pass where the same Python numbers do.
    if hint is float:
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, _REALS):
            raise _KeyError(key, f"must be a number, got {value!r}")
        if not math.isfinite(value):
            raise _KeyError(key, f"must be a finite number, got {value!r}")
        return float(value)
    if hint is int:
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, _INTEGERS):
            raise _KeyError(key, f"must be an integer, got {value!r}")
        return int(value)
    if hint is bool:
        if not isinstance(value, (bool, np.bool_)):
            raise _KeyError(key, f"must be true or false, got {value!r}")
        return bool(value)
    if hint is str and not isinstance(value, str):
        raise _KeyError(key, f"must be a string, got {value!r}")
    return value


def to_dict(obj: Any) -> dict[str, Any]:
    """A plain nested dict of a config dataclass (for JSON, MCAP metadata, TOML)."""
    return dataclasses.asdict(obj)


# --------------------------------------------------------------------------- overrides


def parse_assignments(items: Iterable[str], source: str = "--set") -> dict[str, Any]:
    """Parse ``key=value`` strings; values are read as TOML (``-1``, ``"flee"``, ``true``).

    A bare word that is not valid TOML is taken as a string, so ``evader=flee`` works.
    """
    out: dict[str, Any] = {}
    for item in items:
        key, sep, raw = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise ConfigError(f"{source}: '{item}' is not of the form key=value")
        try:
            out[key] = tomllib.loads(f"v = {raw.strip()}")["v"]
        except tomllib.TOMLDecodeError:
            out[key] = raw.strip()
    return out


def merge_overrides(data: Mapping[str, Any], overrides: Mapping[str, Any]) -> dict[str, Any]:
    """Return ``data`` updated with ``overrides``; dotted keys and nested dicts both work."""
    merged: dict[str, Any] = {
        k: (dict(v) if isinstance(v, Mapping) else v) for k, v in data.items()
    }
    for dotted, value in overrides.items():
        *parents, leaf = dotted.split(".")
        table = merged
        for part in parents:
            table = table.setdefault(part, {})
            if not isinstance(table, dict):
                raise ConfigError(f"overrides: key '{dotted}': '{part}' is not a table")
        if isinstance(value, Mapping) and isinstance(table.get(leaf), Mapping):
            table[leaf] = merge_overrides(table[leaf], value)
        else:
            table[leaf] = value
    return merged


# --------------------------------------------------------------------------- loading


def scenario_names() -> list[str]:
    """Names of the scenarios shipped in ``scenarios/``."""
    return sorted(p.stem for p in SCENARIO_DIR.glob("*.toml"))


def resolve_scenario_path(scenario: str | Path) -> Path:
    """A scenario name (``grid``) or a path to a TOML file, as an existing path."""
    path = Path(scenario)
    if path.suffix == ".toml" or path.exists():
        if not path.is_file():
            raise ConfigError(f"{path}: no such scenario file")
        return path
    named = SCENARIO_DIR / f"{scenario}.toml"
    if not named.is_file():
        raise ConfigError(
            f"unknown scenario '{scenario}' (named scenarios: {', '.join(scenario_names())};"
            " or give a path to a .toml file)"
        )
    return named


def read_toml(path: Path) -> dict[str, Any]:
    """Read a TOML file, turning syntax errors, text that is not UTF-8 and unreadable files
    into a :class:`ConfigError` naming the file."""
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"{path}: invalid TOML: {err}") from None
    except UnicodeDecodeError as err:  # tomllib decodes the whole file before parsing
        raise ConfigError(
            f"{path}: not UTF-8 text (TOML files must be UTF-8; byte 0x{err.object[err.start]:02x}"
            f" at offset {err.start} is not)"
        ) from None
    except OSError as err:
        raise ConfigError(f"{path}: cannot read: {err.strerror}") from None


def load_scenario(
    scenario: str | Path | Scenario, overrides: Mapping[str, Any] | None = None
) -> Scenario:
    """Load a named or file scenario (or take a :class:`Scenario`), apply overrides, validate.

    Overrides are checked exactly like the file: ``load_scenario("grid", {"size": 1})``
    fails with a message naming ``overrides`` and the key ``size``. A ``scenario`` of any
    other type (``load_scenario(123)``) is a ``TypeError`` naming the argument.
    """
    if isinstance(scenario, Scenario):
        data, source = to_dict(scenario), f"scenario '{scenario.name}'"
    elif not isinstance(scenario, (str, os.PathLike)):
        raise TypeError(
            "scenario: expected a scenario name (e.g. 'grid'; see scenario_names()), a path"
            f" to a TOML file or a Scenario, got {type(scenario).__name__} {scenario!r}"
        )
    else:
        path = resolve_scenario_path(scenario)
        data, source = read_toml(path), str(path)
        data.setdefault("name", path.stem)
    if overrides:
        build(Scenario, data, source)  # the file alone must be valid, and be blamed if not
        data, source = merge_overrides(data, overrides), f"{source} (with overrides)"
    return build(Scenario, data, source)


def load_train(
    overrides: Mapping[str, Any] | None = None, source: str = "training options"
) -> Train:
    """A validated :class:`Train` from the defaults and ``overrides``."""
    return build(Train, dict(overrides or {}), source)


CONTROL_DEFAULTS: dict[str, dict[str, float]] = {
    "continuous": {
        "log_std_init": 0.5,
        "mean_bound_coef": 0.1,
        "distance_shaping": 1.0,
        "area_shaping": 2.0,
        "max_grad_norm": 0.5,
        "batch_size": 128,
        "steps": 2_000_000,  # the budget: updates = steps // batch_size
    },
    "discrete": {
        "log_std_init": 0.0,
        "mean_bound_coef": 0.0,
        "distance_shaping": 0.0,
        "area_shaping": 0.0,
        "max_grad_norm": 0.0,
        "batch_size": 128,
        "updates": 5000,
    },
}
"""The values :func:`resolve_train` gives unset :class:`Train` keys, per control type (the
shaping weights per unit of the step cost, :func:`step_cost`). In continuous control a −1
step reward at 10 Hz alone is not learned and unbounded Gaussian means run away
(``BENCHMARKS.md``); discrete control keeps the paper's rewards (and these keys were added
after runs whose stored configs lack them: they mean the discrete values).

- Shaping (``algos/shaping.py``; measured with ``log_std_init`` −0.5, the default then):
  the distance term alone let A2CM match ``pursuit`` against the random evader but never
  catch the fleeing one (8 runs of 10 never captured); with the cell-area term (weight 2)
  every run of 10 catches it in every episode, 0.90× and 0.91× ``pursuit``'s time (A2C,
  A2CM; medians of 5 seeds), and against the random evader A2C comes to 1.02× (was
  1.12×), A2CM to 1.05× (was 1.00×).
- Gradient clipping at norm 0.5: with the area term and no clipping one run in four
  collapsed after learning to capture, never capturing again.
- The Gaussians' initial log-std 0.5 (σ ≈ 1.65: the first commands are clipped to the
  unit disc, near full speed in a random direction; the learned σ falls to 0.1–0.2).
  Against −0.5 (medians of 5 seeds, ratios to ``pursuit``'s capture time): on
  ``phys_cont_collision`` A2CM 1.12× → 1.08× and A2C 1.16× → 1.08× (the slowest seeds
  1.30× and 1.49× → 1.14× and 1.12×); on ``phys_cont_flee`` A2CM 0.91× → 0.84×, A2C
  0.90× → 0.92×; on ``phys_cont`` A2CM 1.05× → 1.02×, A2C 1.02× → 1.05×.
- Updates: the paper's 5,000 of 128 steps (640,000 steps) in discrete control; in
  continuous control a budget of 2,000,000 steps (200,000 s of play at 10 Hz; both
  algorithms were 1.4–1.7× ``pursuit`` after 384,000), ``steps // batch_size`` updates:
  15,625 of 128 steps (against the fleeing evader 4,000,000 in 7,812 updates of 512,
  :data:`FLEE_DEFAULTS`)."""


FLEE_DEFAULTS: dict[str, int] = {"batch_size": 512, "steps": 4_000_000}
"""What continuous control against the scripted fleeing evader changes of
:data:`CONTROL_DEFAULTS` (elsewhere batches of 128, 2,000,000 steps):

- 32-step rollouts in the 16 games (``batch_size`` 512), so the returns carry a trap's
  credit over most of the ~30 steps it takes (with ``gae_lambda`` 1), where 8-step ones
  bootstrap on the critic after 8. That evader is deterministic but for a small seeded
  turn of its candidate headings, so the long returns add little variance. Against the
  random evader they carry its randomness: on ``phys_cont`` A2CM and A2C came to 1.06×
  ``pursuit`` (1.02× and 1.05× with 8 steps), so the other scenarios keep 128.
- 4,000,000 steps (7,812 updates of 512). With 2,000,000 A2CM caught the evader in 0.77×
  ``pursuit``'s time, every seed at 0.77–0.80×, but A2C in 0.88×, one seed of five
  finding the three-pursuer wall trap; with 4,000,000 A2CM takes 0.77× and A2C 0.78×,
  every seed of both at 0.77–0.79× (5 seeds each; with 8-step rollouts and 2,000,000
  steps 0.84× and 0.92×). ``BENCHMARKS.md``, "Rollouts of 32 steps against the fleeing
  evader"."""


ENTROPY: dict[str, tuple[float, Schedule]] = {
    "discrete": (0.03, "linear"),
    "self-play": (0.03, "constant"),
    "continuous": (1e-4, "constant"),
}
"""``Train.entropy_coef`` and ``entropy_schedule`` when unset, by the game
(:func:`entropy_game`); the paper's are 1e-4, constant.

- ``discrete`` (discrete actions, scripted evader): 0.03, annealed linearly to 0 with the
  learning rate. Under the paper's 1e-4 the actors of ``grid_collision`` turned
  deterministic early, one pursuer walking one way in every state, and ended 16% above the
  optimum (3.41 steps); annealed 0.03 explores while the collision penalty is learned and
  ends near-greedy: 2.93–2.94 steps, the optimum, with no collision, for every seed of
  A2C and A2CM in both collision scenarios, and ``grid_flee`` from 57.5 to 6.1 steps
  (5 seeds; ``BENCHMARKS.md``, "The entropy coefficient and its schedule").
- ``self-play`` (discrete actions, learned evader): 0.03 for both teams, constant. Under
  1e-4 both actors turned near-deterministic, so each was exploited by the other's next
  policy: over 5 seeds (A2CM, means) 0.03 took the pursuers from 12.9 to 3.65 steps
  against the random evader and from 826 to 8.96 against the fleeing one, and the learned
  evader from 2.65 to 4.44 steps against the oracle; in ``phys_vs`` (2 seeds) the pursuers
  from 14.4 to 3.6–4.1 steps against the random evader ("Self-play: the entropy
  coefficient").
- ``continuous`` (Gaussian actors, either evader): the paper's 1e-4; a Gaussian's entropy
  is on another scale, and nothing else was measured."""


def entropy_game(scenario: Scenario) -> str:
    """The :data:`ENTROPY` row of ``scenario``: ``continuous``, ``self-play`` or
    ``discrete``."""
    if scenario.continuous:
        return "continuous"
    return "self-play" if scenario.evader == "learned" else "discrete"


SHAPING_KEYS = ("distance_shaping", "area_shaping")
"""Shaping weights whose :data:`CONTROL_DEFAULTS` are per unit of the step cost."""


def step_cost(scenario: Scenario) -> float:
    """What a step costs the team, ``|rewards.step|`` (1 where a step is free): the unit of
    the default shaping weights. The shaping pays in steps of travel, so a scenario whose
    step costs 1,000 (the paper's collision experiments) gets weights 1,000 times larger:
    shaping then weighs the same against the time cost in every scenario (measured on
    ``phys_cont_collision``, 5 seeds: with weights of 1 and 2 A2CM's teams took 1.6–2.9×
    ``pursuit``'s time, with 1,000 and 2,000 1.04–1.30×, ``BENCHMARKS.md``)."""
    return abs(scenario.rewards.step) or 1.0


def resolve_train(scenario: Scenario, cfg: Train) -> Train:
    """``cfg`` with its unset (None) keys given the values of ``scenario``'s control type
    (:data:`CONTROL_DEFAULTS`, the shaping weights times :func:`step_cost`, continuous
    control's updates from its step budget) and game (:data:`ENTROPY`,
    :data:`FLEE_DEFAULTS`): what a run records and its learner sees. A default batch that
    ``cfg.num_envs`` does not divide is a :class:`ConfigError` naming ``batch_size``."""
    values = dict(CONTROL_DEFAULTS["continuous" if scenario.continuous else "discrete"])
    values["entropy_coef"], values["entropy_schedule"] = ENTROPY[entropy_game(scenario)]
    cost = step_cost(scenario)
    for key in SHAPING_KEYS:
        values[key] *= cost
    if scenario.continuous and scenario.evader == "flee":
        values.update(FLEE_DEFAULTS)
    batch = values["batch_size"] if cfg.batch_size is None else cfg.batch_size
    if "steps" in values:
        values["updates"] = values.pop("steps") // batch
    unset = {k: v for k, v in values.items() if getattr(cfg, k) is None}
    if "batch_size" in unset and unset["batch_size"] % cfg.num_envs:
        raise ConfigError(
            f"training options: key 'batch_size': this scenario's default of"
            f" {unset['batch_size']} is not a multiple of num_envs={cfg.num_envs}; set"
            " batch_size too"
        )
    check_network_size(scenario, cfg)
    return dataclasses.replace(cfg, **unset) if unset else cfg


MAX_WEIGHTS = 100_000_000
"""Most weights the networks of a run may have (:func:`network_weights`), 400 MB as
float32. Training holds them with their gradients, the optimiser's state (one more copy
for RMSprop, two for Adam) and a copy of the actors for rollouts, and every checkpoint
writes them: about 2 GB at this bound. The shipped configurations need far fewer (the
``descent`` preset on ``grid_vs``, two layers of 128 over one-hot cells: 133,011); more asked
for by ``hidden`` and ``layers`` (e.g. 64 layers of 16,384 units, 17 billion weights per
agent) ran out of memory or allocated for minutes before a run began."""


def network_inputs(scenario: Scenario, cfg: Train) -> int:
    """The length of the networks' input: the observation, or its one-hot cells."""
    return scenario.obs_dim * (scenario.size if cfg.encoding == "onehot" else 1)


def network_weights(scenario: Scenario, cfg: Train) -> int:
    """How many weights (parameters) the networks of a run of ``cfg`` on ``scenario`` have,
    counted as :func:`~a2cm_phys.algos.models.make_model` builds them, without building
    them: every pursuer's actor, the critics (one with A2CM, one per pursuer with A2C), a
    learned evader's actor and critic, each of ``layers`` hidden layers of ``hidden``
    units over the observation (or its one-hot cells, ``encoding = "onehot"``)."""
    hidden, deep = cfg.hidden, cfg.layers - 1
    inputs = network_inputs(scenario, cfg)
    outputs = 2 if scenario.continuous else scenario.actions
    log_std = outputs if scenario.continuous else 0

    def stack(n: int, fan_in: int, fan_out: int) -> int:  # a StackedLinear layer
        return n * (fan_in * fan_out + fan_out)

    def team(agents: int, critics: int, values: int) -> int:
        actors = stack(agents, inputs, hidden) + deep * stack(agents, hidden, hidden)
        actors += stack(agents, hidden, outputs) + agents * log_std
        critic = stack(critics, inputs, hidden) + deep * stack(critics, hidden, hidden)
        return actors + critic + stack(critics, hidden, values)

    n = scenario.pursuers
    weights = team(n, 1 if cfg.algo == "a2cm" else n, 2 if cfg.split_rewards else 1)
    if scenario.evader == "learned":  # an A2C team of one on one reward (teams.py)
        weights += team(1, 1, 1)
    return weights


def check_network_size(scenario: Scenario, cfg: Train) -> None:
    """A :class:`ConfigError` naming ``hidden`` and ``layers`` if the networks would have more
    than :data:`MAX_WEIGHTS` weights (:func:`network_weights`); nothing is allocated."""
    weights = network_weights(scenario, cfg)
    if weights > MAX_WEIGHTS:
        inputs = "one-hot inputs" if cfg.encoding == "onehot" else "inputs"
        raise ConfigError(
            f"training options: keys 'hidden', 'layers': {cfg.layers} hidden layer(s) of"
            f" {cfg.hidden:,} units for {scenario.pursuers} pursuer(s) over"
            f" {network_inputs(scenario, cfg):,} {inputs} make networks of"
            f" {weights:,} weights, more than the {MAX_WEIGHTS:,} a run may have (all held in"
            " memory several times over); use fewer or narrower layers"
        )


STORED_BEFORE: dict[str, Any] = {"entropy_schedule": "constant"}
"""What runs stored before a key existed trained with (every run before the entropy
schedule had a constant coefficient)."""


def stored_train(values: Mapping[str, Any]) -> dict[str, Any]:
    """A stored run's training config completed for keys added after it was written:
    the discrete values of :data:`CONTROL_DEFAULTS` (such runs had none of these pieces),
    :data:`STORED_BEFORE`, then today's defaults."""
    added = {f.name: f.default for f in dataclasses.fields(Train)}
    return {**added, **CONTROL_DEFAULTS["discrete"], **STORED_BEFORE, **values}
