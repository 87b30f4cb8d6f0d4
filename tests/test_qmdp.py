"""``qmdp``: the Bayes filter over the evader's cell against brute-force posteriors, the
QMDP choice against a direct enumeration through the game's rules, the team reading only
what the pursuers sense, beliefs forgotten at episode ends, and the command line."""

from __future__ import annotations

import dataclasses
import itertools
import json

import numpy as np
import pytest

from a2cm_phys.analysis.policies import pursuer_policy
from a2cm_phys.analysis.qmdp import JointQ
from a2cm_phys.commands.evaluate import main
from a2cm_phys.config import ConfigError, load_scenario
from a2cm_phys.envs.core import default_start
from a2cm_phys.envs.grid import GridRules
from a2cm_phys.envs.sensing import team_observation
from a2cm_phys.envs.vector import VectorEnv
from a2cm_phys.solve.belief import EvaderFilter, evader_moves, pursuer_sightings
from a2cm_phys.solve.cache import load_or_solve
from a2cm_phys.solve.tables import state_of_cells


def _start_cells(sc) -> np.ndarray:
    xy = default_start(sc.size, sc.pursuers)
    return xy[:, 0] + sc.size * xy[:, 1]  # (N + 1,)


def _sighting(sc, rules: GridRules, cells: np.ndarray) -> int:
    """The pooled sighting of cells ``(N + 1,)``: the evader's cell, or -1 (by hand)."""
    xy = rules.cell_xy[cells]
    near = np.abs(xy[:-1] - xy[-1]).max(-1) <= sc.sensing.radius
    return int(cells[-1]) if near.any() else -1


def _play(sc, rules, pursuer_actions, evader_actions, start=None):
    """Cells ``(T + 1, N + 1)`` of one game from ``start`` (default: the fixed start), and
    whether some step captured."""
    cells = (_start_cells(sc) if start is None else np.asarray(start))[:, None]
    path, caught = [cells[:, 0]], False
    for a, m in zip(pursuer_actions, evader_actions, strict=True):
        cells, captured, _, _ = rules.apply(cells, np.asarray(a)[None], np.array([m]))
        path.append(cells[:, 0])
        caught |= bool(captured[0])
    return np.array(path), caught


def _posterior(sc, rules, pursuer_actions, sightings) -> np.ndarray:
    """The evader's cell given the pursuers' moves, no capture and the pooled sightings
    ``(t + 1,)``, by enumerating every evader move sequence."""
    moves = evader_moves(sc)
    post = np.zeros(sc.size**2)
    for seq in itertools.product(moves, repeat=len(pursuer_actions)):
        path, caught = _play(sc, rules, pursuer_actions, seq)
        seen = [_sighting(sc, rules, cells) for cells in path]
        if caught or seen != list(sightings):
            continue
        post[path[-1, -1]] += len(moves) ** -len(seq)
    return post / post.sum()


def _team_obs(sc, rules, cells: np.ndarray) -> np.ndarray:
    """Team vectors ``(B, team_dim)`` of cells ``(B, N + 1)``."""
    state = rules.cell_obs[cells].reshape(len(cells), -1)
    return team_observation(sc, state, rules.cell_xy[cells])


def _true_games(sc, rules, steps: int, games: int, seed: int):
    """Pursuer and evader move sequences of ``games`` games that end no capture early."""
    rng, out = np.random.default_rng(seed), []
    moves = evader_moves(sc)
    while len(out) < games:
        acts = rng.integers(0, sc.actions, (steps, sc.pursuers))
        seq = rng.choice(moves, steps)
        path, caught = _play(sc, rules, acts, seq)
        if not caught:
            out.append((acts, path))
    return out


@pytest.mark.parametrize(
    ("size", "pursuers", "actions", "radius", "steps"),
    [(3, 1, 4, 1, 4), (3, 1, 5, 1, 3), (4, 2, 4, 1, 5), (3, 1, 4, 0.5, 4), (4, 2, 4, 0.5, 4)],
)
def test_the_filter_is_the_brute_force_posterior(size, pursuers, actions, radius, steps) -> None:
    """(A radius under one cell senses only the pursuers' own cells: there the rule that a
    swap of cells is a capture shows, which sightings of the cell left hide otherwise.)"""
    overrides = {"size": size, "pursuers": pursuers, "actions": actions}
    sc = load_scenario("grid_pomdp", {**overrides, "sensing": {"radius": radius}})
    shared = dataclasses.replace(sc, sensing=dataclasses.replace(sc.sensing, share=True))
    rules, filt = GridRules(sc), EvaderFilter(sc)
    games = _true_games(sc, rules, steps, games=3, seed=size + pursuers + actions)
    paths = np.stack([path for _, path in games], axis=1)  # (T + 1, B, N + 1)
    belief = before = None
    for t in range(steps + 1):
        obs = _team_obs(sc, rules, paths[t])
        cells, seen = pursuer_sightings(sc, obs)
        np.testing.assert_array_equal(cells, paths[t][:, :-1])
        pooled = pursuer_sightings(shared, _team_obs(shared, rules, paths[t]))
        np.testing.assert_array_equal(pooled[1], seen)  # share: the same pooled sightings
        if t == 0:
            belief = filt.observe(filt.initial(cells), cells, seen)
        else:
            belief = filt.update(belief, before, cells, seen)
        before = cells
        for g, (acts, path) in enumerate(games):
            sights = [_sighting(sc, rules, c) for c in path[: t + 1]]
            want = _posterior(sc, rules, acts[:t], sights)
            np.testing.assert_allclose(belief[g], want, rtol=0, atol=1e-12)
    assert (belief > 0).sum() > len(games)  # the beliefs spread: the test meant something


@pytest.mark.parametrize(
    ("size", "pursuers", "distance", "steps"), [(3, 1, 2, 3), (4, 2, 2, 3), (4, 1, 3, 3)]
)
def test_from_random_starts_the_filter_is_the_brute_force_posterior(
    size, pursuers, distance, steps
) -> None:
    """From random starts the belief begins uniform over the evader's valid cells given the
    pursuers' (the sampler is uniform over valid starts) and stays the exact posterior: the
    sum over every valid evader start and every evader move sequence."""
    sc = load_scenario(
        "grid_pomdp_random",
        {"size": size, "pursuers": pursuers, "start": {"min_evader_distance": distance}},
    )
    rules, filt, moves = GridRules(sc), EvaderFilter(sc), evader_moves(sc)
    xy, rng, spread = rules.cell_xy, np.random.default_rng(size * 10 + pursuers), False
    for _ in range(4):
        placed = rng.choice(size * size, pursuers, replace=False)
        far = np.abs(xy[:, None] - xy[placed][None]).sum(-1).min(-1) >= distance
        starts = np.flatnonzero(far)  # the evader's valid cells given the pursuers'
        acts = rng.integers(0, sc.actions, (steps, pursuers))
        start = [*placed, rng.choice(starts)]
        path, caught = _play(sc, rules, acts, rng.choice(moves, steps), start)
        if caught:
            continue
        sights = [_sighting(sc, rules, c) for c in path]
        belief = None
        for t in range(steps + 1):
            cells, seen = pursuer_sightings(sc, _team_obs(sc, rules, path[t][None]))
            assert seen[0] == sights[t]
            if t == 0:
                belief = filt.observe(filt.initial(cells), cells, seen)
            else:
                belief = filt.update(belief, path[t - 1][None, :-1], cells, seen)
            want = np.zeros(size * size)
            for e0 in starts:
                for seq in itertools.product(moves, repeat=t):
                    p, c = _play(sc, rules, acts[:t], seq, [*placed, e0])
                    if not c and [_sighting(sc, rules, x) for x in p] == sights[: t + 1]:
                        want[p[-1, -1]] += len(moves) ** -t
            np.testing.assert_allclose(belief[0], want / want.sum(), rtol=0, atol=1e-12)
            spread |= np.count_nonzero(belief[0]) > 1
    assert spread  # some belief was not a single cell: the start's uncertainty was tested


def _direct_value(sc, sol, rules, pursuers: np.ndarray, belief: np.ndarray) -> np.ndarray:
    """``Σ_e b(e) Q(p, e, a)`` for every joint action, move by move through the rules."""
    rw, moves = sc.rewards, evader_moves(sc)
    coll = rw.collision if sc.collisions.mode != "off" else 0.0
    out = []
    for joint in itertools.product(range(sc.actions), repeat=sc.pursuers):
        total = 0.0
        for e in np.flatnonzero(belief):
            for m in moves:
                cells = np.append(pursuers, e)[:, None]
                new, captured, collisions, walls = rules.apply(
                    cells, np.array([joint]), np.array([m])
                )
                r = rw.step + rw.wall * walls[0] + coll * collisions[0] + rw.capture * captured[0]
                ends = captured[0] or (sc.collisions.mode == "terminate" and collisions[0] > 0)
                v = 0.0 if ends else sol.value[state_of_cells(sc, new[:, 0])]
                total += belief[e] / len(moves) * (r + v)
        out.append(total)
    return np.array(out)


GAMES = [
    {"size": 4, "pursuers": 2},
    {"size": 4, "pursuers": 2, "actions": 5, "evader": "static"},
    {
        "size": 3, "pursuers": 2, "collisions": {"mode": "terminate"},
        "rewards": {"step": -1.0, "collision": -20.0, "wall": -0.25, "capture": 2.0},
    },
    {
        "size": 3, "pursuers": 2, "actions": 5, "collisions": {"mode": "penalize"},
        "rewards": {"step": -1.0, "collision": -5.0},
    },
]  # fmt: skip


@pytest.mark.parametrize("overrides", GAMES)
def test_qmdp_takes_the_best_joint_action_of_a_direct_enumeration(overrides, tmp_path) -> None:
    sc = load_scenario("grid_pomdp", overrides)
    sol = load_or_solve(sc, tmp_path)
    rules, q, rng = GridRules(sc), JointQ(sol), np.random.default_rng(7)
    c = sc.size**2
    for _ in range(6):
        pursuers = rng.integers(0, c, sc.pursuers)
        belief = rng.random(c) * (rng.random(c) < 0.6)
        belief[pursuers] = 0.0
        belief[rng.choice(np.setdiff1d(np.arange(c), pursuers))] += 0.1
        belief /= belief.sum()
        direct = _direct_value(sc, sol, rules, pursuers, belief)
        mine = q.expected(pursuers[None], belief[None])[0]
        np.testing.assert_allclose(mine, direct, rtol=1e-12, atol=1e-9 * np.abs(direct).max())
        chosen = q.best(pursuers[None], belief[None])[0]
        index = np.ravel_multi_index(tuple(chosen), (sc.actions,) * sc.pursuers)
        assert direct[index] >= direct.max() - 1e-9 * abs(direct.max())
    # a sure belief gives the oracle's own value: the same objective
    cells = np.stack(np.unravel_index(rng.choice(sol.model.n_states, 40), sol.model.shape))
    cells = cells[:, np.all(cells[:-1] != cells[-1], axis=0)]
    sure = np.eye(c)[cells[-1]]
    best = q.expected(cells[:-1].T, sure).max(axis=1)
    np.testing.assert_allclose(best, sol.value[state_of_cells(sc, cells)], rtol=1e-9, atol=1e-8)


def _scrambled(sc, obs: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    out = obs.copy()
    out[:, : sc.state_dim] = rng.random((len(obs), sc.state_dim), dtype=np.float32)
    return out


def test_the_team_reads_only_what_the_pursuers_sense_and_forgets_ended_games() -> None:
    sc = load_scenario("grid_pomdp")
    honest, blind = pursuer_policy("qmdp", sc), pursuer_policy("qmdp", sc)
    env, rng = VectorEnv(sc, 8), np.random.default_rng(3)
    obs, ended, ends, spread = env.reset(5), np.ones(8, dtype=bool), 0, False
    for _ in range(150):
        cells, seen = pursuer_sightings(sc, obs)
        filt = honest.filter
        want = filt.observe(filt.initial(cells), cells, seen)  # a new episode: the known start
        if honest.belief is not None:
            going = filt.update(honest.belief, honest.cells, cells, seen)
            want[~ended] = going[~ended]
        actions = honest(obs, rng)
        np.testing.assert_array_equal(honest.belief, want)
        np.testing.assert_array_equal(blind(_scrambled(sc, obs, rng), rng), actions)
        np.testing.assert_array_equal(blind.belief, honest.belief)
        spread |= bool(((honest.belief > 0).sum(1) > 1).any())
        # half the games wander at random: the filter follows the pursuers it senses,
        # whoever moved them, and random walks let the beliefs spread
        wander = rng.integers(0, sc.actions, actions.shape)
        actions = np.where(rng.random((8, 1)) < 0.5, wander, actions)
        step = env.step(actions, validate=False)
        obs, ended = step.obs, step.terminated | step.truncated
        if ended.any():
            ends += 1
            honest.episodes_ended(ended)
            blind.episodes_ended(ended)
    env.close()
    assert ends > 10 and spread  # episodes ended mid-batch, and beliefs had spread


def test_qmdp_and_search_are_refused_where_they_do_not_apply() -> None:
    for name, scenario, why in [
        ("qmdp", "grid", "has no sensing"),
        ("qmdp", "phys_cont_pomdp", "is not a grid"),
        ("search", "grid_pomdp", "is not physics with continuous control"),
        ("search", "phys_cont", "has no sensing"),
    ]:
        with pytest.raises(ConfigError, match=f"scenario '{scenario}' {why}"):
            pursuer_policy(name, load_scenario(scenario))
    flee = load_scenario("grid_pomdp", {"evader": "flee"})
    with pytest.raises(ConfigError, match="flee evader"):
        pursuer_policy("qmdp", flee)
    assert callable(pursuer_policy("search", load_scenario("phys_cont_pomdp")))


def test_evaluate_plays_qmdp_no_better_than_the_full_observation_optimum(capsys) -> None:
    argv = ["--scenario", "grid_pomdp", "--pursuers", "qmdp", "--episodes", "200"]
    assert main([*argv, "--json", "--no-progress"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["policy"] == "qmdp vs random evader"
    assert report["capture_rate"]["value"] == 1.0
    mean = report["capture_steps"]["mean"]
    se = (mean["hi"] - mean["lo"]) / (2 * 1.96)  # the bootstrap 95% interval's half-width
    optimum = report["reference"]["capture_steps"]  # exact: no policy beats it on average
    assert report["reference"]["exact"]
    assert mean["value"] + 4 * se >= optimum
    assert mean["value"] < 2 * optimum  # and it is no random walk (random: tens of steps)


def test_on_grid_pomdp_the_team_never_loses_the_evader_so_qmdp_is_optimal() -> None:
    """Every joint state qmdp can reach on grid_pomdp (the known start, then every evader
    move that does not end the episode), with the belief a point on the evader: each step's
    sightings pin it down again. So qmdp plays the oracle's Q-maximising moves throughout,
    and its expected capture time is the full-observation optimum itself."""
    sc = load_scenario("grid_pomdp")
    team, rules, n = pursuer_policy("qmdp", sc), GridRules(sc), sc.pursuers
    filt, q = team.filter, team.values
    frontier, visited, steps = _start_cells(sc)[None], set(), 0
    cells, seen = pursuer_sightings(sc, _team_obs(sc, rules, frontier))
    assert np.count_nonzero(filt.observe(filt.initial(cells), cells, seen)) == 1
    while len(frontier):
        frontier = np.array([s for s in frontier if tuple(s) not in visited]).reshape(-1, n + 1)
        visited.update(map(tuple, frontier))
        if not len(frontier):
            break
        belief = np.eye(sc.size**2)[frontier[:, n]]  # a point on the evader
        actions = q.best(frontier[:, :n], belief)
        following = []
        for move in evader_moves(sc):
            new, captured, _, _ = rules.apply(frontier.T, actions, np.full(len(frontier), move))
            new, going = new.T[~captured], ~captured
            if not going.any():
                continue
            cells, seen = pursuer_sightings(sc, _team_obs(sc, rules, new))
            after = filt.update(belief[going], frontier[going, :n], cells, seen)
            np.testing.assert_array_equal(after, np.eye(sc.size**2)[new[:, n]])
            following.append(new)
            steps += len(new)
        frontier = np.unique(np.concatenate([np.empty((0, n + 1), int), *following]), axis=0)
    assert len(visited) > 20 and steps > 20


@pytest.mark.parametrize("name", ["oracle", "minimax"])
def test_the_full_observation_references_play_partially_observed_grids(
    name, tmp_path, monkeypatch
) -> None:
    """With sensing, ``oracle`` and ``minimax`` read the team vector's state prefix (they
    are the full-observation references): they play, and the agents' slices change nothing."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    sc = load_scenario("grid_pomdp", {"size": 3, "pursuers": 2})
    plain = load_scenario("grid", {"size": 3, "pursuers": 2})
    env, rng = VectorEnv(sc, 6), np.random.default_rng(0)
    obs = env.reset(1)
    for _ in range(5):
        obs = env.step(rng.integers(0, 4, (6, 2)), validate=False).obs
    env.close()
    slices = obs.copy()
    slices[:, sc.state_dim :] = rng.random((6, obs.shape[1] - sc.state_dim))
    team = pursuer_policy(name, sc)(obs, rng)
    np.testing.assert_array_equal(pursuer_policy(name, sc)(slices, rng), team)
    np.testing.assert_array_equal(pursuer_policy(name, plain)(obs[:, : sc.state_dim], rng), team)
