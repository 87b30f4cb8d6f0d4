"""PopArt-style value normalisation: hand-computed statistics, their update, and outputs
preserved through a rescale of the critic's last layer."""

from __future__ import annotations

import math

import pytest
import torch

from a2cm_phys.algos.layers import StackedLinear
from a2cm_phys.algos.normalize import ValueNorm


def test_statistics_by_hand() -> None:
    norm = ValueNorm(2, beta=0.5, min_var=1e-4)
    mean, std = norm.stats()
    assert mean.tolist() == [0.0, 0.0] and std.tolist() == [1.0, 1.0]  # before any data
    norm.update(torch.tensor([[1.0, 0.0], [3.0, 0.0]]))
    # first update: debiasing makes the statistics exactly those of the batch
    mean, std = norm.stats()
    assert mean.tolist() == pytest.approx([2.0, 0.0])
    assert std.tolist() == pytest.approx([1.0, math.sqrt(1e-4)])  # constant: the floor
    norm.update(torch.tensor([[6.0, 10.0], [6.0, 10.0]]))
    # EMA with beta 0.5: m = 0.5·(0.5·2) + 0.5·6 = 3.5, debias 0.75 → 14/3; likewise E[x²]
    m = (0.25 * 2 + 0.5 * 6) / 0.75
    sq = (0.25 * 5 + 0.5 * 36) / 0.75
    mean, std = norm.stats()
    assert mean[0].item() == pytest.approx(m)
    assert std[0].item() == pytest.approx(math.sqrt(sq - m * m))
    assert mean[1].item() == pytest.approx(0.5 * 10 / 0.75)


def test_normalize_round_trip() -> None:
    norm = ValueNorm(3)
    norm.update(torch.randn(50, 3) * torch.tensor([1.0, 1e3, 1e8]) + 5.0)
    x = torch.randn(4, 3, dtype=torch.float64) * 1e3
    torch.testing.assert_close(norm.denormalize(norm.normalize(x)), x)


def test_popart_update_preserves_the_critic_values() -> None:
    g = torch.Generator().manual_seed(0)
    layer = StackedLinear(2, 8, 3, g)  # two critics, three components
    hidden = torch.rand(5, 8, generator=g)
    norm = ValueNorm(3, beta=0.9)
    norm.update(torch.randn(64, 3, generator=g) * 10.0, layer)
    before = norm.denormalize(layer.forward_shared(hidden).double())
    norm.update(torch.randn(64, 3, generator=g) * 1e6 - 3e6, layer)
    after = norm.denormalize(layer.forward_shared(hidden).double())
    scale = norm.stats()[1]
    assert scale.min() > 1e5  # the scale did move, by five orders of magnitude
    # float32 weights: preserved to float32 precision of the new scale
    torch.testing.assert_close(after, before, rtol=0, atol=1e-6 * scale.max().item())


def test_state_round_trip() -> None:
    a, b = ValueNorm(2), ValueNorm(2)
    a.update(torch.randn(10, 2) * 7)
    b.load_state_dict(a.state_dict())
    for x, y in zip(a.stats(), b.stats(), strict=True):
        assert torch.equal(x, y)


def test_stats_follow_every_update_and_load() -> None:
    """stats() is computed once per change (a learner reads it five times an update), so
    every update and every load must replace what it returned before."""
    norm, fresh = ValueNorm(2, beta=0.5), ValueNorm(2, beta=0.5)
    for scale in (1.0, 100.0, 0.01):
        before = norm.stats()
        norm.update(torch.randn(16, 2) * scale)
        fresh.load_state_dict(norm.state_dict())  # recomputes from the raw moments
        after = norm.stats()
        assert not torch.equal(after[1], before[1])
        for x, y in zip(after, fresh.stats(), strict=True):
            assert torch.equal(x, y)
    norm.load_state_dict(ValueNorm(2).state_dict())
    assert torch.equal(norm.stats()[1], torch.ones(2))
