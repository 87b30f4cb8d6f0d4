"""Learner: gradient flow, A2C/A2CM advantage wiring, NaN guard, resume, a bandit, and the
numpy fast path against a plain float64 reference and the torch backend."""

from __future__ import annotations

import copy
import dataclasses
import io

import numpy as np
import pytest
import torch
import torch.nn.functional as F
from threadpoolctl import threadpool_info
from torch.distributions import Categorical

from a2cm_phys.algos.learner import Learner, NonFiniteLoss
from a2cm_phys.algos.models import ActorCritic, StackedLinear
from a2cm_phys.config import Train
from a2cm_phys.rollout import allocate_batch

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


# --------------------------------------------------------------------- numpy fast path
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


@pytest.mark.parametrize("backend", ["numpy", "torch"])
@pytest.mark.parametrize("algo", ["a2c", "a2cm"])
def test_loss_and_gradients_match_a_float64_reference(algo: str, backend: str) -> None:
    cfg = Train(algo=algo, reward_scale=0.5, entropy_coef=0.05)
    for seed in range(3):
        m = model(algo, seed=seed, hidden=128)
        batch = trainer_batch(seed=seed)
        ref_metrics, ref_grads = reference_loss(m, batch, cfg)
        learner = Learner(m, cfg, backend=backend)
        assert learner.active_backend == backend
        metrics = learner.update(batch)
        assert metrics == pytest.approx(ref_metrics, rel=1e-5, abs=1e-6)
        for name, p in m.named_parameters():
            torch.testing.assert_close(p.grad.double(), ref_grads[name], rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("algo", ["a2c", "a2cm"])
def test_numpy_and_torch_backends_take_the_same_steps(algo: str) -> None:
    cfg = Train(algo=algo, max_grad_norm=0.5)
    learners = [Learner(model(algo, hidden=64), cfg, backend=b) for b in ("numpy", "torch")]
    for seed in range(4):
        fast, ref = (learner.update(trainer_batch(seed=seed)) for learner in learners)
        assert fast == pytest.approx(ref, rel=1e-5, abs=1e-6)
    a, b = (learner.model for learner in learners)
    for p, q in zip(a.parameters(), b.parameters(), strict=True):
        torch.testing.assert_close(p, q, rtol=0, atol=1e-5)
    states = [learner.optimizer.state_dict()["state"] for learner in learners]
    for s, t in zip(states[0].values(), states[1].values(), strict=True):
        assert s["step"] == t["step"] == 4
        torch.testing.assert_close(s["square_avg"], t["square_avg"], rtol=1e-4, atol=1e-9)
    obs = np.random.default_rng(0).random((5, OBS), dtype=np.float32)  # act() sees the steps
    np.testing.assert_allclose(a.logits_np(obs), a.logits_np(obs, backend="torch"), atol=1e-5)


def test_packed_rmsprop_step_is_torch_rmsprop_bit_for_bit() -> None:
    m = model("a2c", hidden=32)
    learner = Learner(m, Train(algo="a2c"))
    learner.update(random_batch(seed=0))  # torch creates the optimiser state
    learner.update(random_batch(seed=1))  # the packed path adopts it
    twin = copy.deepcopy(m)
    twin_opt = torch.optim.RMSprop(twin.parameters(), lr=7e-3, alpha=0.9, eps=1e-7)
    twin_opt.load_state_dict(copy.deepcopy(learner.optimizer.state_dict()))
    g = torch.Generator().manual_seed(0)
    fast = learner._fast
    assert fast is not None
    fast.grad_flat.copy_(torch.randn(fast.grad_flat.shape, generator=g) * 1e-3)
    fast.attach_grads()
    for p, q in zip(m.parameters(), twin.parameters(), strict=True):
        q.grad = p.grad.clone()
    assert fast.rmsprop_step(learner.optimizer)
    twin_opt.step()
    for p, q in zip(m.parameters(), twin.parameters(), strict=True):
        assert torch.equal(p, q)
    mine, theirs = learner.optimizer.state_dict()["state"], twin_opt.state_dict()["state"]
    for k in mine:
        assert torch.equal(mine[k]["square_avg"], theirs[k]["square_avg"])
        assert torch.equal(mine[k]["step"], theirs[k]["step"])


def test_checkpoints_move_between_backends_and_through_torch_save() -> None:
    cfg = Train(algo="a2cm")
    a = Learner(model("a2cm"), cfg, backend="torch")
    a.update(random_batch(seed=0))
    buffer = io.BytesIO()
    torch.save(a.state_dict(), buffer)
    b = Learner(model("a2cm", seed=5), cfg)  # numpy backend adopts torch's state
    b.load_state_dict(torch.load(io.BytesIO(buffer.getvalue())))
    for s in range(1, 4):
        b.update(random_batch(seed=s))
    buffer = io.BytesIO()
    torch.save(b.state_dict(), buffer)  # state tensors are views of packed buffers
    c = Learner(model("a2cm", seed=6), cfg)
    c.load_state_dict(torch.load(io.BytesIO(buffer.getvalue())))
    d = Learner(model("a2cm", seed=7), cfg, backend="torch")
    d.load_state_dict(b.state_dict())
    out_b, out_c, out_d = (x.update(random_batch(seed=9)) for x in (b, c, d))
    assert out_b == out_c  # resumed bit-exactly
    assert out_d == pytest.approx(out_b, rel=1e-5)
    for p, q in zip(b.model.parameters(), c.model.parameters(), strict=True):
        assert torch.equal(p, q)
    assert b.optimizer.state_dict()["state"][0]["step"] == 5


def test_falls_back_to_torch_when_the_model_is_not_packed() -> None:
    m = model("a2cm")
    m.load_state_dict(model("a2cm", seed=1).state_dict(), assign=True)  # new tensors
    assert m.packed() is None
    learner = Learner(m, Train())
    assert learner.active_backend == "torch"
    metrics = learner.update(random_batch())
    assert np.isfinite(metrics["loss"])
    with pytest.raises(ValueError, match="numpy backend"):
        Learner(m, Train(), backend="numpy").update(random_batch())


def test_blas_threads_are_capped_only_during_an_update() -> None:
    blas = [p for p in threadpool_info() if p["user_api"] == "blas"]
    if not blas:
        pytest.skip("numpy's BLAS is not visible to threadpoolctl here")
    before = [p["num_threads"] for p in blas]
    Learner(model("a2cm"), Train()).update(random_batch())
    assert [p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas"] == before
