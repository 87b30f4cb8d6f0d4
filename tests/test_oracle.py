"""The exact optimum (``a2cm_phys.oracle``) against hand values, brute force and heuristics.

Tiny arenas only (the 5x5 solve is marked slow). The brute force below is deliberately
naive: it enumerates every (state, joint action, evader move), steps each through the real
``GridRules.apply`` and runs plain value iteration on the resulting table, sharing nothing
with the solver's factorised backup.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from a2cm_phys.analysis.policies import OraclePolicy
from a2cm_phys.commands.oracle import main
from a2cm_phys.config import Scenario, load_scenario
from a2cm_phys.envs.evaders.scripted import STAY, blocked_grid, flee_actions
from a2cm_phys.envs.grid import GridCore, GridRules
from a2cm_phys.solve import GridModel, TooLargeError, solve_dp, state_visits
from a2cm_phys.solve.cache import load_or_solve
from a2cm_phys.solve.tables import flee_law


def grid(**overrides) -> Scenario:
    """The ``grid`` scenario with overrides; ``a__b`` stands for the dotted key ``a.b``."""
    return load_scenario("grid", {k.replace("__", "."): v for k, v in overrides.items()})


# --------------------------------------------------------------------------- brute force


class Enumerated:
    """Every transition of a tiny game, from ``GridRules.apply``, as flat arrays."""

    def __init__(self, sc: Scenario) -> None:
        rules = GridRules(sc)
        c, n, a = sc.size**2, sc.pursuers, sc.actions
        self.states = np.array(list(itertools.product(range(c), repeat=n + 1)))  # (S, N + 1)
        self.joint = np.array(list(itertools.product(range(a), repeat=n)))  # (J, N)
        self.moves = list(range(a)) if sc.evader != "static" else [STAY]
        s, j, b = len(self.states), len(self.joint), len(self.moves)
        cells = np.repeat(self.states, j * b, axis=0).T
        acts = np.tile(np.repeat(self.joint, b, axis=0), (s, 1))
        new, cap, coll, walls = rules.apply(cells, acts, np.tile(self.moves, s * j))
        mode = sc.collisions.mode
        rw = sc.rewards
        coll_r = rw.collision if mode != "off" else 0.0
        reward = rw.step + coll_r * coll + rw.capture * cap + rw.wall * walls
        self.reward = reward.reshape(s, j, b)
        self.go_on = ~(cap | ((mode == "terminate") & (coll > 0))).reshape(s, j, b)
        self.captured = cap.reshape(s, j, b)
        self.next = np.ravel_multi_index(tuple(new), (c,) * (n + 1)).reshape(s, j, b)
        self.prob = np.array([self._evader_law(sc, rules, st) for st in self.states])  # (S, B)
        self.valid = np.all(self.states[:, :-1] != self.states[:, -1:], axis=1)

    def _evader_law(self, sc: Scenario, rules: GridRules, state: np.ndarray) -> np.ndarray:
        if sc.evader != "flee":
            return np.full(len(self.moves), 1.0 / len(self.moves))
        xy = rules.cell_xy
        dist = []
        for b in self.moves:
            cell = rules.move[state[-1] * 5 + b]
            dist.append(min(abs(xy[cell] - xy[p]).sum() for p in state[:-1]))
        best = np.array(dist) == max(dist)
        return best / best.sum()

    def value_iteration(self, sweeps: int = 5000) -> np.ndarray:
        """Optimal expected return of every state, by plain value iteration."""
        v = np.zeros(len(self.states))
        for _ in range(sweeps):
            q = (self.prob[:, None, :] * (self.reward + self.go_on * v[self.next])).sum(-1)
            new = q.max(axis=1)
            if np.max(np.abs(new - v)) < 1e-13:
                return new
            v = new
        raise AssertionError("brute-force value iteration did not converge")

    def expected_steps(self, policy: np.ndarray) -> np.ndarray:
        """Expected steps to termination of a stochastic joint ``policy`` ``(S, J)``, solved
        exactly as the linear system ``(I - P) t = 1`` over the states."""
        s = len(self.states)
        p = np.zeros((s, s))
        flow = policy[:, :, None] * self.prob[:, None, :] * self.go_on
        np.add.at(p, (np.repeat(np.arange(s), flow[0].size), self.next.ravel()), flow.ravel())
        return np.linalg.solve(np.eye(s) - p, np.ones(s))


TINY = [
    {"size": 2, "pursuers": 1},
    {"size": 3, "pursuers": 1, "actions": 5},
    {"size": 2, "pursuers": 2},
    {"size": 3, "pursuers": 2},
    {"size": 3, "pursuers": 2, "evader": "flee"},
    {"size": 3, "pursuers": 2, "evader": "static", "actions": 5},
    # Terminate mode with a mild collision penalty: ending by a collision can pay off.
    {"size": 3, "pursuers": 2, "collisions__mode": "terminate", "rewards__collision": -0.5},
    {"size": 3, "pursuers": 2, "collisions__mode": "terminate", "rewards__collision": -50.0,
     "rewards__capture": 3.0, "rewards__wall": -0.25},
    {"size": 3, "pursuers": 2, "evader": "flee", "collisions__mode": "penalize",
     "rewards__collision": -2.0},
]  # fmt: skip


def _name(overrides: dict) -> str:
    return ",".join(f"{k}={v}" for k, v in overrides.items())


@pytest.mark.parametrize("overrides", TINY, ids=_name)
def test_value_matches_brute_force(overrides: dict) -> None:
    sc = grid(**overrides)
    brute = Enumerated(sc)
    expected = brute.value_iteration()
    sol = load_or_solve(sc, use_cache=False)
    ok = brute.valid
    np.testing.assert_allclose(sol.value[ok], expected[ok], rtol=0, atol=1e-9)
    # The greedy policy, replayed through the rules, earns the optimum.
    policy = np.zeros((len(brute.states), len(brute.joint)))
    policy[np.arange(len(policy)), sol.policy] = 1.0
    steps = brute.expected_steps(policy)
    np.testing.assert_allclose(sol.steps[ok], steps[ok], rtol=0, atol=1e-9)
    assert sol.meta["policy_check"] < 1e-9


# --------------------------------------------------------------------------- by hand


def test_two_by_two_random_by_hand() -> None:
    """One pursuer, random evader on 2x2, pursuer at (0, 0).

    Evader adjacent at (1, 0): the pursuer moves right onto its cell. The evader's move
    down or right bumps the wall (it stays: caught), left swaps with the pursuer (caught),
    up escapes to (1, 1), again adjacent. So A = 1 + A/4, A = 4/3. Waiting (bumping) catches
    only 1/4 and is worse; moving up catches nothing.
    Evader diagonal at (1, 1): moving right to (1, 0) catches the evader's move down (1/4),
    leaves it adjacent after up or right (bumps, 2/4) and diagonal after left (1/4):
    D = 1 + A/2 + D/4, so D = 20/9. Bumping (D = 1 + A/2 + D/2) is worse.
    """
    sol = load_or_solve(grid(size=2, pursuers=1), use_cache=False)
    assert sol.expected_capture_steps([(0, 0), (1, 0)]) == pytest.approx(4 / 3, abs=1e-9)
    assert sol.expected_capture_steps([(0, 0), (1, 1)]) == pytest.approx(20 / 9, abs=1e-9)
    assert sol.optimal_return([(0, 0), (1, 1)]) == pytest.approx(-20 / 9, abs=1e-9)
    assert tuple(sol.actions([(0, 0), (1, 0)])) == (3,)  # right, onto the evader
    assert sol.expected_capture_steps([(1, 1), (1, 1)]) == 0.0  # already caught


def test_static_evader_takes_manhattan_distance() -> None:
    """A static evader is caught in exactly the distance of the nearest pursuer."""
    sc = grid(size=3, pursuers=2, evader="static")
    sol = load_or_solve(sc, use_cache=False)
    xy = sol.model.rules.cell_xy
    states = sol.model.decode(np.arange(sol.model.n_states))
    dist = np.abs(xy[states[:-1]] - xy[states[-1]]).sum(-1).min(0)
    ok = dist > 0
    np.testing.assert_array_equal(sol.steps[ok], dist[ok])
    dist_law = sol.distribution([(0, 0), (2, 0), (1, 1)])
    assert dist_law.capture[1] == pytest.approx(1.0)  # distance 2: caught at step 2


def test_one_pursuer_cannot_catch_a_fleeing_evader() -> None:
    """2x2, one pursuer, flee: an evader diagonal to the pursuer stays (moving would bring it
    closer); an adjacent one moves to the cell diagonal to the pursuer's start-of-step cell,
    which the pursuer cannot reach in one step, and never into the pursuer's cell (no swap).
    So capture is impossible from every state."""
    sc = grid(size=2, pursuers=1, evader="flee")
    sol = load_or_solve(sc, use_cache=False)
    assert sol.meta["losing_states"] == 12
    assert sol.optimal_return([(0, 0), (1, 0)]) == -np.inf
    assert sol.expected_capture_steps([(0, 0), (1, 1)]) == np.inf


# --------------------------------------------------------------------------- heuristics


def chase_policy(brute: Enumerated, sc: Scenario) -> np.ndarray:
    """Each pursuer takes its first action that brings it closer (Manhattan) to the evader."""
    rules = GridRules(sc)
    xy = rules.cell_xy
    policy = np.zeros((len(brute.states), len(brute.joint)))
    index = {tuple(a): k for k, a in enumerate(brute.joint)}
    for s, state in enumerate(brute.states):
        evader = xy[state[-1]]
        acts = []
        for p in state[:-1]:
            now = abs(xy[p] - evader).sum()
            after = [abs(xy[rules.move[p * 5 + a]] - evader).sum() for a in range(sc.actions)]
            closer = [a for a, d in enumerate(after) if d < now]
            acts.append(closer[0] if closer else 0)
        policy[s, index[tuple(acts)]] = 1.0
    return policy


@pytest.mark.parametrize("overrides", [{"size": 3, "pursuers": 2}, {"size": 4, "pursuers": 1}])
def test_optimum_beats_heuristics(overrides: dict) -> None:
    sc = grid(**overrides)
    brute = Enumerated(sc)
    sol = load_or_solve(sc, use_cache=False)
    ok = brute.valid
    uniform = np.full((len(brute.states), len(brute.joint)), 1.0 / len(brute.joint))
    for policy in (chase_policy(brute, sc), uniform):
        steps = brute.expected_steps(policy)
        assert np.all(sol.steps[ok] <= steps[ok] + 1e-9)
    start = sol.index(sol.start_positions())
    assert sol.steps[start] < brute.expected_steps(uniform)[start] - 0.1


# --------------------------------------------------------------------------- playing it


# cells (1, 1) and (2, 1) blocked: a wall beside which fleeing moves bump and stay put
WALL = [{"x": 2.0, "y": 1.5, "width": 2.0, "height": 1.0}]


@pytest.mark.parametrize("obstacles", [[], WALL], ids=["open", "wall"])
def test_flee_law_matches_the_evader(obstacles: list) -> None:
    """The solver's flee distribution is the law of ``flee_actions`` over episode seeds
    (with obstacles, given the blocked cells as the grid core's evader reads them)."""
    sc = grid(size=4, pursuers=2, evader="flee", obstacles=obstacles)
    model = GridModel(sc)
    xy = model.rules.cell_xy.astype(np.float64)
    blocked = blocked_grid(sc)
    assert (blocked is None) == (not obstacles)
    rng = np.random.default_rng(1)
    draws = 4000
    states = np.flatnonzero(model.valid())
    if obstacles:  # the states where the wall changes the law: what is tested here
        law_open = flee_law(grid(size=4, pursuers=2, evader="flee"))
        states = states[np.any(law_open[states] != model.weights[states], axis=1)]
    for s in rng.choice(states, 25, replace=False):
        cells = model.decode(np.array([s]))[:, 0]
        seeds = np.arange(draws, dtype=np.uint64) * np.uint64(7919) + np.uint64(s)
        got = flee_actions(
            seeds, np.zeros(draws, dtype=np.int64), np.repeat(xy[cells[-1]][None], draws, 0),
            np.repeat(xy[cells[:-1]][None], draws, 0), sc.actions, 0, sc.size - 1, blocked,
        )  # fmt: skip
        freq = np.bincount(got, minlength=sc.actions) / draws
        law = model.weights[s]
        np.testing.assert_array_equal(freq > 0, law > 0)
        np.testing.assert_allclose(freq, law, atol=0.04)


@pytest.mark.parametrize("evader", ["random", "flee"])
def test_monte_carlo_in_grid_core_matches_expectation(evader: str) -> None:
    sc = grid(size=4, pursuers=2, evader=evader)
    policy = OraclePolicy(sc, solution=load_or_solve(sc, use_cache=False))
    episodes = 20000
    core = GridCore(sc, episodes)
    core.reset(np.arange(episodes), np.arange(episodes, dtype=np.uint64) + np.uint64(12345))
    length = np.zeros(episodes, dtype=np.int64)
    running = np.ones(episodes, dtype=bool)
    for _ in range(200):
        out = core.step(policy.act(core.observe()))
        length[running] += 1
        running &= ~out.terminated
        if not running.any():
            break
    assert not running.any()
    law = policy.solution.distribution()
    k = np.arange(1, len(law.capture) + 1)
    mean = policy.expected_capture_steps(policy.solution.start_positions())
    assert law.mean_length() == pytest.approx(mean, abs=1e-9)
    sd = np.sqrt(law.capture @ (k - mean) ** 2)
    assert abs(length.mean() - mean) < 4 * sd / np.sqrt(episodes)
    assert np.all(length <= k[-1])


@pytest.mark.parametrize("max_steps", [1000, 3])
def test_state_visits_sum_to_the_expected_length(max_steps: int) -> None:
    """Each step visits one state: the visits sum to E[min(length, max_steps)], the mean of
    the exact law, and from the start they equal the optimum's expected steps."""
    sc = grid(size=3, pursuers=2, max_steps=max_steps)
    sol = load_or_solve(sc, use_cache=False)
    start = int(sol.index(sol.start_positions()))
    visits = state_visits(sol.chain, start, max_steps)
    assert visits[start] == 1.0 and visits.min() == 0.0
    assert visits.sum() == pytest.approx(sol.distribution().mean_length(), rel=1e-12)
    if max_steps == 1000:
        assert visits.sum() == pytest.approx(sol.steps[start], rel=1e-9)
    else:
        assert visits.sum() < sol.steps[start]


def test_act_decodes_observations() -> None:
    sc = grid(size=3, pursuers=2)
    policy = OraclePolicy(sc, solution=load_or_solve(sc, use_cache=False))
    core = GridCore(sc, 64)
    rng = np.random.default_rng(0)
    core.cells = np.stack([rng.choice(9, 3, replace=False) for _ in range(64)], axis=1)
    act = policy.act(core.observe())
    assert act.shape == (64, 2) and act.dtype == np.int64
    np.testing.assert_array_equal(act, policy.solution.actions(core.positions()))


# --------------------------------------------------------------------------- cache and CLI


def test_cache_round_trip(tmp_path) -> None:
    sc = grid(size=3, pursuers=2, evader="flee")
    first = load_or_solve(sc, tmp_path)
    second = load_or_solve(sc, tmp_path)
    assert not first.cached and second.cached and second.path == first.path
    assert first.path is not None and first.path.parent == tmp_path
    for name in ("value", "policy", "steps"):
        np.testing.assert_array_equal(getattr(first, name), getattr(second, name))
    other = load_or_solve(grid(size=3, pursuers=2), tmp_path)  # another game, another file
    assert other.path != first.path and not other.cached


def test_cli_reports_and_caches(tmp_path, capsys) -> None:
    argv = ["--set", "size=3", "--set", "pursuers=2", "--cache-dir", str(tmp_path)]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "expected steps to capture: 1.853516" in out and "saved to" in out
    assert "P(capture <= k)" in out and "median" in out
    assert main(argv) == 0
    assert "loaded from" in capsys.readouterr().out


def test_too_large_is_one_line_and_exit_2(capsys) -> None:
    # beyond the dense solver (7x7 and up) the symmetric one answers, up to its own limit
    assert main(["--set", "size=14", "--no-cache"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "too large" in err and "1,475,789,056 joint states" in err
    assert "8.0 GiB" in err  # the limit it names
    with pytest.raises(TooLargeError, match="GiB"):
        GridModel(grid(size=3, pursuers=2), memory_budget=1000)


@pytest.mark.parametrize(
    "argv",
    [["--set", "size=1"], ["--scenario", "phys"], ["--set", "rewards.step=0"], ["--scenario", "x"]],
)
def test_bad_scenarios_exit_2(argv: list[str], capsys) -> None:
    assert main([*argv, "--no-cache"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and "\n" not in err


@pytest.mark.slow
def test_paper_grid_optimum(tmp_path) -> None:
    """5x5, 3 pursuers, random evader: the optimum from the corners is 770521/262144 steps
    (about 2.94), and capture is certain within 10 steps (~10 s, ~400 MB)."""
    sol = load_or_solve(load_scenario("grid"), tmp_path)
    assert sol.expected_capture_steps(sol.start_positions()) == pytest.approx(770521 / 262144)
    law = sol.distribution()
    assert law.p_capture == pytest.approx(1.0) and len(law.capture) == 10


def test_solve_dp_is_exact_on_finite_games() -> None:
    """A static evader makes the game deterministic: value iteration stops with zero residual."""
    result = solve_dp(GridModel(grid(size=3, pursuers=2, evader="static")))
    assert result.residual == 0.0 and result.lose is None
