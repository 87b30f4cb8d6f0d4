"""Resolution: a run's training settings completed for its scenario (the defaults of its
control type and game), then checked against it, once, before anything is built."""

from __future__ import annotations

import dataclasses

from .parse import ConfigError
from .scenario import Scenario
from .train import Schedule, Train

CONTROL_DEFAULTS: dict[str, dict[str, float]] = {
    "continuous": {
        "log_std_init": 0.5,
        "mean_bound_coef": 0.1,
        "distance_shaping": 1.0,
        "area_shaping": 2.0,
        "max_grad_norm": 0.5,
        "num_envs": 16,
        "batch_size": 128,
        "lr": 7e-3,
        "steps": 2_000_000,  # the budget: updates = steps // batch_size
    },
    "discrete": {
        "log_std_init": 0.0,
        "mean_bound_coef": 0.0,
        "distance_shaping": 0.0,
        "area_shaping": 0.0,
        "max_grad_norm": 0.0,
        "num_envs": 16,
        "batch_size": 128,
        "lr": 7e-3,
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
  15,625 of 128 steps here, 3,906 of 512 against the random evader (:data:`WIDE_DEFAULTS`),
  and against the fleeing evader 4,000,000 in 7,812 updates of 512 (:data:`FLEE_DEFAULTS`)."""


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


WIDE_DEFAULTS: dict[str, float] = {
    "num_envs": 64,
    "batch_size": 512,
    "lr": 1e-2,
}
"""What games against the random evader, on the grid or in continuous control, change of
:data:`CONTROL_DEFAULTS`: 64 games and batches of 512 (8 steps in each game, as before), at
a step size of 1e-2, for the same steps in a quarter of the updates.

The learner's cost is mostly per update, not per step, so a quarter of the updates halves
the training time; the rollout's per-step cost is shared by four times the games.
Measured (greedy over 5,000 episodes, 5 seeds, A2CM; ``BENCHMARKS.md``, "The main job in
half the time"):

- ``grid_collision``: 16 games of 128 at 7e-3 (before) 2.943 steps on seed 0; 64 of 512 at
  7e-3 a median of 2.961 (worst 2.993), at 1e-2 2.949 (worst 2.959), 128 of 1,024 2.964
  (one seed collided); no collision in any other run. With these, A2C came to 2.956
  (worst 3.261; 2.929 before), ``grid_collision_continue`` to 2.957 (2.931; one seed
  collided once in ~1,700 episodes) and ``grid`` to 2.935 (2.929).
- ``phys_cont`` (``pursuit``: 17.452 steps on the same episodes): 16 games of 128 (before)
  17.652 (worst 17.926, 1.011× ``pursuit``); 64 of 512 at 7e-3 17.967 (worst 18.424,
  1.056×); at 1e-2 17.836 (worst 17.869, 1.022×), in 0.54× the training time.
  ``phys_cont_collision`` (``pursuit`` 17.416): 18.567 before (worst 19.402, 1.066×;
  collisions 0.0006 a game), 17.782 with these (worst 18.282, 1.021×; collisions 0, the
  worst seed 0.0002).
- Against the fleeing evader they were far worse (``grid_flee``: A2CM 11.9 steps, A2C 8.0,
  against 6.1 and 5.5 with 16 of 128), so it keeps 16 games of 128 (and continuous control
  its :data:`FLEE_DEFAULTS`), as do a learned evader (self-play) and discrete physics."""

GRID_DEFAULTS: dict[str, float] = {**WIDE_DEFAULTS, "steps": 640_000}
"""Grid games against the random evader: :data:`WIDE_DEFAULTS` for the paper's 640,000
steps (1,250 updates; the paper's 5,000 of 128 with ``--batch-size 128``)."""


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
    """A run's training settings, resolved: ``cfg`` with its unset (None) keys given the
    values of ``scenario``'s control type (:data:`CONTROL_DEFAULTS`, the shaping weights
    times :func:`step_cost`, continuous control's updates from its step budget) and game
    (:data:`ENTROPY`, :data:`FLEE_DEFAULTS`, :data:`GRID_DEFAULTS`, :data:`WIDE_DEFAULTS`),
    then checked against the scenario (:func:`check_train`). Called once, where options
    enter (the train command, a sweep's runs, the report's plan): what it returns is what
    ``config.json`` records and the trainer and learner take, and nothing after it
    resolves or checks again. A batch that the number of games does not divide is a
    :class:`ConfigError` naming ``batch_size``."""
    values = dict(CONTROL_DEFAULTS["continuous" if scenario.continuous else "discrete"])
    values["entropy_coef"], values["entropy_schedule"] = ENTROPY[entropy_game(scenario)]
    cost = step_cost(scenario)
    for key in SHAPING_KEYS:
        values[key] *= cost
    if scenario.continuous and scenario.evader == "flee":
        values.update(FLEE_DEFAULTS)
    if scenario.mode == "grid" and scenario.evader == "random":
        values.update(GRID_DEFAULTS)
        values.pop("updates")
    elif scenario.continuous and scenario.evader == "random":
        values.update(WIDE_DEFAULTS)  # continuous control's step budget stays
    batch = values["batch_size"] if cfg.batch_size is None else cfg.batch_size
    if "steps" in values:
        values["updates"] = values.pop("steps") // batch
    unset = {k: v for k, v in values.items() if getattr(cfg, k) is None}
    games = values["num_envs"] if cfg.num_envs is None else cfg.num_envs
    if "batch_size" in unset and unset["batch_size"] % games:
        raise ConfigError(
            f"training options: key 'batch_size': this scenario's default of"
            f" {unset['batch_size']} is not a multiple of num_envs={games}; set"
            " batch_size too"
        )
    resolved = dataclasses.replace(cfg, **unset) if unset else cfg
    check_train(scenario, resolved)
    return resolved


def check_train(scenario: Scenario, cfg: Train) -> None:
    """Every check of training options against the scenario: a :class:`ConfigError` naming
    the first key at fault. (Each key's own range is checked when :class:`Train` is built;
    whether an exact solver can hold the arena, only the solver knows:
    :mod:`a2cm_phys.training.descent` asks it when descent is set up.)"""
    if cfg.seed < 0:  # seeds feed numpy generators
        raise ConfigError(f"training options: key 'seed': must be >= 0, got {cfg.seed}")
    if cfg.batch_size % cfg.num_envs:  # one of them is this scenario's default
        raise ConfigError(
            f"training options: key 'batch_size': {cfg.batch_size} is not a multiple of"
            f" num_envs={cfg.num_envs} (this scenario's default when unset); set num_envs"
            " too"
        )
    if scenario.mode == "physics" and cfg.workers > cfg.num_envs:
        raise ConfigError(
            f"training options: key 'workers': {cfg.workers} processes for num_envs="
            f"{cfg.num_envs} games; use at most num_envs workers (or more --num-envs)"
        )
    if cfg.pool_every and scenario.evader != "learned":
        raise ConfigError(
            f"training options: key 'pool_every': a pool of past opponents needs a learned"
            f" evader, and scenario '{scenario.name}' has evader = '{scenario.evader}'"
            " (use grid_vs, phys_vs or phys_cont_vs, or pool_every = 0)"
        )
    _check_descent(scenario, cfg)
    _check_encoding(scenario, cfg)
    _check_recurrent(cfg)
    check_network_size(scenario, cfg)


def _check_encoding(scenario: Scenario, cfg: Train) -> None:
    """One-hot inputs need a grid; relative (and metric) inputs the global observation of
    memoryless actors."""
    if cfg.encoding == "onehot" and scenario.mode != "grid":
        raise ConfigError(
            "training options: key 'encoding': one-hot cells need a grid, and scenario"
            f" '{scenario.name}' is in {scenario.mode} mode (use encoding = 'xy')"
        )
    if cfg.encoding in ("relative", "metric") and (scenario.sensing.on or cfg.recurrent != "none"):
        what = "sensing" if scenario.sensing.on else f"recurrent = '{cfg.recurrent}'"
        raise ConfigError(
            f"training options: key 'encoding': {cfg.encoding} inputs are made from the global"
            f" observation of memoryless actors, and this run has {what} (use encoding ="
            " 'xy')"
        )


def _check_recurrent(cfg: Train) -> None:
    """Recurrent actors act through their memory: what reads a team's policy state by state
    (the pool of past opponents, exploitability and its descent) cannot use them yet."""
    if cfg.recurrent == "none":
        return
    for key in ("pool_every", "exploit_every", "descent_every"):
        if getattr(cfg, key):
            raise ConfigError(
                f"training options: keys 'recurrent', '{key}': recurrent actors act on"
                f" what they remember, and {key} reads a policy state by state; use"
                f" recurrent = 'none' or {key} = 0"
            )


def _check_descent(scenario: Scenario, cfg: Train) -> None:
    """Exploitability descent needs grid self-play."""
    if cfg.descent_teams == "both" and not cfg.descent_every:
        raise ConfigError(
            "training options: key 'descent_teams': 'both' needs exploitability descent"
            " (descent_every > 0, or --preset descent)"
        )
    if cfg.descent_every and (scenario.mode != "grid" or scenario.evader != "learned"):
        raise ConfigError(
            "training options: key 'descent_every': exploitability descent needs grid"
            f" self-play, and scenario '{scenario.name}' is in {scenario.mode} mode with"
            f" evader = '{scenario.evader}' (use grid_vs, or descent_every = 0)"
        )
    if cfg.descent_teams == "both" and scenario.collisions.mode == "terminate":
        raise ConfigError(
            "training options: key 'descent_teams': with collisions.mode = 'terminate' the"
            " pursuers' best response could end the episode by colliding, so the evader has"
            " no worst case to raise (use descent_teams = 'pursuers')"
        )


MAX_WEIGHTS = 100_000_000
"""Most weights the networks of a run may have (:func:`network_weights`), 400 MB as
float32. Training holds them with their gradients, the optimiser's state (one more copy
for RMSprop, two for Adam) and a copy of the actors for rollouts, and every checkpoint
writes them: about 2 GB at this bound. The shipped configurations need far fewer (the
``descent`` preset on ``grid_vs``, two layers of 128 over one-hot cells: 133,011); more asked
for by ``hidden`` and ``layers`` (e.g. 64 layers of 16,384 units, 17 billion weights per
agent) ran out of memory or allocated for minutes before a run began."""


def network_inputs(scenario: Scenario, cfg: Train, width: int | None = None) -> int:
    """The length of the networks' input: the observation (or ``width`` numbers), or its
    one-hot cells."""
    width = scenario.obs_dim if width is None else width
    return width * (scenario.size if cfg.encoding == "onehot" else 1)


def network_weights(scenario: Scenario, cfg: Train) -> int:
    """How many weights (parameters) the networks of a run of ``cfg`` on ``scenario`` have,
    counted as :func:`~a2cm_phys.algos.build.make_model` builds them, without building
    them: every pursuer's actor, the critics (one with A2CM, one per pursuer with A2C), a
    learned evader's actor and critic, each of ``layers`` hidden layers of ``hidden``
    units over the observation (or its one-hot cells, ``encoding = "onehot"``)."""
    hidden, deep = cfg.hidden, cfg.layers - 1
    inputs = network_inputs(scenario, cfg)
    outputs = 2 if scenario.continuous else scenario.actions
    log_std = outputs if scenario.continuous else 0

    def stack(n: int, fan_in: int, fan_out: int) -> int:  # a StackedLinear layer
        return n * (fan_in * fan_out + fan_out)

    memory = cfg.recurrent != "none"

    def team(agents: int, critics: int, values: int, seen: int, own: bool = True) -> int:
        actors = stack(agents, inputs, hidden) + deep * stack(agents, hidden, hidden)
        actors += stack(agents, hidden, outputs) + agents * log_std
        if memory:  # a GRU cell per actor; A2C's critics also read their actor's memory
            actors += 2 * stack(agents, hidden, 3 * hidden)
            seen += hidden if own else 0
        critic = stack(critics, seen, hidden) + deep * stack(critics, hidden, hidden)
        return actors + critic + stack(critics, hidden, values)

    n = scenario.pursuers
    # with sensing, A2CM's one critic reads the global state (centralised training)
    shared = network_inputs(scenario, cfg, scenario.state_dim)
    critics, seen = (1, shared) if cfg.algo == "a2cm" else (n, inputs)
    weights = team(n, critics, 2 if cfg.split_rewards else 1, seen, cfg.algo == "a2c")
    if scenario.evader == "learned":  # an A2C team of one on one reward (teams.py)
        weights += team(1, 1, 1, inputs)
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
