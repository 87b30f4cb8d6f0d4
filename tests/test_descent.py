"""Exploitability descent (issue 14): the exact gradient of a pursuer team's worst case,
checked against the rules enumerated by hand, and its use in grid self-play."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import torch

from a2cm_phys.config import ConfigError, load_scenario, load_train, resolve_train
from a2cm_phys.envs.grid import GridRules
from a2cm_phys.solve.best_response import evader_best_response, pursuers_best_response
from a2cm_phys.solve.tables import model_table, n_states, start_state, state_cells
from a2cm_phys.solve.worst_case import EvaderGradient, WorstCaseGradient
from a2cm_phys.training.descent import ExploitabilityDescent, check_descent
from a2cm_phys.training.teams import make_teams

SMALL = {"size": 3, "pursuers": 2, "max_steps": 300}


def small(mode: str = "off"):
    return load_scenario("grid_vs", {**SMALL, "collisions": {"mode": mode}})


def random_table(scenario, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.dirichlet(np.ones(scenario.actions), size=(n_states(scenario), scenario.pursuers))


def enumerate_rules(scenario):
    """For every state, joint action and evader move, by ``GridRules.apply`` one at a time:
    the next state and whether the episode goes on."""
    n, a, s = scenario.pursuers, scenario.actions, n_states(scenario)
    cells = state_cells(scenario)
    rules = GridRules(scenario)
    joints = list(itertools.product(range(a), repeat=n))
    nxt = np.zeros((s, len(joints), a), dtype=np.int64)
    goes_on = np.zeros((s, len(joints), a), dtype=bool)
    shape = (scenario.size**2,) * (n + 1)
    for j, joint in enumerate(joints):
        for b in range(a):
            new, captured, collisions, _ = rules.apply(
                cells.copy(), np.tile(joint, (s, 1)), np.full(s, b)
            )
            nxt[:, j, b] = np.ravel_multi_index(tuple(new), shape)
            ends = captured | ((scenario.collisions.mode == "terminate") & (collisions > 0))
            goes_on[:, j, b] = ~ends
    return nxt, goes_on


def joint_probs(table: np.ndarray) -> np.ndarray:
    n = table.shape[1]
    out = table[:, 0]
    for i in range(1, n):
        out = (out[:, :, None] * table[:, i, None, :]).reshape(len(table), -1)
    return out


def brute_force(scenario, table, gamma, sweeps):
    """Values, best moves, per-pursuer advantages and discounted visits, by enumeration."""
    nxt, goes_on = enumerate_rules(scenario)
    valid = ~np.any(state_cells(scenario)[:-1] == state_cells(scenario)[-1], axis=0)
    w = joint_probs(table)
    v = np.zeros(len(table))
    for _ in range(sweeps):
        q = np.einsum("sj,sjb->sb", w, 1 + gamma * goes_on * v[nxt])
        v = np.where(valid, q.max(1), 0.0)
    choice = q.argmax(1)
    rows = np.arange(len(table))
    step = 1 + gamma * goes_on[rows, :, choice] * v[nxt[rows, :, choice]]  # (S, J)
    n, a = scenario.pursuers, scenario.actions
    step = step.reshape((len(table),) + (a,) * n)
    assert n == 2
    q_i = np.stack(
        [np.einsum("sab,sb->sa", step, table[:, 1]), np.einsum("sab,sa->sb", step, table[:, 0])],
        axis=1,
    )
    adv = q_i - (q_i * table).sum(-1, keepdims=True)
    visits, d = np.zeros(len(table)), np.zeros(len(table))
    d[start_state(scenario)] = 1.0
    for _ in range(400):
        visits += d
        flow = d[:, None] * w * goes_on[rows, :, choice]
        d = gamma * np.bincount(nxt[rows, :, choice].ravel(), flow.ravel(), len(table))
    return v, choice, adv, visits


@pytest.mark.parametrize("mode", ["off", "terminate"])
def test_undiscounted_values_are_the_exact_best_response(mode: str) -> None:
    scenario = small(mode)
    table = random_table(scenario, 0)
    gradient = WorstCaseGradient(scenario, 1.0, sweeps=scenario.max_steps)
    value = gradient.refresh(table)
    br = evader_best_response(scenario, table)
    np.testing.assert_allclose(gradient.values, br.values, rtol=0, atol=1e-8)
    assert value == pytest.approx(br.value_from_start, abs=1e-8)


@pytest.mark.parametrize("mode", ["off", "terminate"])
def test_advantages_and_visits_match_enumeration(mode: str) -> None:
    scenario, gamma = small(mode), 0.9
    table = random_table(scenario, 1)
    gradient = WorstCaseGradient(scenario, gamma, sweeps=200, trajectories=40_000, horizon=200)
    gradient.refresh(table)
    v, choice, adv, visits = brute_force(scenario, table, gamma, 200)
    np.testing.assert_allclose(gradient.values, v, atol=1e-10)
    np.testing.assert_array_equal(gradient.choice, choice)
    rows = np.arange(len(table))
    np.testing.assert_allclose(gradient.advantages(rows), adv, atol=1e-10)
    # sampled visits: the discounted counts of 40,000 games, per game, near the exact law
    got_rows, counts = gradient.visits(np.random.default_rng(0))
    sampled = np.zeros(len(table))
    sampled[got_rows] = counts
    assert np.abs(sampled - visits).sum() < 0.02 * visits.sum()


def test_states_drawn_for_the_gradient_follow_the_visits() -> None:
    """Each call draws 100 of 300 states; their weights sum to the visits' total, and over
    2,000 calls they average to the visits (unbiased)."""
    gradient = WorstCaseGradient(small(), 0.9, samples=100)
    rng = np.random.default_rng(4)
    rows = np.sort(rng.choice(10_000, 300, replace=False))
    weights = rng.exponential(size=300)
    same = gradient.sample(rng, rows[:100], weights[:100])  # no more than the draws: all
    assert np.array_equal(same[0], rows[:100]) and np.array_equal(same[1], weights[:100])
    mean = np.zeros(300)
    for _ in range(2_000):
        drawn_rows, drawn = gradient.sample(rng, rows, weights)
        assert len(drawn_rows) <= 100 and drawn.sum() == pytest.approx(weights.sum())
        mean[np.searchsorted(rows, drawn_rows)] += drawn / 2_000
    # 200,000 draws over 300 states: an L1 error of about 0.03 of the total
    assert np.abs(mean - weights).sum() < 0.06 * weights.sum()


def test_the_gradient_is_the_derivative_of_the_worst_case() -> None:
    """Σ_s d(s) Σ_i Σ_a δ_i(a|s) A_i(s, a) against a finite difference of V(s₀) along δ."""
    scenario, gamma = small(), 0.9
    table = random_table(scenario, 2)
    v, _, adv, visits = brute_force(scenario, table, gamma, 300)
    rng = np.random.default_rng(3)
    delta = rng.normal(size=table.shape)
    delta -= delta.mean(-1, keepdims=True)  # stays on the simplex
    predicted = (visits[:, None, None] * delta * adv).sum()
    eps = 1e-6
    moved = WorstCaseGradient(scenario, gamma, sweeps=300)
    start = WorstCaseGradient(scenario, gamma, sweeps=300)
    finite = (moved.refresh(table + eps * delta) - start.refresh(table)) / eps
    assert predicted == pytest.approx(finite, rel=1e-4)
    assert start.refresh(table) == pytest.approx(v[start_state(scenario)])


def test_descent_steps_lower_the_worst_case() -> None:
    """Ten steps of the actors against the exact best response make the exact worst case
    (horizon 300) of a fresh team fall by more than half."""
    scenario = small()
    cfg = load_train({"layers": 2, "hidden": 64, "encoding": "onehot", "descent_lr": 3e-3,
                      "descent_steps": 5, "descent_every": 1})  # fmt: skip
    cfg = resolve_train(scenario, cfg)
    pursuers, _ = make_teams(scenario, cfg)
    descent = ExploitabilityDescent(scenario, cfg, pursuers.model, seed=0)

    def worst_case() -> float:
        table = model_table(scenario, pursuers.model, scenario.pursuers)
        return evader_best_response(scenario, table).value_from_start

    before = worst_case()
    for _ in range(10):
        metrics = descent.step()
    after = worst_case()
    assert metrics["descent_states"] > 0
    assert after < 0.5 * before, (before, after)


@pytest.mark.parametrize("teams", ["pursuers", "both"])
def test_a_linear_descent_schedule_anneals_the_step_to_zero(teams: str) -> None:
    """At the run's start the linear schedule steps as the constant one does (the same
    weights, bit for bit); at its end its step size is 0 and no actor moves, while the
    constant schedule's still do."""
    scenario = small()

    def descent(schedule: str) -> ExploitabilityDescent:
        options = {"descent_every": 1, "descent_teams": teams, "descent_schedule": schedule}
        cfg = resolve_train(scenario, load_train(options))
        pursuers, evader = make_teams(scenario, cfg)
        return ExploitabilityDescent(scenario, cfg, pursuers.model, 0, evader.model)

    def actors(d: ExploitabilityDescent) -> list[torch.Tensor]:
        models = [d.model] if d.evader is None else [d.model, d.evader]
        return [p.detach().clone() for m in models for k, p in m.named_parameters()
                if k.startswith("actor_")]  # fmt: skip

    constant, linear = descent("constant"), descent("linear")
    constant.step(0.0)
    linear.step(0.0)
    for a, b in zip(actors(constant), actors(linear), strict=True):
        assert torch.equal(a, b)
    before = actors(linear)
    linear.step(1.0)
    assert all(torch.equal(a, b) for a, b in zip(before, actors(linear), strict=True))
    constant.step(1.0)
    assert not all(torch.equal(a, b) for a, b in zip(before, actors(constant), strict=True))


@pytest.mark.parametrize("teams", ["pursuers", "both"])
def test_descent_state_round_trips(teams: str) -> None:
    scenario = small()
    cfg = resolve_train(scenario, load_train({"descent_every": 1, "descent_teams": teams}))

    def descent(seed: int) -> ExploitabilityDescent:
        pursuers, evader = make_teams(scenario, cfg)
        return ExploitabilityDescent(scenario, cfg, pursuers.model, seed, evader.model)

    a = descent(0)
    a.step()
    b = descent(9)
    b.load_state_dict(a.state_dict())
    sides = [(a.gradient, a.rng, a.optimizer, b.gradient, b.rng, b.optimizer)]
    if teams == "both":
        sides.append((a.evader_gradient, a.evader_rng, a.evader_optimizer,
                      b.evader_gradient, b.evader_rng, b.evader_optimizer))  # fmt: skip
    for grad_a, rng_a, opt_a, grad_b, rng_b, opt_b in sides:
        np.testing.assert_array_equal(grad_a.values, grad_b.values)
        assert rng_a.random() == rng_b.random()
        assert torch.equal(
            opt_a.state_dict()["state"][0]["exp_avg"], opt_b.state_dict()["state"][0]["exp_avg"]
        )


@pytest.mark.parametrize(
    ("scenario", "options", "key"),
    [
        ("phys_vs", {"descent_every": 5}, "descent_every"),
        ("grid", {"descent_every": 5}, "descent_every"),
        ("phys", {"encoding": "onehot"}, "encoding"),
    ],
)
def test_descent_and_one_hot_inputs_need_a_grid(scenario: str, options: dict, key: str) -> None:
    with pytest.raises(ConfigError, match=f"key '{key}'"):
        resolve_train(load_scenario(scenario), load_train(options))


def test_descent_refuses_arenas_beyond_the_exact_solver() -> None:
    big = load_scenario("grid_vs", {"size": 9})
    with pytest.raises(ConfigError, match=r"key 'descent_every'.*too large"):
        check_descent(big, load_train({"descent_every": 5}))


def test_in_self_play_the_pursuers_learn_by_descent_alone(tmp_path) -> None:
    """Updates 1 and 3 step only the evader; update 2 and 4 also the pursuers' actors, by
    descent; the pursuers' learner (its critic) never moves. The summary says so."""
    from a2cm_phys.training.trainer import Trainer

    scenario = load_scenario("grid_vs", {**SMALL, "max_steps": 50})
    cfg = load_train({"num_envs": 4, "batch_size": 32, "updates": 4, "descent_every": 2})
    trainer = Trainer(scenario, resolve_train(scenario, cfg), tmp_path, record=False)

    def weights(model, prefix: str) -> list[torch.Tensor]:
        return [p.detach().clone() for k, p in model.named_parameters() if k.startswith(prefix)]

    history = []
    update = trainer._one_update

    def spy(on_step: object) -> None:
        before = [weights(trainer.model, p) for p in ("actor_", "critic_")]
        evader = weights(trainer.evader.model, "actor_")
        update(on_step)
        after = [weights(trainer.model, p) for p in ("actor_", "critic_")]
        moved = [not all(torch.equal(a, b) for a, b in zip(x, y, strict=True))
                 for x, y in zip(before, after, strict=True)]  # fmt: skip
        history.append((*moved, not all(
            torch.equal(a, b)
            for a, b in zip(evader, weights(trainer.evader.model, "actor_"), strict=True)
        ), "descent_value" in trainer.last_metrics))  # fmt: skip

    trainer._one_update = spy  # type: ignore[method-assign]
    assert trainer.run() == "done"
    # (pursuers' actors moved, their critic moved, the evader moved, descent logged)
    assert history == [(False, False, True, False), (True, False, True, True)] * 2
    summary = trainer.summary()
    assert "exploitability descent every 2 updates" in summary["opponents"]
    assert summary["descent_value"] == trainer.last_metrics["descent_value"] > 0


def random_evader(scenario, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.dirichlet(np.ones(scenario.actions), size=(n_states(scenario), 1))


def evader_gradient(scenario, gamma: float, sweeps: int) -> EvaderGradient:
    worst = WorstCaseGradient(scenario, gamma, trajectories=40_000, horizon=200)
    worst.refresh(random_table(scenario, 9))  # the next-state structures, any team
    return EvaderGradient(scenario, gamma, worst, sweeps=sweeps, first_sweeps=sweeps)


def evader_brute_force(scenario, evader, gamma, sweeps, best=None):
    """The pursuers' best-response costs, and against ``best`` (default: the brute force's
    own minimiser) the evader's advantages and the discounted visits, by enumeration."""
    nxt, goes_on = enumerate_rules(scenario)
    valid = ~np.any(state_cells(scenario)[:-1] == state_cells(scenario)[-1], axis=0)
    sigma, rows = evader[:, 0], np.arange(len(evader))
    v = np.zeros(len(evader))
    for _ in range(sweeps):
        q = np.einsum("sb,sjb->sj", sigma, 1 + gamma * goes_on * v[nxt])
        v = np.where(valid, q.min(1), 0.0)
    best = q.argmin(1) if best is None else best
    q_b = 1 + gamma * goes_on[rows, best] * v[nxt[rows, best]]  # (S, nb)
    adv = q_b - (q_b * sigma).sum(-1, keepdims=True)
    visits, d = np.zeros(len(evader)), np.zeros(len(evader))
    d[start_state(scenario)] = 1.0
    for _ in range(400):
        visits += d
        flow = d[:, None] * sigma * goes_on[rows, best]
        d = gamma * np.bincount(nxt[rows, best].ravel(), flow.ravel(), len(evader))
    return v, q, adv, visits


def test_undiscounted_evader_values_are_the_pursuers_best_response() -> None:
    scenario = small()
    table = random_evader(scenario, 0)
    gradient = evader_gradient(scenario, 1.0, sweeps=300)
    value = gradient.refresh(table)
    br = pursuers_best_response(scenario, table)
    valid = ~np.any(state_cells(scenario)[:-1] == state_cells(scenario)[-1], axis=0)
    np.testing.assert_allclose(gradient.values[valid], br.values[valid], rtol=0, atol=1e-8)
    assert value == pytest.approx(br.value_from_start, abs=1e-8)


def test_evader_advantages_and_visits_match_enumeration() -> None:
    scenario, gamma = small(), 0.9
    table = random_evader(scenario, 1)
    gradient = evader_gradient(scenario, gamma, sweeps=200)
    gradient.refresh(table)
    v, q, adv, visits = evader_brute_force(scenario, table, gamma, 200, best=None)
    valid = ~np.any(state_cells(scenario)[:-1] == state_cells(scenario)[-1], axis=0)
    np.testing.assert_allclose(gradient.values[valid], v[valid], atol=1e-10)
    rows = np.arange(len(table))
    # its joint action is a minimiser (ties may go either way), and against it:
    assert np.all(q[rows, gradient.best] <= q.min(1) + 1e-10)
    _, _, adv, visits = evader_brute_force(scenario, table, gamma, 200, best=gradient.best)
    np.testing.assert_allclose(gradient.advantages(rows), adv, atol=1e-10)
    got_rows, counts = gradient.visits(np.random.default_rng(0))
    sampled = np.zeros(len(table))
    sampled[got_rows] = counts
    assert np.abs(sampled - visits).sum() < 0.02 * visits.sum()


def test_the_evader_gradient_is_the_derivative_of_its_worst_case() -> None:
    """Σ_s d(s) Σ_b δ(b|s) A(s, b) against a finite difference of V(s₀) along δ."""
    scenario, gamma = small(), 0.9
    table = random_evader(scenario, 2)
    gradient = evader_gradient(scenario, gamma, sweeps=300)
    value = gradient.refresh(table)
    _, _, adv, visits = evader_brute_force(scenario, table, gamma, 300, best=gradient.best)
    rng = np.random.default_rng(3)
    delta = rng.normal(size=table.shape)
    delta -= delta.mean(-1, keepdims=True)
    predicted = (visits[:, None] * delta[:, 0] * adv).sum()
    eps = 1e-6
    moved = evader_gradient(scenario, gamma, sweeps=300).refresh(table + eps * delta)
    assert predicted == pytest.approx((moved - value) / eps, rel=1e-4)
    assert predicted != pytest.approx(0.0, abs=1e-3)  # a real direction


def test_evader_descent_raises_its_worst_case() -> None:
    """Ten steps of a fresh evader against the pursuers' exact best response make that best
    response's capture time (exact, horizon 300) grow."""
    scenario = small()
    cfg = load_train({"layers": 2, "hidden": 64, "encoding": "onehot", "descent_lr": 3e-3,
                      "descent_steps": 5, "descent_every": 1, "descent_teams": "both"})  # fmt: skip
    cfg = resolve_train(scenario, cfg)
    pursuers, evader = make_teams(scenario, cfg)
    descent = ExploitabilityDescent(scenario, cfg, pursuers.model, 0, evader.model)

    def worst_case() -> float:
        table = model_table(scenario, evader.model, 1)
        return pursuers_best_response(scenario, table).value_from_start

    before = worst_case()
    for _ in range(10):
        metrics = descent.step()
    after = worst_case()
    assert metrics["evader_descent_states"] > 0 and metrics["evader_descent_value"] > 0
    assert after > before + 0.1, (before, after)


@pytest.mark.parametrize(
    ("overrides", "options", "match"),
    [
        ({}, {"descent_teams": "both"}, "key 'descent_teams'.*descent_every"),
        ({"collisions": {"mode": "terminate"}}, {"descent_every": 2, "descent_teams": "both"},
         "key 'descent_teams'.*terminate"),
    ],
)  # fmt: skip
def test_evader_descent_needs_descent_and_no_ending_collisions(
    overrides: dict, options: dict, match: str
) -> None:
    with pytest.raises(ConfigError, match=match):
        resolve_train(load_scenario("grid_vs", {**SMALL, **overrides}), load_train(options))


def test_with_both_teams_the_evader_learns_by_descent_alone(tmp_path) -> None:
    """With ``descent_teams = "both"`` the evader's actor moves at the descent updates only
    (its rollout learner is not stepped), and the summary says both teams descend."""
    from a2cm_phys.training.trainer import Trainer

    scenario = load_scenario("grid_vs", {**SMALL, "max_steps": 50})
    cfg = load_train({"num_envs": 4, "batch_size": 32, "updates": 4, "descent_every": 2,
                      "descent_teams": "both"})  # fmt: skip
    trainer = Trainer(scenario, resolve_train(scenario, cfg), tmp_path, record=False)
    moved = []
    update = trainer._one_update

    def spy(on_step: object) -> None:
        before = [p.detach().clone() for p in trainer.evader.model.parameters()]
        update(on_step)
        after = list(trainer.evader.model.parameters())
        moved.append(not all(torch.equal(a, b) for a, b in zip(before, after, strict=True)))

    trainer._one_update = spy  # type: ignore[method-assign]
    assert trainer.run() == "done"
    assert moved == [False, True, False, True]
    summary = trainer.summary()
    assert summary["opponents"].startswith("both teams: exploitability descent")
    assert summary["evader_descent_value"] == trainer.last_metrics["evader_descent_value"] > 0


def test_the_descent_preset_is_grid_self_play_with_deeper_one_hot_actors() -> None:
    from a2cm_phys.config import preset

    cfg = load_train(preset("descent"))
    assert cfg.descent_every > 0 and cfg.layers == 2 and cfg.encoding == "onehot"
    assert cfg.descent_teams == "both"
    check_descent(load_scenario("grid_vs"), resolve_train(load_scenario("grid_vs"), cfg))
    with pytest.raises(ConfigError, match="key 'descent_every'"):
        resolve_train(load_scenario("grid"), cfg)
