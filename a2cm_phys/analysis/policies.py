"""Named policies of either side, as rollout policies: what learned ones are measured against.

- ``random``: uniform actions (discrete), or uniform commands in the unit square (continuous).
- ``pursuit``: every pursuer heads straight for the evader (:mod:`a2cm_phys.analysis.baselines`).
- ``oracle``: the exact optimum of the grid game (:mod:`a2cm_phys.oracle`); in physics
  mode the grid oracle driven in the physics arena: each body's centre is mapped to the
  cell it lies in, and the oracle's move becomes the velocity command in that direction.
  (With differential drive a move turns the pursuer first: the move's primitive with
  discrete control, :func:`~.baselines.steer` along it with continuous control.)
  It is the optimum against the scenario's own evader (the random one where that is
  learned), one team whatever evader :func:`matchup` sets against it: against another
  evader it is that team, not the other evader's best response (which is the oracle of
  a scenario with that evader, ``--set evader=…``).
- ``minimax``: the grid's minimax team (:mod:`a2cm_phys.solve.minimax`): deterministic,
  optimal when the evader sees its move, so no evader escapes it longer than the bound
  (grid mode only).
- ``qmdp``: belief planning for partially observed grids (:mod:`a2cm_phys.analysis.qmdp`):
  a Bayes filter over the evader's cell from the team's pooled sightings (never the state),
  and each step the joint move best on average over the belief under the oracle's values
  (grid scenarios with sensing only).
- ``search``: a scripted sweep for partially observed continuous physics
  (:mod:`a2cm_phys.analysis.search`): each pursuer sweeps its strip of the arena until the
  team sights the evader, then all head for it (physics, continuous control, sensing only).

``qmdp`` and ``search`` have memory: they are objects with ``episodes_ended`` (see
:func:`~a2cm_phys.training.rollout.episodes_ended`), built anew for each evaluation.

Evaders the solvers give (grid mode only): ``best-response``, the exact best response to the
pursuers of the pairing, and ``equilibrium``, the game's equilibrium evader
(:mod:`a2cm_phys.solve.nash`), which no team catches sooner on average than the game's value.

Each is a :data:`~a2cm_phys.training.rollout.Policy`: ``policy(obs (B, obs_dim), rng) -> actions``.
With sensing on (SPEC §6b) ``obs`` is the team vector: ``random``, ``pursuit``, ``oracle``
and ``minimax`` are full-observation references and read its global-state prefix; ``qmdp``
and ``search`` read only the pursuers' own slices.

A :class:`Matchup` is one pairing to play: the game (its evader set to the evader's kind),
the pursuers' policy, and a learned evader's policy where the evader is one (scripted
evaders ``random``, ``flee`` and ``static`` are the scenario's own, injected in the core).
:func:`matchup` builds one from names or run directories (see :func:`resolve_side`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..config import ConfigError, Physics, Scenario, build, load_scenario
from ..deploy import Team, load_team
from ..envs.core import ACTION_DELTAS
from ..solve.cache import OracleSolution, load_or_solve_optimum
from ..solve.symmetric import SymmetricResult
from ..training.rollout import Policy
from .baselines import pursuit_actions, steer
from .names import (
    BEST_RESPONSE,
    EQUILIBRIUM,
    EVADER_POLICIES,
    PURSUER_POLICIES,
    SOLVED_EVADERS,
    oracle_evader,
)
from .qmdp import qmdp_policy
from .search import search_policy


def positions_from_obs(scenario: Scenario, obs: np.ndarray) -> np.ndarray:
    """Agent positions ``(B, N + 1, 2)`` from observations (SPEC §5): integer cells in
    grid mode, metres in physics mode."""
    obs = np.asarray(obs, dtype=np.float64)
    n = scenario.pursuers + 1
    xy = obs[:, : 2 * n].reshape(len(obs), n, 2)
    if scenario.mode == "grid":
        return np.rint(xy * scenario.position_unit).astype(np.int64)
    return xy * scenario.position_unit


def headings_from_obs(scenario: Scenario, obs: np.ndarray) -> np.ndarray | None:
    """The pursuers' headings ``(B, N, 2)`` ``(cos θ, sin θ)`` from observations (the
    state's last ``2 N`` numbers with differential drive), else ``None``."""
    if not scenario.differential:
        return None
    obs = np.asarray(obs, dtype=np.float64)
    n = scenario.pursuers
    at = 4 * (n + 1)
    return obs[:, at : at + 2 * n].reshape(len(obs), n, 2)


def random_policy(scenario: Scenario) -> Policy:
    """Uniformly random actions for every pursuer."""
    shape = (scenario.pursuers,)
    if scenario.continuous:
        return lambda obs, rng: rng.uniform(-1.0, 1.0, size=(len(obs), *shape, 2)).astype(
            np.float32
        )
    return lambda obs, rng: rng.integers(0, scenario.actions, size=(len(obs), *shape))


def pursuit_policy(scenario: Scenario) -> Policy:
    """Every pursuer straight at the evader, on its own (both control types, either drive)."""
    return lambda obs, rng: pursuit_actions(
        scenario, positions_from_obs(scenario, obs), headings_from_obs(scenario, obs)
    )


def grid_twin(scenario: Scenario) -> Scenario:
    """The grid game the oracle solves for a scenario: a physics scenario at the resolution
    of its cells, and against the random evader where the evader is learned (the oracle
    is then the team that is optimal against the random evader)."""
    evader = oracle_evader(scenario)
    if scenario.mode == "grid":
        return dataclasses.replace(scenario, evader=evader)
    return dataclasses.replace(
        scenario, mode="grid", control="discrete", physics=Physics(), evader=evader
    )


class OraclePolicy:
    """The optimal joint policy of a grid scenario, acting on global observations.

    ``scenario`` is a :class:`Scenario` or a scenario name/path; the solution is loaded from
    the cache or solved on construction (see :func:`load_or_solve_optimum`: the symmetric
    solver's on arenas too large for the dense one; ``progress``: report a solve on stderr).
    """

    def __init__(
        self,
        scenario: Scenario | str | Path,
        cache_dir: str | Path | None = None,
        solution: OracleSolution | SymmetricResult | None = None,
        progress: bool = False,
    ) -> None:
        self.scenario = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
        self.solution = solution or load_or_solve_optimum(
            self.scenario, cache_dir, progress=progress
        )

    def positions(self, obs: np.ndarray) -> np.ndarray:
        """Integer cells ``(B, N + 1, 2)`` decoded from observations ``(B, obs_dim)`` (with
        sensing, the team vector: its global-state prefix)."""
        obs = np.asarray(obs, dtype=np.float64)[:, : self.scenario.state_dim]
        n, size = self.scenario.pursuers, self.scenario.size
        return np.rint(obs.reshape(len(obs), n + 1, 2) * (size - 1)).astype(np.int64)

    def act(self, obs: np.ndarray) -> np.ndarray:
        """Optimal actions ``(B, N)`` int64 for observations ``(B, obs_dim)`` float32."""
        return self.solution.actions(self.positions(obs))

    def expected_capture_steps(self, positions: np.ndarray) -> float | np.ndarray:
        """See :meth:`OracleSolution.expected_capture_steps`."""
        return self.solution.expected_capture_steps(positions)


def oracle_policy(scenario: Scenario, progress: bool = False) -> Policy:
    """The exact optimum of the (grid twin of the) scenario; see the module docstring
    (``progress``: report a solve on stderr).

    Raises :class:`~a2cm_phys.config.ConfigError` when the oracle cannot solve it.
    """
    from ..solve import TooLargeError, UnsupportedError

    try:
        oracle = OraclePolicy(grid_twin(scenario), progress=progress)
    except (TooLargeError, UnsupportedError) as err:
        raise ConfigError(f"oracle policy: {err}") from None
    if scenario.mode == "grid":
        return lambda obs, rng: oracle.act(obs)
    top = scenario.size - 1
    directions = ACTION_DELTAS.astype(np.float32)

    def act(obs: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        cells = np.clip(np.floor(positions_from_obs(scenario, obs)), 0, top).astype(np.int64)
        moves = oracle.solution.actions(cells)
        if not scenario.continuous:
            return moves
        if scenario.differential:
            return steer(scenario, directions[moves], headings_from_obs(scenario, obs))
        return directions[moves]

    return act


def minimax_policy(scenario: Scenario, progress: bool = False) -> Policy:
    """The minimax team of a grid scenario (of its twin against the random evader where the
    evader is learned; the team does not depend on the evader; ``progress``: report a
    solve on stderr). Raises
    :class:`~a2cm_phys.config.ConfigError` outside grid mode or where it cannot be solved.
    """
    from ..solve import TooLargeError, UnsupportedError
    from ..solve.tables import TablePolicy
    from .sources import pursuer_source

    if scenario.mode != "grid":
        raise ConfigError("minimax policy: the minimax team is solved on grids only")
    twin = grid_twin(scenario)
    try:
        team = TablePolicy(twin, pursuer_source(twin, "minimax", progress=progress).table)
    except (TooLargeError, UnsupportedError) as err:
        raise ConfigError(f"minimax policy: {err}") from None
    state = slice(0, scenario.state_dim)  # with sensing, the team vector's state prefix
    return lambda obs, rng: team.act(np.asarray(obs)[:, state], rng, greedy=True)


def pursuer_policy(name: str, scenario: Scenario, progress: bool = False) -> Policy:
    """The named pursuer policy for ``scenario`` (one of :data:`PURSUER_POLICIES`;
    ``progress``: report a solver's progress on stderr). A policy with memory (``qmdp``,
    ``search``) is a new object at each call: give each evaluation its own."""
    solved = {"oracle": oracle_policy, "minimax": minimax_policy, "qmdp": qmdp_policy}
    scripted = {"random": random_policy, "pursuit": pursuit_policy, "search": search_policy}
    if name in solved:
        return solved[name](scenario, progress)
    if name not in scripted:
        known = ", ".join([*scripted, *solved])
        raise ConfigError(f"unknown pursuer policy {name!r} (known: {known})")
    return scripted[name](scenario)


@dataclass(frozen=True)
class Matchup:
    """One pairing of pursuers and evader, ready to play."""

    scenario: Scenario
    pursuers: Policy
    evader: Policy | None  # a learned evader's policy, actions (B, 1, ...); None: scripted
    label: str


def matchup(
    scenario: Scenario,
    pursuers: str,
    evader: str | None = None,
    *,
    greedy: bool = False,
    progress: bool = False,
) -> Matchup:
    """Pursuers ``pursuers`` (a run directory or one of :data:`PURSUER_POLICIES`) against
    ``evader`` (a run directory with a learned evader, or one of :data:`EVADER_POLICIES`;
    ``None``: the scenario's own evader, or the pursuers' run's evader when it is learned)
    in ``scenario``. Trained policies act greedily when ``greedy``; ``progress`` reports
    the solvers' progress (oracle, minimax, best response, equilibrium) on stderr.
    """
    from ..training.runs import load_trained_run, model_policy

    team = load_team(pursuers)
    pursuer_run = (
        None
        if team is not None or pursuers in PURSUER_POLICIES
        else _run(load_trained_run, "--pursuers", pursuers)
    )
    if pursuer_run is not None:
        check_layout(pursuer_run.scenario, scenario, pursuers, pursuer_run.pursuers)
    if team is not None:
        check_layout(team_scenario(team, pursuers), scenario, pursuers, team)
    evader_model, evader_name = None, evader or scenario.evader
    team_evader = None
    if evader == BEST_RESPONSE:
        evader_model = best_response_evader(scenario, pursuers, progress)
        evader_name = "learned"
    elif evader == EQUILIBRIUM:
        evader_model, evader_name = equilibrium_evader(scenario, progress), "learned"
    elif evader is not None and evader not in EVADER_POLICIES:
        run = _run(load_trained_run, "--evader", evader)
        if run.evader is None:
            raise ConfigError(f"--evader {evader}: the run has no learned evader")
        check_layout(run.scenario, scenario, evader, run.evader)
        evader_model, evader_name = run.evader, "learned"
    elif evader is None and scenario.evader == "learned" and team is not None:
        if "evader" not in team.actors:
            raise ConfigError(
                f"scenario '{scenario.name}' has a learned evader and {pursuers} exports none:"
                f" give --evader (a run directory, or one of {', '.join(EVADER_POLICIES)})"
            )
        team_evader = team.rollout_policy(greedy, side="evader")
    elif evader is None and scenario.evader == "learned":
        if pursuer_run is None or pursuer_run.evader is None:
            raise ConfigError(
                f"scenario '{scenario.name}' has a learned evader: give --evader (a run "
                f"directory, or one of {', '.join(EVADER_POLICIES)})"
            )
        evader_model = pursuer_run.evader
    game = dataclasses.replace(scenario, evader=evader_name)
    if pursuer_run is not None:
        pursuer_policy_ = model_policy(pursuer_run.pursuers, greedy)
        p_label = f"{_short(pursuers)} ({'greedy' if greedy else 'sampled'})"
    elif team is not None:
        pursuer_policy_ = team.rollout_policy(greedy)
        p_label = f"{pursuers} ({'greedy' if greedy else 'sampled'})"
    else:  # of the scenario, not the game: the oracle stays one team in a cross-play
        pursuer_policy_, p_label = pursuer_policy(pursuers, scenario, progress), pursuers
    e_label = _short(evader) if evader_model is not None and evader else evader_name
    e_policy = None if evader_model is None else model_policy(evader_model, greedy)
    if team_evader is not None:
        e_label, e_policy = f"{pursuers}'s", team_evader
    if evader == BEST_RESPONSE:  # deterministic: its table has one-hot rows
        e_label, e_policy = BEST_RESPONSE, model_policy(evader_model, greedy=True)
    if evader == EQUILIBRIUM:  # mixed: its greedy move would be some other policy
        e_label, e_policy = EQUILIBRIUM, model_policy(evader_model, greedy=False)
    return Matchup(game, pursuer_policy_, e_policy, f"{p_label} vs {e_label} evader")


def team_scenario(team: Team, spec: str) -> Scenario:
    """The scenario an exported team (``onnx:DIR``, ``pretrained:NAME``) was trained on,
    from its ``policy.json``."""
    return build(Scenario, team.scenario, f"{spec} (policy.json)")


def exported_scenario(spec: str) -> Scenario | None:
    """The scenario of the exported team ``spec`` names, or ``None`` if it names none."""
    team = load_team(spec)
    return None if team is None else team_scenario(team, spec)


LAYOUT_KEYS = ("mode", "pursuers", "control", "actions")
"""The scenario keys that decide a trained network's layout: the observation's length
(``mode``: 2 or 4 numbers per agent; ``pursuers``: how many agents, and actors), and its
actions (``control``: moves or commands; ``actions``: how many moves)."""


def check_layout(trained: Scenario, scenario: Scenario, run: str, model: Any = None) -> None:
    """A :class:`~a2cm_phys.config.ConfigError` naming ``run`` and the first key of
    :data:`LAYOUT_KEYS` in which ``scenario`` differs from the one the run was ``trained``
    on (or ``size``, for networks whose inputs hold the arena's size, one-hot cells or
    metric offsets: ``model.arena_bound``): its networks
    read the trained observation and play the trained actions, and nothing else. A
    scenario with more moves than the run's (5 with stay, for a run of 4) is accepted: the
    run plays a subset of them."""
    keys = [k for k in LAYOUT_KEYS if k != "actions" or not trained.continuous]
    if getattr(model, "arena_bound", False):
        keys.append("size")
    for key in keys:
        want, got = getattr(trained, key), getattr(scenario, key)
        if key == "actions" and want < got:  # moves are numbered alike: 4 of 5 is a subset
            continue
        if want != got:
            plays = "(vx, vy) commands" if trained.continuous else f"{trained.actions} moves"
            raise ConfigError(
                f"run {run} was trained with {key} = {want!r}, but the scenario"
                f" '{scenario.name}' has {key} = {got!r}: its networks read observations of"
                f" {trained.obs_dim} numbers and play {plays}; evaluate it on a scenario with"
                f" the same {', '.join(keys)}"
            )


def best_response_evader(scenario: Scenario, pursuers: str, progress: bool = False):
    """The evader's exact best response to ``pursuers`` (a run directory, ``random``,
    ``oracle`` or ``minimax``), as a table policy with the actors' interface (grids only;
    ``progress``: report the solve on stderr)."""
    from ..solve import TooLargeError, UnsupportedError
    from ..solve.best_response import evader_best_response
    from ..solve.tables import TablePolicy
    from .sources import SourceError, pursuer_source

    if scenario.mode != "grid":
        raise ConfigError("--evader best-response: exact best responses exist on grids only")
    twin = grid_twin(scenario)
    try:
        table = pursuer_source(twin, pursuers, progress=progress).table
        policy = evader_best_response(twin, table, progress=progress).policy
    except (SourceError, TooLargeError, UnsupportedError) as err:
        raise ConfigError(f"--evader best-response: {err}") from None
    return TablePolicy(twin, policy)


def equilibrium_evader(scenario: Scenario, progress: bool = False):
    """The game's equilibrium evader (:func:`~a2cm_phys.solve.cache.load_or_solve_value`: cached
    beside the oracle, or solved in minutes), as a table policy with the actors' interface
    (grids only; ``progress``: report the solve on stderr)."""
    from ..solve import TooLargeError, UnsupportedError
    from ..solve.cache import load_or_solve_value
    from ..solve.tables import TablePolicy

    if scenario.mode != "grid":
        raise ConfigError("--evader equilibrium: the game's value is solved on grids only")
    twin = grid_twin(scenario)
    try:
        return TablePolicy(twin, load_or_solve_value(twin, progress=progress).evader)
    except (TooLargeError, UnsupportedError) as err:
        raise ConfigError(f"--evader equilibrium: {err}") from None


def _run(load, option: str, spec: str):
    """A run directory named by ``option``, or an error that also lists the named policies."""
    names = PURSUER_POLICIES if option == "--pursuers" else (*EVADER_POLICIES, *SOLVED_EVADERS)
    try:
        return load(spec)
    except ConfigError as err:
        raise ConfigError(
            f"{option} {spec}: not one of {', '.join(names)}, nor a run ({err})"
        ) from None


def _short(path: str | None) -> str:
    return Path(path).name if path else "learned"
