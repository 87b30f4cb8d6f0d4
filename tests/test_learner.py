"""Learner: gradient flow, A2C/A2CM advantage wiring, NaN guard, resume, a bandit."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch

from a2cm_phys.algos.learner import Learner, NonFiniteLoss
from a2cm_phys.algos.models import ActorCritic
from a2cm_phys.config import Train

torch.set_num_threads(1)

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
    learner = Learner(m, Train(algo=algo))
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
    metrics = Learner(m, Train()).update(random_batch())
    manual = torch.linalg.vector_norm(torch.stack([p.grad.norm() for p in m.parameters()]))
    assert metrics["grad_norm"] == pytest.approx(manual.item(), rel=1e-5)
    m2 = model("a2cm")
    clipped = Learner(m2, Train(max_grad_norm=1e-3)).update(random_batch())
    assert clipped["grad_norm"] == pytest.approx(metrics["grad_norm"], rel=1e-5)  # pre-clip
    after = torch.linalg.vector_norm(torch.stack([p.grad.norm() for p in m2.parameters()]))
    assert after.item() == pytest.approx(1e-3, rel=1e-3)


def actor0_grad(m: ActorCritic, batch: dict) -> list[torch.Tensor]:
    """Gradient of agent 0's actor after one update on ``batch``."""
    Learner(m, Train(algo="a2c" if m.n_critics > 1 else "a2cm")).update(batch)
    return [m.actor_hidden.weight.grad[0].clone(), m.actor_out.weight.grad[0].clone()]


def test_a2c_actor_i_uses_only_critic_i() -> None:
    batch = random_batch()
    base = actor0_grad(model("a2c"), batch)
    other_critic = model("a2c")
    with torch.no_grad():
        other_critic.critic_out.bias[1] += 5.0  # change agent 1's critic only
    assert all(
        torch.equal(x, y) for x, y in zip(base, actor0_grad(other_critic, batch), strict=True)
    )
    own_critic = model("a2c")
    with torch.no_grad():
        own_critic.critic_out.bias[0] += 5.0  # change agent 0's critic
    assert not torch.equal(base[1], actor0_grad(own_critic, batch)[1])


def test_truncation_bootstraps_from_final_obs() -> None:
    batch = random_batch()
    base = Learner(model("a2cm"), Train()).update(batch)
    moved = dict(batch, final_obs=batch["final_obs"].clone())
    moved["final_obs"][5] += 1.0  # step 5 did not end: never read
    assert Learner(model("a2cm"), Train()).update(moved) == base
    moved["final_obs"][7, 1] += 1.0  # step 7 of env 1 was truncated: its value is read
    assert Learner(model("a2cm"), Train()).update(moved)["value_loss"] != base["value_loss"]


def test_reward_scale() -> None:
    batch = random_batch()
    scaled = Learner(model("a2c"), Train(algo="a2c", reward_scale=0.1)).update(batch)
    pre = Learner(model("a2c"), Train(algo="a2c")).update(
        dict(batch, rewards=batch["rewards"] * 0.1)
    )
    assert scaled == pytest.approx(pre, rel=1e-5)


def test_non_finite_loss_does_not_step() -> None:
    m = model("a2cm")
    learner = Learner(m, Train())
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
    cfg = Train(algo="a2c")
    a = Learner(model("a2c", seed=0), cfg)
    for s in range(3):
        a.update(random_batch(seed=s))
    saved = a.state_dict()
    a.update(random_batch(seed=3))  # must not change the saved copy
    b = Learner(model("a2c", seed=9), cfg)
    b.load_state_dict(saved)
    a.load_state_dict(saved)
    obs = np.random.default_rng(0).random((2, OBS), dtype=np.float32)
    np.testing.assert_array_equal(a.model.logits_np(obs), b.model.logits_np(obs))
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
    learner = Learner(m, Train(algo=algo, lr=7e-3, gamma=0.99))
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
    learner = Learner(model("a2cm"), Train())
    group = learner.optimizer.param_groups[0]
    assert (group["lr"], group["alpha"], group["eps"]) == (7e-3, 0.9, 1e-7)
    assert group["momentum"] == 0 and not group["centered"]
    assert dataclasses.asdict(Train())["gamma"] == 0.99
