"""Training settings as frozen, typed data, their limits and the named presets."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

from .parse import ConfigError, InvalidKey, check_limits

Algo = Literal["a2c", "a2cm"]
Optimizer = Literal["rmsprop", "adam"]
Schedule = Literal["constant", "linear"]
Encoding = Literal["xy", "onehot", "relative", "metric"]
DescentTeams = Literal["pursuers", "both"]
Recurrent = Literal["none", "gru"]


@dataclass(frozen=True)
class Train:
    """Training settings (SPEC §6).

    The paper's hyperparameters are kept (RMSprop 7e-3 as Keras has it, γ 0.99, batch 128,
    5,000 updates, 128 hidden units); what is ours, chosen by the ablation in
    ``BENCHMARKS.md`` so that the collision scenarios are learned: 16 games (64 against the
    random evader, on the grid and in continuous control, with batches of 512 and a step
    size of 1e-2, :data:`WIDE_DEFAULTS`: the same steps in a quarter of the updates), the
    reward split into its time and collision components, each valued by its own critic output
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
    num_envs: int | None = None  # None: 16, or 64 by the game (resolve_train); the paper's: 1
    seed: int = 0
    lr: float | None = None  # None: the paper's 7e-3, or 1e-2 by the game (resolve_train)
    rmsprop_alpha: float = 0.9
    rmsprop_eps: float = 1e-7
    gamma: float = 0.99
    entropy_coef: float | None = None  # None: by the game (ENTROPY, resolve_train)
    value_coef: float = 0.5
    hidden: int = 128
    layers: int = 1  # hidden layers of every actor and critic (the paper's: 1)
    # the networks' input: the observation, one-hot cells (grid), or "relative": each actor's
    # from its own body, the others' positions as offsets (algos/encoding.py); "metric": the
    # same offsets in metres (cells on a grid), not fractions of the arena
    encoding: Encoding = "xy"
    # "gru": each actor carries a GRU state across an episode (algos/recurrent.py), learnt by
    # back-propagation through each rollout (batch_size / num_envs steps)
    recurrent: Recurrent = "none"
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
    # where that bound starts: a little past the command box's ±1, so that a mean can still
    # command full speed along an axis (3 is faster: docs/benchmarks/random-starts.md)
    mean_bound: float = 1.1
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
    descent_schedule: Schedule = "constant"  # "linear": descent_lr · (1 − progress)
    descent_teams: DescentTeams = "pursuers"  # who learns by descent

    def validate(self) -> None:
        """Raise ``ValueError`` naming the key of the first impossible value."""
        check_limits(self, TRAIN_LIMITS)
        for key in (
            "updates", "batch_size", "num_envs", "hidden", "layers", "threads", "workers",
            "descent_steps",
        ):  # fmt: skip
            if getattr(self, key) is not None and getattr(self, key) < 1:
                raise InvalidKey(key, f"must be >= 1, got {getattr(self, key)}")
        unset = self.batch_size is None or self.num_envs is None
        if not unset and self.batch_size % self.num_envs:
            raise InvalidKey(
                "batch_size",
                f"{self.batch_size} is not a multiple of num_envs={self.num_envs}",
            )
        if not 0.0 <= self.gamma <= 1.0:
            raise InvalidKey("gamma", f"must be in [0, 1], got {self.gamma}")
        for key in ("lr", "reward_scale", "descent_lr"):
            if getattr(self, key) is not None and not getattr(self, key) > 0:
                raise InvalidKey(key, f"must be > 0, got {getattr(self, key)}")
        for key in ("entropy_coef", "value_coef", "max_grad_norm", "rmsprop_eps"):
            value = getattr(self, key)
            if value is not None and value < 0:
                raise InvalidKey(key, f"must be >= 0, got {value}")
        if not 0.0 <= self.rmsprop_alpha < 1.0:
            raise InvalidKey("rmsprop_alpha", f"must be in [0, 1), got {self.rmsprop_alpha}")
        if not 0.0 < self.value_norm_beta < 1.0:
            raise InvalidKey("value_norm_beta", f"must be in (0, 1), got {self.value_norm_beta}")
        if not 0.0 <= self.gae_lambda <= 1.0:
            raise InvalidKey("gae_lambda", f"must be in [0, 1], got {self.gae_lambda}")
        if not self.adam_eps > 0:
            raise InvalidKey("adam_eps", f"must be > 0, got {self.adam_eps}")
        for key in (
            "collision_budget", "lagrange_lr", "collision_weight", "exploit_every",
            "descent_every",
        ):  # fmt: skip
            if getattr(self, key) < 0:
                raise InvalidKey(key, f"must be >= 0, got {getattr(self, key)}")
        for key in ("distance_shaping", "area_shaping", "mean_bound_coef"):
            value = getattr(self, key)
            if value is not None and not 0.0 <= value < float("inf"):
                raise InvalidKey(key, f"must be finite and >= 0, got {value}")
        if not 0.0 < self.mean_bound < float("inf"):
            raise InvalidKey("mean_bound", f"must be finite and > 0, got {self.mean_bound}")
        if self.log_std_init is not None and not math.isfinite(self.log_std_init):
            raise InvalidKey("log_std_init", f"must be finite, got {self.log_std_init}")
        if self.pool_every < 0:
            raise InvalidKey("pool_every", f"must be >= 0, got {self.pool_every}")
        if self.pool_size < 1:
            raise InvalidKey("pool_size", f"must be >= 1, got {self.pool_size}")
        if not 0.0 <= self.pool_latest <= 1.0:
            raise InvalidKey("pool_latest", f"must be in [0, 1], got {self.pool_latest}")
        if self.constrain_collisions and not (self.split_rewards and self.value_norm):
            raise InvalidKey(
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


def matching_preset(values: dict[str, Any]) -> str | None:
    """The preset whose every value ``values`` (a :class:`Train` as a dict, e.g. a run's
    ``config.json``) holds, or ``None``: how a run written before the preset was recorded
    is named. A preset with an option overridden no longer matches, except ``updates``:
    a longer or shorter run of the paper's method is still the paper's method."""
    for name, fixed in PRESETS.items():
        if all(values.get(key) == value for key, value in fixed.items() if key != "updates"):
            return name
    return None


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
