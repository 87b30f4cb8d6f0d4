"""Returns (eq. 13) and advantages (eq. 12) against hand-computed numbers."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from a2cm_phys.algos.returns import advantages, discounted_returns, discounted_returns_np, gae

torch.set_num_threads(1)


def col(*xs: float) -> torch.Tensor:
    """A (T, 1) float32 column: one environment."""
    return torch.tensor(xs, dtype=torch.float32).unsqueeze(1)


def flags(*xs: int) -> torch.Tensor:
    """A (T, 1) bool column."""
    return torch.tensor(xs, dtype=torch.bool).unsqueeze(1)


NO = flags(0, 0, 0, 0)


def test_gamma_one_terminal_in_the_middle() -> None:
    # r = 1, 2, 3, 4; terminated at t=1; bootstrap V(s_4) = 10; γ = 1
    # G3 = 4 + 10 = 14;  G2 = 3 + 14 = 17;  G1 = 2 (terminal);  G0 = 1 + 2 = 3
    g = discounted_returns(
        col(1, 2, 3, 4), flags(0, 1, 0, 0), NO, torch.tensor([10.0]), col(0, 0, 0, 0), 1.0
    )
    assert g.shape == (4, 1)
    assert g[:, 0].tolist() == [3.0, 2.0, 17.0, 14.0]


def test_gamma_099_bootstrap_at_the_end() -> None:
    # r = 1, 1, 1; no episode end; V(s_3) = 10; γ = 0.99
    # G2 = 1 + 0.99·10 = 10.9;  G1 = 1 + 0.99·10.9 = 11.791;  G0 = 1 + 0.99·11.791 = 12.67309
    g = discounted_returns(
        col(1, 1, 1), flags(0, 0, 0), flags(0, 0, 0), torch.tensor([10.0]), col(0, 0, 0), 0.99
    )
    assert g[:, 0].tolist() == pytest.approx([12.67309, 11.791, 10.9], rel=1e-6)


def test_truncation_in_the_middle_bootstraps_from_its_final_obs() -> None:
    # r = 1, 1, 1; truncated at t=1 with V(final_obs_1) = 5; V(s_3) = 10; γ = 0.99
    # G2 = 1 + 0.99·10 = 10.9;  G1 = 1 + 0.99·5 = 5.95 (not G2!);  G0 = 1 + 0.99·5.95 = 6.8905
    # truncation values at non-truncated steps are never read, even NaN
    tv = col(math.nan, 5, math.nan)
    g = discounted_returns(
        col(1, 1, 1), flags(0, 0, 0), flags(0, 1, 0), torch.tensor([10.0]), tv, 0.99
    )
    assert g[:, 0].tolist() == pytest.approx([6.8905, 5.95, 10.9], rel=1e-6)


def test_truncation_is_not_termination() -> None:
    # the same step once truncated (V(final) = 5) and once terminated; γ = 1, r = 1 each
    # truncated: G1 = 1 + 5 = 6, G0 = 1 + 6 = 7;  terminated: G1 = 1, G0 = 1 + 1 = 2
    args = (col(1, 1), torch.tensor([100.0]), col(5, 5), 1.0)
    trunc = discounted_returns(args[0], flags(0, 0), flags(0, 1), *args[1:])
    term = discounted_returns(args[0], flags(0, 1), flags(0, 0), *args[1:])
    assert trunc[:, 0].tolist() == [7.0, 6.0]
    assert term[:, 0].tolist() == [2.0, 1.0]


def test_terminated_and_truncated_together_is_terminal() -> None:
    # r = 3 at the last step which is both: G = 3 (no V(final), no bootstrap)
    g = discounted_returns(col(3), flags(1), flags(1), torch.tensor([9.0]), col(7), 0.5)
    assert g.tolist() == [[3.0]]


def test_gamma_zero_is_the_reward() -> None:
    g = discounted_returns(
        col(1, -2, 3), flags(0, 0, 0), flags(0, 0, 0), torch.tensor([50.0]), col(0, 0, 0), 0.0
    )
    assert g[:, 0].tolist() == [1.0, -2.0, 3.0]


def test_two_envs_are_independent() -> None:
    # env 0: r = -1, -1, terminal at t=0, V_T = 4;  env 1: r = 2, 2, no end, V_T = -4;  γ = 0.5
    # env 0: G1 = -1 + 0.5·4 = 1;  G0 = -1 (terminal)
    # env 1: G1 = 2 + 0.5·(-4) = 0;  G0 = 2 + 0.5·0 = 2
    r = torch.tensor([[-1.0, 2.0], [-1.0, 2.0]])
    term = torch.tensor([[True, False], [False, False]])
    g = discounted_returns(
        r,
        term,
        torch.zeros(2, 2, dtype=torch.bool),
        torch.tensor([4.0, -4.0]),
        torch.zeros(2, 2),
        0.5,
    )
    assert g.tolist() == [[-1.0, 2.0], [1.0, 0.0]]


def test_multi_critic_broadcasting() -> None:
    # team reward (T=3, B=1) broadcast to C=2 critics, γ = 0.5, truncated at t=1
    # bootstrap V_T = (10, 20); truncation values at t=1: (4, 8)
    # critic 0: G2 = 1 + 0.5·10 = 6;  G1 = 2 + 0.5·4 = 4;  G0 = 3 + 0.5·4 = 5
    # critic 1: G2 = 1 + 0.5·20 = 11; G1 = 2 + 0.5·8 = 6;  G0 = 3 + 0.5·6 = 6
    tv = torch.tensor([[[0.0, 0.0]], [[4.0, 8.0]], [[0.0, 0.0]]])
    g = discounted_returns(
        col(3, 2, 1), flags(0, 0, 0), flags(0, 1, 0), torch.tensor([[10.0, 20.0]]), tv, 0.5
    )
    assert g.shape == (3, 1, 2)
    assert g[:, 0].tolist() == [[5.0, 6.0], [4.0, 6.0], [6.0, 11.0]]
    # (T, B, C) rewards give the same as broadcasting (T, B) ones
    g3 = discounted_returns(
        col(3, 2, 1).unsqueeze(-1).expand(3, 1, 2),
        flags(0, 0, 0),
        flags(0, 1, 0),
        torch.tensor([[10.0, 20.0]]),
        tv,
        0.5,
    )
    assert torch.equal(g, g3)


def test_dtype_and_no_grad() -> None:
    boot = torch.tensor([1.0], requires_grad=True)
    g = discounted_returns(col(1, 1), flags(0, 0), flags(0, 0), boot, col(0, 0), 0.9)
    assert g.dtype == torch.float32
    assert not g.requires_grad


def test_advantages() -> None:
    # A = G − V; a (T, B, 1) shared critic broadcasts against (T, B, 1) returns
    g = torch.tensor([[[3.0]], [[2.0]]])
    v = torch.tensor([[[1.0]], [[2.5]]])
    assert advantages(g, v).tolist() == [[[2.0]], [[-0.5]]]
    # per-critic: (T, B, C) − (T, B, C)
    g2 = torch.tensor([[[1.0, 4.0]]])
    v2 = torch.tensor([[[0.5, 5.0]]])
    assert advantages(g2, v2).tolist() == [[[0.5, -1.0]]]


def python_returns(r, term, trunc, boot, tval, gamma) -> np.ndarray:
    """Eq. 13 one env and one critic at a time, in Python floats."""
    t_len, n_envs, n_critics = tval.shape
    out = np.zeros((t_len, n_envs, n_critics))
    for b in range(n_envs):
        for c in range(n_critics):
            g = float(boot[b, c])
            for t in reversed(range(t_len)):
                rt = float(np.float32(r[t, b]))
                if term[t, b]:
                    g = rt
                elif trunc[t, b]:
                    g = rt + float(np.float32(gamma) * np.float32(tval[t, b, c]))
                else:
                    g = rt + float(np.float32(gamma)) * g
                out[t, b, c] = g
    return out


def test_matches_a_plain_python_recurrence_on_random_batches() -> None:
    rng = np.random.default_rng(0)
    for trial in range(50):
        t_len, n_envs, n_critics = rng.integers(1, 10), rng.integers(1, 20), rng.integers(1, 4)
        r = rng.normal(size=(t_len, n_envs)).astype(np.float32)
        term = rng.random((t_len, n_envs)) < 0.2
        trunc = rng.random((t_len, n_envs)) < 0.2
        boot = rng.normal(size=(n_envs, n_critics)).astype(np.float32)
        tval = rng.normal(size=(t_len, n_envs, n_critics)).astype(np.float32)
        tval[~trunc] = np.nan if trial % 2 else np.inf  # never read
        gamma = float(rng.choice([0.0, 0.5, 0.99, 1.0]))
        expected = python_returns(r, term, trunc, boot, tval, gamma)
        got = discounted_returns_np(r, term, trunc, boot, tval, gamma)
        assert got.dtype == np.float32 and got.shape == (t_len, n_envs, n_critics)
        np.testing.assert_allclose(got, expected, rtol=1e-6, atol=1e-6)
        via_torch = discounted_returns(*map(torch.from_numpy, (r, term, trunc, boot, tval)), gamma)
        assert np.array_equal(via_torch.numpy(), got)


def test_empty_batch() -> None:
    g = discounted_returns_np(
        np.zeros((0, 3)),
        np.zeros((0, 3), bool),
        np.zeros((0, 3), bool),
        np.zeros(3),
        np.zeros((0, 3)),
        0.9,
    )
    assert g.shape == (0, 3)


def test_gae_by_hand_with_a_terminal_and_a_truncation_in_the_middle() -> None:
    # one env, T = 4: step 1 terminates, step 2 is truncated (its final obs is worth 10)
    r = np.array([[1.0], [2.0], [3.0], [4.0]])
    v = np.array([[0.5], [0.25], [1.0], [2.0]])
    after = np.array([[0.25], [99.0], [10.0], [8.0]])  # V of the state after each step
    term = np.array([[False], [True], [False], [False]])
    trunc = np.array([[False], [False], [True], [False]])
    g, lam = 0.9, 0.5
    got = gae(r, v, after, term, trunc, g, lam)
    d3 = 4 + g * 8 - 2  # bootstrapped with the value after the batch
    d2 = 3 + g * 10 - 1  # truncated: its own final obs, nothing from step 3
    d1 = 2 - 0.25  # terminal: no future at all (the 99 is never read)
    d0 = 1 + g * 0.25 - 0.5
    expected = [d0 + g * lam * d1, d1, d2, d3]
    np.testing.assert_allclose(got[:, 0], expected)


def test_gae_with_lambda_one_gives_eq_13_returns() -> None:
    rng = np.random.default_rng(0)
    t, b = 12, 3
    r = rng.normal(size=(t, b))
    v = rng.normal(size=(t, b))
    boot = rng.normal(size=b)
    final = rng.normal(size=(t, b))
    term = rng.random((t, b)) < 0.2
    trunc = (rng.random((t, b)) < 0.2) & ~term
    after = np.concatenate([v[1:], boot[None]])
    after = np.where(trunc, final, after)
    adv = gae(r, v, after, term, trunc, 0.97, 1.0)
    returns = discounted_returns_np(r, term, trunc, boot, final, 0.97)
    np.testing.assert_allclose(adv + v, returns, rtol=1e-12, atol=1e-12)
