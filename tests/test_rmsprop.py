"""KerasRMSprop is torch.optim.RMSprop's arithmetic, bit for bit, and its checkpoint layout."""

from __future__ import annotations

import copy

import pytest
import torch

from a2cm_phys.algos.models import ActorCritic
from a2cm_phys.algos.rmsprop import KerasRMSprop


def twins() -> tuple[ActorCritic, ActorCritic]:
    """Two identical small models (A2C: several critics, so several parameter shapes)."""
    return tuple(  # type: ignore[return-value]
        ActorCritic(
            8, 3, 4, 16, shared_critic=False, n_values=2, generator=torch.Generator().manual_seed(0)
        )
        for _ in range(2)
    )


def give_grads(a: torch.nn.Module, b: torch.nn.Module, g: torch.Generator, skip: int = -1) -> None:
    """The same random gradient on both models' parameters (none on parameter ``skip``)."""
    for i, (p, q) in enumerate(zip(a.parameters(), b.parameters(), strict=True)):
        grad = None if i == skip else torch.randn(p.shape, generator=g)
        p.grad = None if grad is None else grad.clone()
        q.grad = None if grad is None else grad.clone()


def same(a: torch.nn.Module, b: torch.nn.Module) -> bool:
    return all(torch.equal(p, q) for p, q in zip(a.parameters(), b.parameters(), strict=True))


def test_steps_are_bit_identical_to_torch_rmsprop() -> None:
    ours_model, torch_model = twins()
    ours = KerasRMSprop(ours_model.parameters(), lr=7e-3, alpha=0.9, eps=1e-7)
    ref = torch.optim.RMSprop(torch_model.parameters(), lr=7e-3, alpha=0.9, eps=1e-7)
    g = torch.Generator().manual_seed(1)
    for step in range(300):
        # a parameter without a gradient for a while (skipped, no state), a changing lr
        give_grads(ours_model, torch_model, g, skip=0 if step < 5 else -1)
        for opt in (ours, ref):
            opt.param_groups[0]["lr"] = 7e-3 * (1 - step / 300)
            opt.step()
        assert same(ours_model, torch_model), step
    mine, theirs = ours.state_dict(), ref.state_dict()
    assert mine["param_groups"] == theirs["param_groups"]
    assert mine["state"].keys() == theirs["state"].keys()
    for i, entry in theirs["state"].items():
        assert torch.equal(mine["state"][i]["square_avg"], entry["square_avg"])
        assert torch.equal(mine["state"][i]["step"], entry["step"])
    assert mine["state"][0]["step"].item() == 295.0  # no gradient, no step


@pytest.mark.parametrize("direction", ["torch->ours", "ours->torch"])
def test_checkpoints_move_between_the_two(direction: str) -> None:
    a_model, b_model = twins()
    a = KerasRMSprop(a_model.parameters(), lr=1e-2, alpha=0.9, eps=1e-7)
    b = torch.optim.RMSprop(b_model.parameters(), lr=1e-2, alpha=0.9, eps=1e-7)
    if direction == "ours->torch":
        a, b = b, a
        a_model, b_model = b_model, a_model
    g = torch.Generator().manual_seed(2)
    for _ in range(20):  # a trains alone; b then takes over its weights and state
        give_grads(a_model, b_model, g)
        a.step()
    b_model.load_state_dict(a_model.state_dict())
    b.load_state_dict(copy.deepcopy(a.state_dict()))  # both alias live tensors, as torch's
    for _ in range(20):
        give_grads(a_model, b_model, g)
        a.step()
        b.step()
        assert same(a_model, b_model)


def test_zero_grad_and_a_mismatched_state_dict() -> None:
    model, other = twins()
    opt = KerasRMSprop(model.parameters(), lr=1e-3, alpha=0.9, eps=1e-7)
    give_grads(model, other, torch.Generator().manual_seed(3))
    opt.zero_grad(set_to_none=False)
    assert all(torch.count_nonzero(p.grad) == 0 for p in model.parameters())
    opt.zero_grad()
    assert all(p.grad is None for p in model.parameters())
    small = KerasRMSprop(list(model.parameters())[:2], lr=1e-3, alpha=0.9, eps=1e-7)
    with pytest.raises(ValueError, match="2 in 1"):
        small.load_state_dict(opt.state_dict())
