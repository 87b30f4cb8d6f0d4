"""Batched actor–critic model: parameter counts, batched == per-agent, init, fast act()."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import torch.nn.functional as F
from torch import nn

from a2cm_phys.algos import make_model
from a2cm_phys.algos.distributions import (
    CategoricalActions,
    GaussianActions,
    sample_categorical,
)
from a2cm_phys.algos.encoding import OneHotCells
from a2cm_phys.algos.layers import StackedLinear
from a2cm_phys.algos.models import ActorCritic
from a2cm_phys.config import Scenario, Train

torch.set_num_threads(1)

N, OBS, A, H = 3, 8, 4, 128


def model(shared: bool, seed: int = 0) -> ActorCritic:
    """A small seeded model with the paper's sizes."""
    return ActorCritic(
        OBS, N, A, H, shared_critic=shared, generator=torch.Generator().manual_seed(seed)
    )


def n_params(m: nn.Module) -> int:
    """Total number of trainable scalars."""
    return sum(p.numel() for p in m.parameters())


@pytest.mark.parametrize("shared", [True, False])
def test_parameter_counts(shared: bool) -> None:
    actor = (OBS * H + H) + (H * A + A)  # Dense(obs,128) + Dense(128,A)
    critic = (OBS * H + H) + (H * 1 + 1)  # Dense(obs,128) + Dense(128,1)
    m = model(shared)
    n_critics = 1 if shared else N
    assert m.n_critics == n_critics
    assert n_params(m) == N * actor + n_critics * critic
    assert n_params(m.actor_hidden) + n_params(m.actor_out) == N * actor
    assert n_params(m.critic_hidden) + n_params(m.critic_out) == n_critics * critic


@pytest.mark.parametrize("shared", [True, False])
def test_shapes(shared: bool) -> None:
    m = model(shared)
    logits, values = m(torch.randn(5, 2, OBS))
    assert logits.shape == (5, 2, N, A)
    assert values.shape == (5, 2, m.n_critics)
    assert m.actor_outputs(torch.randn(OBS)).shape == (N, A)
    assert m.value(torch.randn(OBS)).shape == (m.n_critics,)


@pytest.mark.parametrize("shared", [True, False])
def test_batched_equals_per_agent_loop(shared: bool) -> None:
    m = model(shared)
    obs = torch.randn(7, OBS)
    logits, values = m(obs)

    def mlp(layer1: StackedLinear, layer2: StackedLinear, i: int) -> torch.Tensor:
        h = F.relu(F.linear(obs, layer1.weight[i], layer1.bias[i]))
        return F.linear(h, layer2.weight[i], layer2.bias[i])

    for i in range(N):
        torch.testing.assert_close(logits[:, i], mlp(m.actor_hidden, m.actor_out, i))
    for c in range(m.n_critics):
        torch.testing.assert_close(values[:, c], mlp(m.critic_hidden, m.critic_out, c)[:, 0])


def test_stacked_slices_initialise_like_nn_linear() -> None:
    torch.manual_seed(3)
    ref = nn.Linear(OBS, H)
    torch.manual_seed(3)
    stacked = StackedLinear(1, OBS, H)
    assert torch.equal(stacked.weight[0], ref.weight)
    assert torch.equal(stacked.bias[0], ref.bias)
    m = model(False)
    for layer, fan_in in ((m.actor_hidden, OBS), (m.actor_out, H), (m.critic_out, H)):
        bound = 1 / fan_in**0.5
        assert layer.weight.abs().max() <= bound and layer.bias.abs().max() <= bound
        assert not torch.equal(layer.weight[0], layer.weight[1])  # independent slices


def test_make_model_from_configs() -> None:
    scen = Scenario()
    a2cm = make_model(Train(algo="a2cm", seed=1), scen)
    a2c = make_model(Train(algo="a2c", seed=1), scen)
    assert (a2cm.n_critics, a2c.n_critics) == (1, scen.pursuers)
    assert a2cm.obs_dim == scen.obs_dim and a2cm.n_actions == scen.actions
    again = make_model(Train(algo="a2cm", seed=1), scen)
    for p, q in zip(a2cm.parameters(), again.parameters(), strict=True):
        assert torch.equal(p, q)


def test_act_is_deterministic_for_a_seeded_generator() -> None:
    m = model(True)
    obs = np.random.default_rng(0).random((16, OBS), dtype=np.float32)
    a = np.stack([m.act(obs, rng) for rng in [np.random.default_rng(5)] for _ in range(20)])
    b = np.stack([m.act(obs, rng) for rng in [np.random.default_rng(5)] for _ in range(20)])
    assert a.dtype == np.int64 and a.shape == (20, 16, N)
    assert np.array_equal(a, b)
    assert a.min() >= 0 and a.max() < A
    assert m.act(obs[0], np.random.default_rng(0)).shape == (N,)


def set_policy(m: ActorCritic, probs: np.ndarray) -> None:
    """Make every actor ignore the input and output ``log(probs[i])``."""
    with torch.no_grad():
        m.actor_out.weight.zero_()
        with np.errstate(divide="ignore"):
            m.actor_out.bias.copy_(torch.as_tensor(np.log(probs), dtype=torch.float32))


def test_act_respects_probabilities() -> None:
    m = model(True)
    probs = np.array([[0.1, 0.2, 0.3, 0.4], [0.97, 0.01, 0.01, 0.01], [0.0, 0.5, 0.5, 0.0]])
    set_policy(m, probs)  # also checks the numpy snapshot follows in-place weight changes
    obs = np.zeros((20_000, OBS), dtype=np.float32)
    acts = m.act(obs, np.random.default_rng(0))
    freq = np.stack([np.bincount(acts[:, i], minlength=A) / len(acts) for i in range(N)])
    # binomial std ≤ sqrt(0.25/20000) ≈ 0.0035: 0.015 is > 4 sigma
    np.testing.assert_allclose(freq, probs, atol=0.015)
    assert freq[2, 0] == 0 and freq[2, 3] == 0  # zero-probability actions never sampled
    np.testing.assert_allclose(m.action_probs_np(obs[:1])[0], probs, atol=1e-6)
    greedy = m.act(obs[:2], np.random.default_rng(0), greedy=True)
    assert greedy.tolist() == [[3, 0, 1]] * 2


def test_greedy_uses_no_randomness() -> None:
    m = model(True)
    rng = np.random.default_rng(0)
    state = rng.bit_generator.state
    m.act(np.zeros((2, OBS), dtype=np.float32), rng, greedy=True)
    assert rng.bit_generator.state == state


def test_snapshot_follows_load_state_dict() -> None:
    m, other = model(True, seed=0), model(True, seed=1)
    obs = np.random.default_rng(0).random((3, OBS), dtype=np.float32)
    before = m.outputs_np(obs)
    m.load_state_dict(other.state_dict())
    after = m.outputs_np(obs)
    assert not np.allclose(before, after)
    np.testing.assert_allclose(after, other.outputs_np(obs))


def test_sample_categorical_extreme_logits() -> None:
    logits = np.array([[1e4, -1e4, 0.0, -np.inf]], dtype=np.float32)
    out = sample_categorical(np.repeat(logits, 100, 0), np.random.default_rng(0))
    assert (out == 0).all()


def test_numpy_rollout_outputs_match_the_torch_forward() -> None:
    m = model(False)
    obs = np.random.default_rng(1).random((4, OBS), dtype=np.float32)
    with torch.no_grad():
        expected = m.actor_outputs(torch.from_numpy(obs)).numpy()
    np.testing.assert_allclose(m.outputs_np(obs), expected, rtol=1e-5, atol=1e-5)


def gaussian(shared: bool, log_std: float = 0.0) -> ActorCritic:
    """A Gaussian-actor model over a 2-D command."""
    return ActorCritic(
        OBS,
        N,
        GaussianActions(2),
        H,
        shared_critic=shared,
        log_std_init=log_std,
        generator=torch.Generator().manual_seed(0),
    )


@pytest.mark.parametrize("shared", [True, False])
def test_gaussian_parameter_count_and_shapes(shared: bool) -> None:
    m = gaussian(shared)
    actor = (OBS * H + H) + (H * 2 + 2) + 2  # the mean head and a log-std per dimension
    critic = (OBS * H + H) + (H + 1)
    assert n_params(m) == N * actor + m.n_critics * critic
    dist = m.dist.torch(m.actor_outputs(torch.randn(5, OBS)), m.log_std)
    assert dist.batch_shape == (5, N) and dist.event_shape == (2,)
    actions = m.act(np.zeros((5, OBS), dtype=np.float32), np.random.default_rng(0))
    assert actions.shape == (5, N, 2) and actions.dtype == np.float32


def test_gaussian_samples_have_the_mean_and_std_of_the_policy() -> None:
    m = gaussian(True, log_std=-1.0)
    obs = np.zeros((20_000, OBS), dtype=np.float32)
    acts = m.act(obs, np.random.default_rng(0))
    mean = m.act(obs[:1], np.random.default_rng(0), greedy=True)[0]  # greedy = the mean
    np.testing.assert_allclose(acts.mean(0), mean, atol=4 * np.exp(-1.0) / np.sqrt(len(obs)))
    np.testing.assert_allclose(acts.std(0), np.exp(-1.0), rtol=0.03)
    with pytest.raises(TypeError, match="discrete"):
        m.action_probs_np(obs[:1])


def test_make_model_follows_the_scenario_control() -> None:
    discrete = make_model(Train(), Scenario())
    assert isinstance(discrete.dist, CategoricalActions) and discrete.log_std is None
    split = make_model(Train(split_rewards=True, algo="a2c"), Scenario())
    assert split.n_values == 2 and split.value(torch.zeros(Scenario().obs_dim)).shape == (N, 2)


def deep(shared: bool, layers: int = 3, onehot: bool = True) -> ActorCritic:
    """Three hidden layers of 16 over the one-hot cells of a 5x5 grid observation."""
    return ActorCritic(
        OBS, N, A, 16, shared_critic=shared, generator=torch.Generator().manual_seed(0),
        layers=layers, encoding=OneHotCells(5) if onehot else None,
    )  # fmt: skip


def grid_obs(rows: int, seed: int = 0) -> np.ndarray:
    """Observations of a 5x5 grid: cells divided by size - 1."""
    return np.random.default_rng(seed).integers(0, 5, (rows, OBS)).astype(np.float32) / 4


@pytest.mark.parametrize("shared", [True, False])
def test_deeper_networks_over_one_hot_cells(shared: bool) -> None:
    m = deep(shared)
    actor = (OBS * 5 * 16 + 16) + 2 * (16 * 16 + 16) + (16 * A + A)
    critic = (OBS * 5 * 16 + 16) + 2 * (16 * 16 + 16) + (16 + 1)
    assert m.layers == 3 and n_params(m) == N * actor + m.n_critics * critic
    obs = grid_obs(9)
    x = torch.from_numpy(obs)
    onehot = F.one_hot(torch.round(x * 4).long(), 5).float().flatten(1)  # (9, OBS * 5)
    assert torch.equal(OneHotCells(5).torch(x), onehot)
    np.testing.assert_array_equal(OneHotCells(5).numpy(obs), onehot.numpy())
    with torch.no_grad():
        logits, values = m(x)
    for i in range(N):  # agent i's own stack of layers, by hand
        h = F.relu(onehot @ m.actor_hidden.weight[i].T + m.actor_hidden.bias[i])
        for layer in m.actor_deep:
            h = F.relu(h @ layer.weight[i].T + layer.bias[i])
        torch.testing.assert_close(logits[:, i], h @ m.actor_out.weight[i].T + m.actor_out.bias[i])
    np.testing.assert_allclose(m.outputs_np(obs), logits.numpy(), rtol=1e-5, atol=1e-5)
    assert values.shape == (9, m.n_critics)


def test_one_layer_draws_the_papers_weights() -> None:
    """Deeper layers are drawn after the paper's, so one layer is the same network."""
    paper = model(True)
    one = ActorCritic(OBS, N, A, H, shared_critic=True, generator=torch.Generator().manual_seed(0),
                      layers=1)  # fmt: skip
    for (k, a), (_, b) in zip(paper.state_dict().items(), one.state_dict().items(), strict=True):
        assert torch.equal(a, b), k
    two = ActorCritic(OBS, N, A, H, shared_critic=True, generator=torch.Generator().manual_seed(0),
                      layers=2)  # fmt: skip
    for k, a in paper.state_dict().items():
        assert torch.equal(a, two.state_dict()[k]), k


def test_make_model_reads_layers_and_encoding() -> None:
    m = make_model(Train(layers=2, encoding="onehot"), Scenario())
    assert m.layers == 2 and isinstance(m.encoding, OneHotCells) and m.encoding.size == 5
    obs = grid_obs(4)
    np.testing.assert_allclose(m.action_probs_np(obs).sum(-1), 1.0, rtol=1e-6)
