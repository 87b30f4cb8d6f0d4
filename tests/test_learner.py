"""Learner: gradient flow, A2C/A2CM advantage wiring, NaN guard, resume, bandits (discrete
and Gaussian), the loss against a plain float64 reference, and the pieces of issue 12:
GAE, advantage normalisation, PopArt value normalisation and split reward components."""

from __future__ import annotations

import copy
import dataclasses

import numpy as np
import pytest
import torch
import torch.nn.functional as F
from torch.distributions import Categorical

from a2cm_phys.algos.distributions import GaussianActions
from a2cm_phys.algos.layers import StackedLinear
from a2cm_phys.algos.learner import Learner
from a2cm_phys.algos.losses import NonFiniteLoss
from a2cm_phys.algos.models import ActorCritic
from a2cm_phys.config import ConfigError, Train, load_scenario, load_train, preset, resolve_train
from a2cm_phys.training.rollout import allocate_batch

torch.set_num_threads(1)


GRID = load_scenario("grid")


def paper_cfg(**options: object) -> Train:
    """The paper's method (``--preset paper``) with ``options``, resolved on the grid: the
    plain loss these tests check piece by piece (the defaults add our pieces on top)."""
    return resolve_train(GRID, Train(**{**preset("paper"), **options}))


N, OBS, A = 3, 8, 4


def model(algo: str, seed: int = 0, hidden: int = 32) -> ActorCritic:
    """A small seeded model for ``algo``."""
    return ActorCritic(
        OBS,
        N,
        A,
        hidden,
        shared_critic=algo == "a2cm",
        generator=torch.Generator().manual_seed(seed),
    )


def random_batch(t: int = 16, b: int = 2, seed: int = 0) -> dict[str, torch.Tensor]:
    """A random time-major batch with a terminal and a truncated step."""
    g = torch.Generator().manual_seed(seed)
    terminated = torch.zeros(t, b, dtype=torch.bool)
    truncated = torch.zeros(t, b, dtype=torch.bool)
    terminated[3, 0] = True
    truncated[7, b - 1] = True
    return {
        "obs": torch.rand(t, b, OBS, generator=g),
        "actions": torch.randint(0, A, (t, b, N), generator=g),
        "rewards": -torch.rand(t, b, generator=g),
        "terminated": terminated,
        "truncated": truncated,
        "final_obs": torch.rand(t, b, OBS, generator=g),
        "next_obs": torch.rand(b, OBS, generator=g),
    }


def params(m: torch.nn.Module) -> list[torch.Tensor]:
    """Copies of all parameters."""
    return [p.detach().clone() for p in m.parameters()]


@pytest.mark.parametrize("algo", ["a2c", "a2cm"])
def test_update_metrics_and_gradients_reach_every_head(algo: str) -> None:
    m = model(algo)
    learner = Learner(m, paper_cfg(algo=algo))
    before = params(m)
    metrics = learner.update(random_batch())
    assert set(metrics) == {
        "policy_loss",
        "value_loss",
        "entropy",
        "mean_advantage",
        "grad_norm",
        "loss",
    }
    assert all(np.isfinite(v) for v in metrics.values())
    assert 0 < metrics["entropy"] <= np.log(A)
    for layer in (m.actor_hidden, m.actor_out, m.critic_hidden, m.critic_out):
        for i in range(layer.n):  # every actor slice, and every critic slice
            assert layer.weight.grad[i].abs().sum() > 0
            assert layer.bias.grad[i].abs().sum() > 0
    assert all(not torch.equal(p, q) for p, q in zip(before, m.parameters(), strict=True))


def test_grad_norm_and_clipping() -> None:
    m = model("a2cm")
    metrics = Learner(m, paper_cfg()).update(random_batch())
    manual = torch.linalg.vector_norm(torch.stack([p.grad.norm() for p in m.parameters()]))
    assert metrics["grad_norm"] == pytest.approx(manual.item(), rel=1e-5)
    m2 = model("a2cm")
    clipped = Learner(m2, paper_cfg(max_grad_norm=1e-3)).update(random_batch())
    assert clipped["grad_norm"] == pytest.approx(metrics["grad_norm"], rel=1e-5)  # pre-clip
    after = torch.linalg.vector_norm(torch.stack([p.grad.norm() for p in m2.parameters()]))
    assert after.item() == pytest.approx(1e-3, rel=1e-3)


def actor0_grad(m: ActorCritic, batch: dict, **options: object) -> list[torch.Tensor]:
    """Gradient of agent 0's actor after one update on ``batch``."""
    Learner(m, paper_cfg(algo="a2c" if m.n_critics > 1 else "a2cm", **options)).update(batch)
    return [m.actor_hidden.weight.grad[0].clone(), m.actor_out.weight.grad[0].clone()]


# advantage and value normalisation are per critic: they must not couple A2C's pairs
OURS = {"normalize_advantages": True, "value_norm": True, "lr_schedule": "linear"}


@pytest.mark.parametrize("options", [{}, OURS], ids=["paper", "ours"])
def test_a2c_actor_i_uses_only_critic_i(options: dict) -> None:
    batch = random_batch()
    base = actor0_grad(model("a2c"), batch, **options)
    other_critic = model("a2c")
    with torch.no_grad():
        other_critic.critic_out.bias[1] += 5.0  # change agent 1's critic only
    other = actor0_grad(other_critic, batch, **options)
    assert all(torch.equal(x, y) for x, y in zip(base, other, strict=True))
    own_critic = model("a2c")
    with torch.no_grad():
        own_critic.critic_out.bias[0] += 5.0  # change agent 0's critic
    assert not torch.equal(base[1], actor0_grad(own_critic, batch, **options)[1])


def test_truncation_bootstraps_from_final_obs() -> None:
    batch = random_batch()
    base = Learner(model("a2cm"), paper_cfg()).update(batch)
    moved = dict(batch, final_obs=batch["final_obs"].clone())
    moved["final_obs"][5] += 1.0  # step 5 did not end: never read
    assert Learner(model("a2cm"), paper_cfg()).update(moved) == base
    moved["final_obs"][7, 1] += 1.0  # step 7 of env 1 was truncated: its value is read
    assert Learner(model("a2cm"), paper_cfg()).update(moved)["value_loss"] != base["value_loss"]


def test_reward_scale() -> None:
    batch = random_batch()
    scaled = Learner(model("a2c"), paper_cfg(algo="a2c", reward_scale=0.1)).update(batch)
    pre = Learner(model("a2c"), paper_cfg(algo="a2c")).update(
        dict(batch, rewards=batch["rewards"] * 0.1)
    )
    assert scaled == pytest.approx(pre, rel=1e-5)


def test_non_finite_loss_does_not_step() -> None:
    m = model("a2cm")
    learner = Learner(m, paper_cfg())
    learner.update(random_batch(seed=1))  # optimiser state exists
    before, opt_before = params(m), learner.optimizer.state_dict()
    sq = [s["square_avg"].clone() for s in learner.optimizer.state.values()]
    batch = random_batch(seed=2)
    batch["rewards"][4, 1] = float("nan")
    with pytest.raises(NonFiniteLoss, match="non-finite"):
        learner.update(batch)
    assert all(torch.equal(p, q) for p, q in zip(before, m.parameters(), strict=True))
    assert learner.optimizer.state_dict()["state"][0]["step"] == opt_before["state"][0]["step"]
    assert all(
        torch.equal(a, s["square_avg"])
        for a, s in zip(sq, learner.optimizer.state.values(), strict=True)
    )


def test_state_dict_resume_is_bit_exact() -> None:
    cfg = paper_cfg(algo="a2c")
    a = Learner(model("a2c", seed=0), cfg)
    for s in range(3):
        a.update(random_batch(seed=s))
    saved = a.state_dict()
    a.update(random_batch(seed=3))  # must not change the saved copy
    b = Learner(model("a2c", seed=9), cfg)
    b.load_state_dict(saved)
    a.load_state_dict(saved)
    obs = np.random.default_rng(0).random((2, OBS), dtype=np.float32)
    np.testing.assert_array_equal(a.model.outputs_np(obs), b.model.outputs_np(obs))
    for s in range(3, 5):
        assert a.update(random_batch(seed=s)) == b.update(random_batch(seed=s))
    for p, q in zip(a.model.parameters(), b.model.parameters(), strict=True):
        assert torch.equal(p, q)


@pytest.mark.parametrize("algo", ["a2c", "a2cm"])
def test_one_step_bandit_learns_the_rewarded_actions(algo: str) -> None:
    # every step is a one-step episode; the team reward counts pursuers that chose their
    # own target action; after a few hundred updates each target is taken with p > 0.9
    target = np.array([2, 0, 3])
    m = model(algo, hidden=16)
    learner = Learner(m, paper_cfg(algo=algo, lr=7e-3, gamma=0.99))
    rng = np.random.default_rng(0)
    obs = np.full((8, 1, OBS), 0.5, dtype=np.float32)
    done = torch.ones(8, 1, dtype=torch.bool)
    for _ in range(300):
        acts = m.act(obs[:, 0], rng)  # (T, N)
        reward = (acts == target).sum(-1).astype(np.float32)
        learner.update(
            {
                "obs": torch.from_numpy(obs),
                "actions": torch.from_numpy(acts[:, None]),
                "rewards": torch.from_numpy(reward[:, None]),
                "terminated": done,
                "truncated": torch.zeros_like(done),
                "final_obs": torch.from_numpy(obs),
                "next_obs": torch.from_numpy(obs[0]),
            }
        )
    probs = m.action_probs_np(obs[0])[0]  # (N, A)
    assert (probs[np.arange(N), target] > 0.9).all(), probs


def test_train_defaults_are_keras_rmsprop() -> None:
    learner = Learner(model("a2cm"), paper_cfg())
    group = learner.optimizer.param_groups[0]
    assert (group["lr"], group["alpha"], group["eps"]) == (7e-3, 0.9, 1e-7)
    assert group["momentum"] == 0 and not group["centered"]
    assert dataclasses.asdict(paper_cfg())["gamma"] == 0.99


# --------------------------------------------------------------------- against a reference
def trainer_batch(t: int = 8, b: int = 16, seed: int = 0) -> dict[str, np.ndarray]:
    """A random batch in the trainer's own arrays and dtypes, with episode ends of each kind."""
    rng = np.random.default_rng(seed)
    batch = allocate_batch(t, b, OBS, N)
    batch["obs"][:] = rng.random(batch["obs"].shape)
    batch["actions"][:] = rng.integers(0, A, batch["actions"].shape)
    batch["rewards"][:] = rng.normal(-0.5, 1.0, batch["rewards"].shape)
    batch["terminated"][:] = rng.random((t, b)) < 0.1
    batch["truncated"][:] = rng.random((t, b)) < 0.1
    batch["terminated"][2, 0] = batch["truncated"][2, 0] = True  # both at once: terminal
    batch["truncated"][t - 1, 1] = True
    batch["final_obs"][:] = rng.random(batch["final_obs"].shape)
    batch["final_obs"][~batch["truncated"]] = np.nan  # never read where not truncated
    batch["next_obs"][:] = rng.random(batch["next_obs"].shape)
    return batch


def reference_loss(
    m: ActorCritic, batch: dict, cfg: Train
) -> tuple[dict[str, float], dict[str, torch.Tensor]]:
    """The loss written out plainly in float64: per agent, per critic, eq. 13 per env.

    Returns the metrics and the gradient of every parameter (of a float64 copy of ``m``).
    """
    m = copy.deepcopy(m).double()
    obs, final, nxt = (torch.as_tensor(batch[k]).double() for k in ("obs", "final_obs", "next_obs"))
    actions = torch.as_tensor(batch["actions"]).long()
    rewards = torch.as_tensor(batch["rewards"]).float().double() * cfg.reward_scale
    term, trunc = (torch.as_tensor(batch[k]).bool() for k in ("terminated", "truncated"))
    t_len, n_envs = obs.shape[:2]

    def mlp(layer1: StackedLinear, layer2: StackedLinear, i: int, x: torch.Tensor) -> torch.Tensor:
        hidden = F.relu(F.linear(x, layer1.weight[i], layer1.bias[i]))
        return F.linear(hidden, layer2.weight[i], layer2.bias[i])

    value_loss, advs = torch.zeros((), dtype=torch.float64), []
    for c in range(m.n_critics):
        v = mlp(m.critic_hidden, m.critic_out, c, obs)[..., 0]  # (T, B)
        returns = torch.zeros(t_len, n_envs, dtype=torch.float64)
        with torch.no_grad():
            for b in range(n_envs):
                g = mlp(m.critic_hidden, m.critic_out, c, nxt[b]).item()
                for t in reversed(range(t_len)):
                    r = rewards[t, b].item()
                    if term[t, b]:
                        g = r
                    elif trunc[t, b]:
                        g = (
                            r
                            + cfg.gamma * mlp(m.critic_hidden, m.critic_out, c, final[t, b]).item()
                        )
                    else:
                        g = r + cfg.gamma * g
                    returns[t, b] = g
        advs.append((returns - v).detach())
        value_loss = value_loss + ((returns - v) ** 2).mean()
    policy_loss = entropy = torch.zeros((), dtype=torch.float64)
    for i in range(m.n_agents):
        dist = Categorical(logits=mlp(m.actor_hidden, m.actor_out, i, obs))
        adv = advs[0 if m.n_critics == 1 else i]
        policy_loss = policy_loss - (adv * dist.log_prob(actions[..., i])).mean()
        entropy = entropy + dist.entropy().mean()
    loss = policy_loss - cfg.entropy_coef * entropy + cfg.value_coef * value_loss
    loss.backward()
    grads = {name: p.grad for name, p in m.named_parameters()}
    metrics = {
        "policy_loss": policy_loss.item(),
        "value_loss": value_loss.item(),
        "entropy": entropy.item() / m.n_agents,
        "mean_advantage": torch.stack(advs).mean().item(),
        "loss": loss.item(),
        "grad_norm": torch.linalg.vector_norm(
            torch.cat([g.flatten() for g in grads.values()])
        ).item(),
    }
    return metrics, grads


@pytest.mark.parametrize("algo", ["a2c", "a2cm"])
def test_loss_and_gradients_match_a_float64_reference(algo: str) -> None:
    cfg = paper_cfg(algo=algo, reward_scale=0.5, entropy_coef=0.05)
    for seed in range(3):
        m = model(algo, seed=seed, hidden=128)
        batch = trainer_batch(seed=seed)
        ref_metrics, ref_grads = reference_loss(m, batch, cfg)
        learner = Learner(m, cfg)
        metrics = learner.update(batch)
        assert metrics == pytest.approx(ref_metrics, rel=1e-5, abs=1e-6)
        for name, p in m.named_parameters():
            torch.testing.assert_close(p.grad.double(), ref_grads[name], rtol=1e-5, atol=1e-6)


def test_the_linear_entropy_schedule_weighs_entropy_by_the_run_left() -> None:
    """At progress p the loss and gradients are those of the coefficient 0.05 · (1 − p)."""
    for progress in (0.0, 0.25, 0.9):
        m, batch = model("a2cm", seed=1, hidden=16), trainer_batch(seed=1)
        annealed = paper_cfg(entropy_coef=0.05, entropy_schedule="linear")
        ref_metrics, ref_grads = reference_loss(
            m, batch, paper_cfg(entropy_coef=0.05 * (1.0 - progress))
        )
        metrics = Learner(m, annealed).update(batch, progress=progress)
        assert metrics == pytest.approx(ref_metrics, rel=1e-5, abs=1e-6)
        for name, p in m.named_parameters():
            torch.testing.assert_close(p.grad.double(), ref_grads[name], rtol=1e-5, atol=1e-6)
    # constant: progress changes nothing
    m, batch = model("a2cm", seed=1, hidden=16), trainer_batch(seed=1)
    ref_metrics, _ = reference_loss(m, batch, paper_cfg(entropy_coef=0.05))
    metrics = Learner(m, paper_cfg(entropy_coef=0.05)).update(batch, progress=0.9)
    assert metrics == pytest.approx(ref_metrics, rel=1e-5, abs=1e-6)


# --------------------------------------------------------------------- continuous actions
def gaussian_model(algo: str, seed: int = 0, hidden: int = 16) -> ActorCritic:
    """A small seeded model with diagonal-Gaussian actors over a 2-D command."""
    return ActorCritic(
        OBS,
        N,
        GaussianActions(2),
        hidden,
        shared_critic=algo == "a2cm",
        generator=torch.Generator().manual_seed(seed),
    )


def test_gaussian_loss_uses_the_unclipped_sample_and_reaches_log_std() -> None:
    m = gaussian_model("a2cm")
    batch = random_batch()
    rng = np.random.default_rng(0)
    batch["actions"] = torch.from_numpy(3.0 * rng.standard_normal((16, 2, N, 2))).float()
    metrics = Learner(m, paper_cfg()).update(batch)
    assert m.log_std.grad is not None and m.log_std.grad.abs().sum() > 0
    # entropy of N(·, 1) per dimension at the initial log_std = 0
    assert metrics["entropy"] == pytest.approx(2 * 0.5 * np.log(2 * np.pi * np.e), rel=1e-6)
    # the log-probability is of the action as sampled (|a| = 3 is outside the box)
    m2 = gaussian_model("a2cm")
    clipped = dict(batch, actions=batch["actions"].clamp(-1, 1))
    assert Learner(m2, paper_cfg()).update(clipped)["policy_loss"] != metrics["policy_loss"]


@pytest.mark.parametrize("algo", ["a2c", "a2cm"])
def test_gaussian_bandit_learns_the_rewarded_command(algo: str) -> None:
    # one-step episodes, reward −|a_i − target_i|² summed: the means move to the targets
    target = np.array([[0.5, -0.5], [-0.3, 0.2], [0.0, 0.8]], dtype=np.float32)
    m = gaussian_model(algo)
    learner = Learner(m, paper_cfg(algo=algo, lr=3e-3, optimizer="adam", normalize_advantages=True))
    rng = np.random.default_rng(0)
    obs = np.full((32, 1, OBS), 0.5, dtype=np.float32)
    done = np.ones((32, 1), dtype=bool)
    for _ in range(600):
        acts = m.act(obs[:, 0], rng)  # (T, N, 2) float32
        reward = -((acts - target) ** 2).sum((-1, -2))
        learner.update(
            {
                "obs": obs,
                "actions": acts[:, None],
                "rewards": reward[:, None],
                "terminated": done,
                "truncated": ~done,
                "final_obs": obs,
                "next_obs": obs[0],
            }
        )
    mean = m.act(obs[0], rng, greedy=True)[0]
    np.testing.assert_allclose(mean, target, atol=0.15)
    assert m.act(obs[0], rng, greedy=True).dtype == np.float32


# --------------------------------------------------------------------- issue 12's pieces
def test_advantage_normalisation_standardises_the_actor_advantage() -> None:
    batch = trainer_batch(seed=4)
    plain = paper_cfg(entropy_coef=0.0)
    normed = paper_cfg(entropy_coef=0.0, normalize_advantages=True)
    ref_metrics, _ = reference_loss(model("a2cm"), batch, plain)
    m = model("a2cm")
    metrics = Learner(m, normed).update(batch)
    # the critic's part is unchanged, the policy loss is of standardised advantages
    assert metrics["value_loss"] == pytest.approx(ref_metrics["value_loss"], rel=1e-5)
    assert metrics["policy_loss"] != pytest.approx(ref_metrics["policy_loss"], rel=1e-3)
    learner = Learner(model("a2cm"), normed)
    adv = torch.tensor([[[[1.0]], [[3.0]]], [[[5.0]], [[7.0]]]], dtype=torch.float64)
    out = learner._actor_advantage(adv)  # (T=2, B=2, C=1)
    expected = (np.array([1.0, 3.0, 5.0, 7.0]) - 4.0) / np.std([1, 3, 5, 7], ddof=1)
    np.testing.assert_allclose(out.flatten().numpy(), expected, rtol=1e-6)


def test_split_rewards_value_each_component_and_scale_it_apart() -> None:
    cfg = paper_cfg(value_norm=True, split_rewards=True)
    m = ActorCritic(OBS, N, A, 16, shared_critic=True, n_values=2)
    learner = Learner(m, cfg)
    batch = trainer_batch(seed=1)
    parts = np.zeros((*batch["rewards"].shape, 2))
    parts[..., 0] = -1.0
    parts[3, 2, 1] = -1e8  # one catastrophic collision
    batch["reward_parts"] = parts
    batch["rewards"] = parts.sum(-1)
    metrics = learner.update(batch)
    assert np.isfinite(metrics["loss"])
    std = learner.value_norm.stats()[1][0]  # the one critic: (K,)
    assert std[1] > 1e5 * std[0]  # each component has its own scale
    adv = torch.ones(2, 2, 1, 2, dtype=torch.float64)
    expected = (1 / std[0] + 1 / std[1]).item()
    assert learner._actor_advantage(adv)[0, 0, 0].item() == pytest.approx(expected, rel=1e-6)
    with pytest.raises(ValueError, match="components"):
        learner.update(dict(batch, reward_parts=parts[..., :1]))


def test_collision_constraint_multiplier_follows_dual_ascent() -> None:
    cfg = paper_cfg(
        value_norm=True,
        split_rewards=True,
        constrain_collisions=True,
        collision_budget=0.01,
        lagrange_lr=2.0,
    )
    m = ActorCritic(OBS, N, A, 16, shared_critic=True, n_values=2)
    learner = Learner(m, cfg)
    batch = trainer_batch(seed=2)  # T=8, B=16: 128 steps
    batch["reward_parts"] = np.stack([batch["rewards"], np.zeros_like(batch["rewards"])], -1)
    batch["collisions"] = np.zeros(batch["rewards"].shape, dtype=np.int64)
    batch["collisions"][0, :4] = 1  # 4 collisions in 128 steps: 0.03125 per step
    metrics = learner.update(batch)
    assert metrics["multiplier"] == pytest.approx(2.0 * (4 / 128 - 0.01))
    learner.update(batch)
    assert learner.multiplier == pytest.approx(2 * 2.0 * (4 / 128 - 0.01))
    batch["collisions"][:] = 0  # no collision: λ falls by lr·budget, never below 0
    for _ in range(10):
        learner.update(batch)
    assert learner.multiplier == 0.0
    # with λ = 0 the actors see only the time component; λ weighs the collision cost in
    learner.multiplier = 3.0
    std = learner.value_norm.stats()[1][0]  # the one critic: (K,)
    adv = torch.tensor([1.0, 2.0], dtype=torch.float64).expand(2, 2, 1, 2)
    expected = (1.0 / std[0] + 3.0 * 2.0 / std[1]) / 4.0
    assert learner._actor_advantage(adv)[0, 0, 0].item() == pytest.approx(expected.item())
    state = learner.state_dict()
    other = Learner(ActorCritic(OBS, N, A, 16, shared_critic=True, n_values=2), cfg)
    other.load_state_dict(state)
    assert other.multiplier == 3.0


def test_constraint_needs_split_components() -> None:
    with pytest.raises(ValueError, match="split_rewards"):
        load_train({"constrain_collisions": True, "split_rewards": False})


def test_non_finite_rewards_change_nothing_under_our_settings() -> None:
    cfg = resolve_train(GRID, Train())  # ours: PopArt, split components, normalised advantages
    m = ActorCritic(OBS, N, A, 16, shared_critic=True, n_values=2)
    learner = Learner(m, cfg)
    batch = trainer_batch(seed=3)
    batch["reward_parts"] = np.stack([batch["rewards"], np.zeros_like(batch["rewards"])], -1)
    learner.update(batch)
    before, norm = params(m), learner.value_norm.state_dict()
    batch["reward_parts"][2, 1, 0] = float("nan")
    with pytest.raises(NonFiniteLoss, match="non-finite"):
        learner.update(batch)
    assert all(torch.equal(p, q) for p, q in zip(before, m.parameters(), strict=True))
    after = learner.value_norm.state_dict()
    assert all(torch.equal(norm[k], after[k]) for k in norm)


@pytest.mark.parametrize("b", [Train().mean_bound, 3.0])
def test_mean_bound_loss_by_hand(b):
    from a2cm_phys.algos.losses import mean_bound_loss

    means = torch.tensor([[[[0.5, b + 0.2]], [[-b - 0.5, 0.0]]]])  # (T=1, B=2, N=1, dim=2)
    # per agent: the batch mean of the per-dimension squared overshoots, summed
    expected = ((0.2**2) + (0.5**2)) / 2
    assert mean_bound_loss(means, b).item() == pytest.approx(expected, rel=1e-5)
    assert mean_bound_loss(torch.zeros(3, 2, 4, 2), b).item() == 0.0
    inside = torch.full((1, 1, 1, 2), b - 0.05)  # just inside the bound: free
    assert mean_bound_loss(inside, b).item() == 0.0


def test_the_learner_bounds_the_means_where_mean_bound_says() -> None:
    """``Train.mean_bound`` is where the learner's soft bound starts: two learners that
    differ only in it differ in their loss by exactly the bound's term at the model's
    means (2.0 here: past the default 1.1, inside 3.0, where the term is 0)."""
    from a2cm_phys.algos.losses import mean_bound_loss

    batch = random_batch()
    batch["actions"] = torch.zeros(16, 2, N, 2)
    losses = {}
    for bound in (Train().mean_bound, 3.0):
        m = gaussian_model("a2cm")
        with torch.no_grad():
            m.actor_out.weight.zero_()
            m.actor_out.bias.fill_(2.0)
        cfg = paper_cfg(mean_bound_coef=1.0, mean_bound=bound)
        losses[bound] = Learner(m, cfg).update(batch)["loss"]
    means = torch.full((16, 2, N, 2), 2.0)
    gap = mean_bound_loss(means, Train().mean_bound).item()
    assert gap == pytest.approx(N * 2 * 0.9**2)
    assert losses[Train().mean_bound] - losses[3.0] == pytest.approx(gap, rel=1e-5)


def test_mean_bound_must_be_positive_and_finite() -> None:
    for bad in (0.0, -1.0, float("inf")):
        with pytest.raises(ConfigError, match="training options: key 'mean_bound': must be"):
            load_train({"mean_bound": bad})


def test_mean_bound_pulls_runaway_gaussian_means_back():
    """With no advantage signal, the bound alone moves means beyond it back towards ±1.1,
    and leaves means inside it untouched."""
    from a2cm_phys.algos.losses import mean_bound_loss

    out = torch.tensor([[[[3.0, 0.5]]]], requires_grad=True)
    mean_bound_loss(out, Train().mean_bound).backward()
    assert out.grad[0, 0, 0, 0] > 0  # descent lowers the runaway mean
    assert out.grad[0, 0, 0, 1] == 0
