"""Exact best responses (``a2cm_phys.solve.best_response``) against brute force and by hand.

The brute force shares nothing with the solver: the grid rules are re-written below in
plain Python (SPEC §2), every (state, joint action, evader move) is enumerated, and the
finite-horizon expectimax runs on the resulting explicit table.
"""

from __future__ import annotations

import dataclasses
import itertools
from pathlib import Path

import numpy as np
import pytest

from a2cm_phys.commands.oracle import main
from a2cm_phys.config import Scenario, load_scenario
from a2cm_phys.envs.grid import GridCore
from a2cm_phys.solve import GridModel, TooLargeError, solve_dp
from a2cm_phys.solve.best_response import (
    evader_best_response,
    evaluate_tables,
    pursuers_best_response,
)
from a2cm_phys.solve.cache import load_or_solve
from a2cm_phys.solve.pursuer_step import PursuerStep
from a2cm_phys.solve.tables import (
    TablePolicy,
    check_table,
    joint_observations,
    joint_policy_table,
    model_table,
    scripted_evader_table,
    state_index,
    uniform_table,
    valid_states,
)

UP, DOWN, LEFT, RIGHT, STAY = range(5)
DELTA = [(0, 1), (0, -1), (-1, 0), (1, 0), (0, 0)]


def grid(**overrides) -> Scenario:
    """The ``grid`` scenario with overrides; ``a__b`` stands for the dotted key ``a.b``."""
    return load_scenario("grid", {k.replace("__", "."): v for k, v in overrides.items()})


# --------------------------------------------------------------------------- brute force


def move(size: int, cell: tuple[int, int], action: int) -> tuple[int, int]:
    """SPEC §2: a move off the arena stays."""
    x, y = cell[0] + DELTA[action][0], cell[1] + DELTA[action][1]
    return (x, y) if 0 <= x < size and 0 <= y < size else cell


def met(old_a, new_a, old_b, new_b) -> bool:
    """Same cell after the move, or swapped cells."""
    return new_a == new_b or (new_a == old_b and new_b == old_a)


class Brute:
    """Every transition of a tiny game, from the rules written out above."""

    def __init__(self, sc: Scenario, evader_moves: int) -> None:
        size, n, a = sc.size, sc.pursuers, sc.actions
        cells = [(x, y) for y in range(size) for x in range(size)]  # cell x + size * y
        self.states = list(itertools.product(range(size**2), repeat=n + 1))
        self.joint = list(itertools.product(range(a), repeat=n))
        self.index = {s: k for k, s in enumerate(self.states)}
        s_, j_, b_ = len(self.states), len(self.joint), evader_moves
        self.next = np.zeros((s_, j_, b_), dtype=np.int64)
        self.capture = np.zeros((s_, j_, b_), dtype=bool)
        self.end = np.zeros((s_, j_, b_), dtype=bool)
        terminate = sc.collisions.mode == "terminate"
        for k, state in enumerate(self.states):
            old = [cells[c] for c in state]
            for j, acts in enumerate(self.joint):
                new_p = [move(size, old[i], acts[i]) for i in range(n)]
                coll = any(
                    met(old[i], new_p[i], old[h], new_p[h])
                    for i in range(n)
                    for h in range(i + 1, n)
                )
                for b in range(b_):
                    new_e = move(size, old[-1], b)
                    cap = any(met(old[i], new_p[i], old[-1], new_e) for i in range(n))
                    nxt = tuple(x + size * y for x, y in [*new_p, new_e])
                    self.next[k, j, b] = self.index[nxt]
                    self.capture[k, j, b] = cap
                    self.end[k, j, b] = cap or (terminate and coll)
        self.valid = np.array([all(p != s[-1] for p in s[:-1]) for s in self.states])

    def joint_probs(self, table: np.ndarray) -> np.ndarray:
        """``(S, J)`` product probabilities of a pursuer table ``(S, N, A)``."""
        out = np.ones((len(self.states), len(self.joint)))
        for j, acts in enumerate(self.joint):
            for i, act in enumerate(acts):
                out[:, j] *= table[:, i, act]
        return out

    def expectimax(self, pursuers: np.ndarray, horizon: int, evader: np.ndarray | None = None):
        """``(steps, P(capture), P(end))`` within ``horizon`` from every state; the evader
        maximises the steps, or plays ``evader (S, B)``."""
        p = self.joint_probs(pursuers)[:, :, None]  # (S, J, 1)
        go = ~self.end
        v = np.zeros((3, len(self.states)))
        for _ in range(horizon):
            q = [
                (p * (1.0 + go * v[0][self.next])).sum(1),
                (p * (self.capture + go * v[1][self.next])).sum(1),
                (p * (self.end + go * v[2][self.next])).sum(1),
            ]  # each (S, B)
            if evader is None:
                top = q[0] >= q[0].max(1, keepdims=True) - 1e-9  # then least captured
                cap = np.where(top, q[1], np.inf)
                best = np.argmax(cap <= cap.min(1, keepdims=True) + 1e-12, axis=1)
                v = np.stack([x[np.arange(len(best)), best] for x in q])
            else:
                v = np.stack([(evader * x).sum(1) for x in q])
            v[:, ~self.valid] = 0.0
        return v

    def optimal_pursuit(self, evader: np.ndarray) -> np.ndarray:
        """Minimal expected steps to the end against ``evader (S, B)`` (value iteration)."""
        go = ~self.end
        v = np.zeros(len(self.states))
        for _ in range(10_000):
            new = (evader[:, None, :] * (1.0 + go * v[self.next])).sum(-1).min(1)
            new[~self.valid] = 0.0
            if np.max(np.abs(new - v)) < 1e-13:
                return new
            v = new
        raise AssertionError("brute-force value iteration did not converge")


def dirichlet(sc: Scenario, agents: int, seed: int, width: int | None = None) -> np.ndarray:
    rng = np.random.default_rng(seed)
    s = sc.size ** (2 * (sc.pursuers + 1))
    return rng.dirichlet(np.ones(width or sc.actions), (s, agents))


def one_hot(sc: Scenario, agents: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    s = sc.size ** (2 * (sc.pursuers + 1))
    return np.eye(sc.actions)[rng.integers(0, sc.actions, (s, agents))]


TINY = [
    {"size": 2, "pursuers": 1, "max_steps": 7},
    {"size": 2, "pursuers": 2, "max_steps": 6, "actions": 5},
    {"size": 3, "pursuers": 2, "max_steps": 6},
    {"size": 3, "pursuers": 2, "max_steps": 5, "collisions__mode": "terminate"},
]


def _name(overrides: dict) -> str:
    return ",".join(f"{k}={v}" for k, v in overrides.items())


# --------------------------------------------------------------------------- evader side


@pytest.mark.parametrize("overrides", TINY, ids=_name)
@pytest.mark.parametrize("policy", ["uniform", "dirichlet", "one_hot"])
def test_evader_best_response_matches_expectimax(overrides: dict, policy: str) -> None:
    sc = grid(**overrides)
    n = sc.pursuers
    table = {
        "uniform": lambda: uniform_table(sc, n),
        "dirichlet": lambda: dirichlet(sc, n, 1),
        "one_hot": lambda: one_hot(sc, n, 2),
    }[policy]()
    brute = Brute(sc, sc.actions)
    steps, capture, end = brute.expectimax(table, sc.max_steps)
    kinds = ["general"]
    kinds += ["product"] if policy == "uniform" and sc.collisions.mode != "terminate" else []
    kinds += ["deterministic"] if policy == "one_hot" else []
    for kind in kinds:
        br = evader_best_response(sc, table, tol=-1.0, kind=kind)
        assert br.outcome.iterations == sc.max_steps
        np.testing.assert_allclose(br.values, steps, rtol=0, atol=1e-12)
        np.testing.assert_allclose(
            br.outcome.p_capture[brute.valid], capture[brute.valid], atol=1e-12
        )
        np.testing.assert_allclose(br.outcome.p_end[brute.valid], end[brute.valid], atol=1e-12)
        # the returned rule is the first step's: one step of it, then V_{H-1}, is V_H
        before = brute.expectimax(table, sc.max_steps - 1)[0]
        p = brute.joint_probs(table)[:, :, None]
        q = (p * (1.0 + ~brute.end * before[brute.next])).sum(1)
        chosen = q[np.arange(len(q)), br.policy[:, 0, :].argmax(1)]
        np.testing.assert_allclose(chosen[brute.valid], steps[brute.valid], atol=1e-12)


@pytest.mark.parametrize("overrides", TINY, ids=_name)
def test_fixed_evader_matches_enumeration(overrides: dict) -> None:
    sc = grid(**overrides)
    pursuers, evader = dirichlet(sc, sc.pursuers, 3), dirichlet(sc, 1, 4)
    brute = Brute(sc, sc.actions)
    steps, capture, end = brute.expectimax(pursuers, sc.max_steps, evader[:, 0])
    out = evaluate_tables(sc, pursuers, evader, tol=-1.0)
    np.testing.assert_allclose(out.values, steps, rtol=0, atol=1e-12)
    np.testing.assert_allclose(out.p_capture[brute.valid], capture[brute.valid], atol=1e-12)
    np.testing.assert_allclose(out.p_end[brute.valid], end[brute.valid], atol=1e-12)


def test_early_stop_is_within_its_bound() -> None:
    """Against the oracle capture is certain: the induction stops early, with the values of
    the full horizon, and the stationary rule it returns achieves them."""
    sc = grid(size=3, pursuers=2, max_steps=200)
    table = joint_policy_table(sc, load_or_solve(sc, use_cache=False).policy)
    early = evader_best_response(sc, table)
    full = evader_best_response(sc, table, tol=-1.0)  # every step
    assert early.outcome.iterations < 20 and full.outcome.iterations == 200
    assert early.outcome.error_bound <= 1e-9
    np.testing.assert_allclose(early.values, full.values, rtol=0, atol=1e-9)
    played = evaluate_tables(sc, table, early.policy)
    np.testing.assert_allclose(played.values, early.values, rtol=0, atol=1e-9)
    stochastic = 0.7 * table + 0.3 * uniform_table(sc, 2)  # capture only likely
    early = evader_best_response(sc, stochastic, tol=1e-6)
    full = evader_best_response(sc, stochastic, tol=-1.0)
    assert early.outcome.iterations < 200
    assert abs(early.value_from_start - full.value_from_start) <= 1e-6


def test_static_box_by_hand() -> None:
    """3x3, four pursuers on the edges' midpoints, each pushing into its wall: it stays.
    An evader in the centre steps onto a pursuer whatever it does: captured at step 1.
    Open the top (three pursuers) and it goes up, then bumps into the top wall for ever:
    it lasts exactly max_steps. From a corner beside two pursuers it bumps: max_steps too."""
    pushes = {(1, 0): DOWN, (0, 1): LEFT, (2, 1): RIGHT, (1, 2): UP}
    for n in (4, 3):
        sc = grid(size=3, pursuers=n, max_steps=40)
        cells = list(pushes)[:n]
        table = np.zeros((9 ** (n + 1), n, 4))
        for i, cell in enumerate(cells):
            table[:, i, pushes[cell]] = 1.0
        br = evader_best_response(sc, table)
        centre = int(state_index(sc, [*cells, (1, 1)]))
        corner = int(state_index(sc, [*cells, (0, 0)]))
        if n == 4:
            assert br.values[centre] == 1.0 and br.outcome.p_capture[centre] == 1.0
        else:
            assert br.values[centre] == 40.0 and br.outcome.p_capture[centre] == 0.0
            assert br.policy[centre, 0].argmax() == UP
        assert br.values[corner] == 40.0


def test_random_pair_on_two_by_two_by_hand() -> None:
    """2x2, uniformly random pursuers at (0,0) and (1,1), evader at (1,0), two steps.
    Up (onto (1,1)) survives only if that pursuer goes left: 1/4. Left (onto (0,0))
    survives only if that pursuer goes up: 1/4. Bumping (down or right) survives unless
    either pursuer steps onto (1,0): 3/4 · 3/4. So V_2 = 1 + 9/16, by bumping down."""
    sc = grid(size=2, pursuers=2, max_steps=2)
    br = evader_best_response(sc, uniform_table(sc, 2))
    s = int(state_index(sc, [(0, 0), (1, 1), (1, 0)]))
    assert br.values[s] == pytest.approx(25 / 16, abs=1e-15)
    assert br.policy[s, 0].argmax() == DOWN


def test_truncation_gives_exactly_max_steps() -> None:
    """Pursuers that always stay (5 actions): the evader never has to be caught."""
    sc = grid(size=3, pursuers=2, actions=5, max_steps=300)
    table = np.zeros((9**3, 2, 5))
    table[..., STAY] = 1.0
    br = evader_best_response(sc, table)
    valid = valid_states(sc)
    assert np.all(br.values[valid] == 300.0) and br.outcome.iterations == 300
    assert np.all(br.outcome.p_capture[valid] == 0.0)


@pytest.mark.parametrize("overrides", [{"size": 3, "pursuers": 2}, {"size": 4, "pursuers": 2}])
def test_oracle_worst_case_is_at_least_its_random_value(overrides: dict) -> None:
    sc = grid(max_steps=100, **overrides)
    sol = load_or_solve(sc, use_cache=False)
    table = joint_policy_table(sc, sol.policy)
    worst = evader_best_response(sc, table)
    random = evaluate_tables(sc, table, uniform_table(sc, 1))
    # the truncated evaluation agrees with the oracle's own chain (another code path)
    assert random.values[worst.start] == pytest.approx(sol.distribution().mean_length(), abs=1e-9)
    assert np.all(worst.values >= random.values - 1e-9)
    assert worst.value_from_start > random.values[worst.start] + 0.5


# --------------------------------------------------------------------------- pursuers side


@pytest.mark.parametrize(
    "overrides", [{"size": 2, "pursuers": 1}, {"size": 3, "pursuers": 2}], ids=_name
)
@pytest.mark.parametrize("evader", ["dirichlet", "flee", "static", "one_hot"])
def test_pursuers_best_response_matches_value_iteration(overrides: dict, evader: str) -> None:
    sc = grid(max_steps=400, **overrides)
    table = {
        "dirichlet": lambda: dirichlet(sc, 1, 6),
        "flee": lambda: scripted_evader_table(sc, "flee"),
        "static": lambda: scripted_evader_table(sc, "static"),
        "one_hot": lambda: one_hot(sc, 1, 7),
    }[evader]()
    br = pursuers_best_response(sc, table)
    brute = Brute(sc, table.shape[-1])
    steps, _, _ = brute.expectimax(br.policy, sc.max_steps, table[:, 0])
    np.testing.assert_allclose(br.values, steps, rtol=0, atol=1e-9)
    if br.meta["losing_states"]:  # an evader that can escape somewhere: no finite optimum
        assert evader in ("one_hot", "flee") and overrides["size"] == 2
        return
    best = brute.optimal_pursuit(table[:, 0])  # capture is certain within a few steps
    np.testing.assert_allclose(br.values[brute.valid], best[brute.valid], rtol=0, atol=1e-8)


@pytest.mark.parametrize("name", ["random", "flee", "static"])
def test_scripted_tables_give_the_scripted_oracle(name: str) -> None:
    sc = grid(size=3, pursuers=2)
    scripted = load_or_solve(dataclasses.replace(sc, evader=name), use_cache=False)
    table = solve_dp(GridModel(sc, evader_probs=scripted_evader_table(sc, name)))
    np.testing.assert_allclose(table.value, scripted.value, rtol=0, atol=1e-12)


# --------------------------------------------------------------------------- tables


class LinearSoftmax:
    """A stand-in for a model: softmax of a fixed linear map of the observation."""

    def __init__(self, obs_dim: int, agents: int, actions: int) -> None:
        self.w = np.random.default_rng(0).normal(size=(obs_dim, agents, actions))
        self.calls = 0

    def action_probs_np(self, obs: np.ndarray) -> np.ndarray:
        self.calls += 1
        logits = np.einsum("bd,dka->bka", obs, self.w)
        e = np.exp(logits - logits.max(-1, keepdims=True))
        return e / e.sum(-1, keepdims=True)


def test_model_table_and_table_policy_round_trip() -> None:
    sc = grid(size=3, pursuers=2)
    model = LinearSoftmax(6, 2, 4)
    table = model_table(sc, model, 2, batch=100)
    assert table.shape == (729, 2, 4) and model.calls == 8
    obs = joint_observations(sc)
    np.testing.assert_allclose(table, model.action_probs_np(obs), rtol=0, atol=1e-15)
    core = GridCore(sc, 16)
    rng = np.random.default_rng(3)
    core.cells = np.stack([rng.choice(9, 3, replace=False) for _ in range(16)], axis=1)
    np.testing.assert_array_equal(
        joint_observations(sc, state_index(sc, core.positions())), core.observe()
    )
    policy = TablePolicy(sc, table)
    np.testing.assert_array_equal(
        policy.action_probs_np(core.observe()), model.action_probs_np(core.observe())
    )
    greedy = policy.act(core.observe(), rng, greedy=True)
    np.testing.assert_array_equal(greedy, model.action_probs_np(core.observe()).argmax(-1))
    with pytest.raises(ValueError, match=r"expected \(1, 4\)"):
        model_table(sc, model, 1)


def test_check_table_says_what_is_wrong() -> None:
    sc = grid(size=2, pursuers=1)
    good = uniform_table(sc, 1)
    with pytest.raises(ValueError, match="shape"):
        check_table(sc, good[:, :, :3], "pursuers")
    with pytest.raises(ValueError, match="negative"):
        check_table(sc, -good, "pursuers")
    with pytest.raises(ValueError, match="sum to 1"):
        check_table(sc, 2 * good, "evader")
    assert check_table(sc, scripted_evader_table(sc, "static"), "evader").shape == (16, 1, 5)
    with pytest.raises(ValueError, match="shape"):
        check_table(sc, scripted_evader_table(sc, "static"), "pursuers")


def test_too_large_says_the_limit() -> None:
    sc = grid(size=3, pursuers=2)
    with pytest.raises(TooLargeError, match="limit"):
        PursuerStep(sc, uniform_table(sc, 2), np.arange(4), memory_budget=1000)


# --------------------------------------------------------------------------- command line

SMALL = ["--set", "size=3", "--set", "pursuers=2", "--set", "max_steps=50"]


def test_cli_evader_best_response(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    sc = grid(size=3, pursuers=2, max_steps=50)
    argv = [*SMALL, "--best-response", "evader", "--cache-dir", str(tmp_path)]
    assert main([*argv, "--pursuers", "random"]) == 0
    out = capsys.readouterr().out
    worst = evader_best_response(sc, uniform_table(sc, 2)).value_from_start
    assert f"worst-case capture time: {worst:.6f}" in out and "random evader" in out
    assert main([*argv, "--pursuers", "oracle"]) == 0
    out = capsys.readouterr().out
    assert "worst-case capture time: 6.000000" in out
    assert "expected capture time: 1.853516" in out  # the oracle's random-evader value


@pytest.mark.parametrize("evader", ["random", "flee", "static"])
def test_cli_pursuers_best_response(
    evader: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    sc = grid(size=3, pursuers=2, max_steps=50)
    argv = [*SMALL, "--best-response", "pursuers", "--evader", evader]
    assert main([*argv, "--cache-dir", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    value = pursuers_best_response(sc, scripted_evader_table(sc, evader)).value_from_start
    assert f"expected capture time: {value:.6f}" in out


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--best-response", "evader", "--pursuers", "no/such/run"], "no checkpoint"),
        (["--set", "pursuers=4", "--best-response", "evader", "--pursuers", "random"], "limit"),
        (["--best-response", "pursuers", "--evader", "no/such/run"], "no/such/run"),
        (["--pursuers", "random"], "--best-response evader"),
        (["--best-response", "evader", "--evader", "flee"], "--best-response pursuers"),
        (["--scenario", "phys", "--best-response", "evader", "--pursuers", "random"], "grid"),
    ],
)
def test_cli_errors_are_one_line(
    argv: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main([*argv, "--no-cache"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and "\n" not in err and message in err


def test_cli_with_a_trained_run(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A run's actors (general table) against the evader's best response; the scenario is
    the run's own when ``--scenario`` is not given."""
    from a2cm_phys.config import load_train, resolve_train
    from a2cm_phys.training.runs import load_trained
    from a2cm_phys.training.trainer import Trainer

    sc = grid(size=3, pursuers=2, max_steps=30)
    cfg = load_train({"num_envs": 4, "updates": 2})
    assert Trainer(sc, resolve_train(sc, cfg), tmp_path, record=False).run() == "done"
    assert main(["--best-response", "evader", "--pursuers", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    _, model = load_trained(tmp_path)
    table = model_table(sc, model, 2)
    worst = evader_best_response(sc, table).value_from_start
    assert "general table" in out and f"worst-case capture time: {worst:.6f}" in out
    assert (
        main(["--scenario", "grid", "--best-response", "evader", "--pursuers", str(tmp_path)]) == 2
    )
    assert "trained on grid 3x3" in capsys.readouterr().err


# --------------------------------------------------------------------------- minimax bounds


def brute_bounds(b: Brute, horizon: int) -> tuple[np.ndarray, np.ndarray]:
    """``(V_lo, V_hi)`` of the evader-first and pursuers-first games, by loops over states."""
    lo, hi = np.zeros(len(b.states)), np.zeros(len(b.states))
    for _ in range(horizon):
        new_lo, new_hi = np.zeros_like(lo), np.zeros_like(hi)
        joint, moves = range(len(b.joint)), range(b.next.shape[2])
        for k in np.flatnonzero(b.valid):

            def steps(v: np.ndarray, j: int, m: int, k: int = k) -> float:
                return 1.0 if b.capture[k, j, m] else 1.0 + v[b.next[k, j, m]]

            new_hi[k] = min(max(steps(hi, j, m) for m in moves) for j in joint)
            new_lo[k] = max(min(steps(lo, j, m) for j in joint) for m in moves)
        lo, hi = new_lo, new_hi
    return lo, hi


@pytest.mark.parametrize(
    "overrides",
    [
        {"size": 2, "pursuers": 2, "max_steps": 20},
        {"size": 3, "pursuers": 1, "max_steps": 12},  # one pursuer: the evader can run for ever
        {"size": 3, "pursuers": 2, "max_steps": 30, "collisions__mode": "penalize"},
    ],
)
def test_minimax_bounds_match_brute_force(overrides: dict) -> None:
    from a2cm_phys.solve.minimax import minimax_bounds

    sc = grid(**overrides)
    bounds = minimax_bounds(sc)
    lo, hi = brute_bounds(Brute(sc, sc.actions), sc.max_steps)
    np.testing.assert_array_equal(bounds.lower, lo)
    np.testing.assert_array_equal(bounds.upper, hi)
    assert np.all(bounds.lower <= bounds.upper)


def test_minimax_team_is_escaped_exactly_as_long_as_the_upper_bound() -> None:
    from a2cm_phys.solve.minimax import minimax_bounds

    sc = grid(size=3, pursuers=2, max_steps=30)
    bounds = minimax_bounds(sc)
    team = joint_policy_table(sc, bounds.policy)
    br = evader_best_response(sc, team)
    valid = valid_states(sc)
    np.testing.assert_allclose(br.values[valid], bounds.upper[valid], atol=1e-9)
    assert np.any(bounds.lower < bounds.upper)  # moving first costs a team something
    # No team, however it randomises, is escaped for less than the lower bound.
    oracle = joint_policy_table(sc, load_or_solve(sc, use_cache=False).policy)
    for table in (team, oracle, uniform_table(sc, 2)):
        worst = evader_best_response(sc, table).values
        assert np.all(worst[valid] >= bounds.lower[valid] - 1e-9)


def test_minimax_refuses_games_it_cannot_bound() -> None:
    from a2cm_phys.solve import UnsupportedError
    from a2cm_phys.solve.minimax import minimax_bounds

    with pytest.raises(UnsupportedError, match="collisions end the episode"):
        minimax_bounds(grid(size=3, pursuers=2, collisions__mode="terminate"))
    with pytest.raises(UnsupportedError, match="grids only"):
        minimax_bounds(load_scenario("phys"))


def test_cli_minimax_team_prints_the_bounds(capsys: pytest.CaptureFixture[str]) -> None:
    from a2cm_phys.solve.minimax import minimax_bounds

    bounds = minimax_bounds(grid(size=3, pursuers=2, max_steps=50))
    argv = [*SMALL, "--best-response", "evader", "--pursuers", "minimax"]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert f"worst-case capture time: {bounds.upper_from_start:.6f}" in out
    assert f"at least {bounds.lower_from_start:g}" in out
    assert f"at most {bounds.upper_from_start:g}" in out
    assert main([*argv, "--set", "collisions.mode=terminate"]) == 2
    assert "collisions end the episode" in capsys.readouterr().err


def test_minimax_team_is_escaped_for_its_bound_in_play() -> None:
    from a2cm_phys.analysis.evaluation import play
    from a2cm_phys.analysis.policies import matchup
    from a2cm_phys.solve.minimax import minimax_bounds

    sc = grid(size=3, pursuers=2, max_steps=50)
    upper = minimax_bounds(sc).upper_from_start
    game = matchup(sc, "minimax", "best-response")  # both deterministic, a fixed start
    result = play(game.scenario, game.pursuers, 8, 4, 0, game.evader)
    assert np.all(result.lengths == upper) and result.captured.all()
    random = matchup(sc, "minimax", "random")
    assert play(random.scenario, random.pursuers, 200, 8, 0).lengths.max() <= upper
