"""RMSprop as the paper's Keras has it: torch's arithmetic, without torch.optim's machinery.

Keras' RMSprop (non-centred, no momentum, ``eps`` outside the square root) is
``torch.optim.RMSprop(lr, alpha=rho, eps=eps)``. :class:`KerasRMSprop` performs exactly the
operations of torch's single-tensor implementation, in the same order, so every step is
bit-identical to it (``tests/test_rmsprop.py``), and reads and writes torch's
``state_dict`` layout, so checkpoints move between the two. Why not torch.optim itself: the
first use of any ``torch.optim.Optimizer`` imports ``torch._dynamo`` (1.3–1.75 s of the
main job's 30) and each ``step`` passes through profiling and hook wrappers (about 110 µs
of an update's 2.7 ms); the main job takes 5,000 steps (``BENCHMARKS.md``, "The main
job's time"). Adam stays torch.optim's.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

import torch

__all__ = ["KerasRMSprop"]


class KerasRMSprop:
    """``param -= lr · grad / (sqrt(v) + eps)`` with ``v = alpha · v + (1 − alpha) · grad²``.

    Mirrors the parts of ``torch.optim.Optimizer`` the learner uses: ``param_groups`` (one
    group; its ``lr`` may be changed between steps), ``state`` (per parameter ``step`` and
    ``square_avg``, created at a parameter's first gradient), :meth:`step`,
    :meth:`zero_grad`, :meth:`state_dict` and :meth:`load_state_dict`. Parameters without a
    gradient are skipped, as torch skips them.
    """

    def __init__(
        self, params: Iterable[torch.nn.Parameter], lr: float, alpha: float, eps: float
    ) -> None:
        self.params = list(params)
        self.param_groups: list[dict[str, Any]] = [
            {
                "lr": lr,
                "momentum": 0,
                "alpha": alpha,
                "eps": eps,
                "centered": False,
                "weight_decay": 0,
                "capturable": False,
                "foreach": None,
                "maximize": False,
                "differentiable": False,
                "params": self.params,
            }
        ]
        self.state: dict[torch.Tensor, dict[str, Any]] = {}  # "step" a float until saved

    @torch.no_grad()
    def step(self) -> None:
        """One update of every parameter that has a gradient."""
        group = self.param_groups[0]
        lr, alpha, eps = group["lr"], group["alpha"], group["eps"]
        for param in self.params:
            grad = param.grad
            if grad is None:
                continue
            state = self.state.get(param)
            if state is None:
                state = self.state[param] = {
                    "step": 0.0,
                    "square_avg": torch.zeros_like(param, memory_format=torch.preserve_format),
                }
            state["step"] += 1.0
            square_avg = state["square_avg"]
            square_avg.mul_(alpha).addcmul_(grad, grad, value=1 - alpha)
            avg = square_avg.sqrt().add_(eps)
            param.addcdiv_(grad, avg, value=-lr)

    def zero_grad(self, set_to_none: bool = True) -> None:
        """Drop (or zero) every parameter's gradient."""
        for param in self.params:
            if param.grad is None:
                continue
            if set_to_none:
                param.grad = None
            else:
                param.grad.zero_()

    def state_dict(self) -> dict[str, Any]:
        """torch.optim's layout: ``state`` keyed by parameter index, then ``param_groups``."""
        index = {id(p): i for i, p in enumerate(self.params)}
        group = {k: v for k, v in self.param_groups[0].items() if k != "params"}
        group["params"] = list(range(len(self.params)))
        state = {
            index[id(p)]: {"step": torch.tensor(s["step"]), "square_avg": s["square_avg"]}
            for p, s in self.state.items()
        }
        return {"state": dict(sorted(state.items())), "param_groups": [group]}

    def load_state_dict(self, state_dict: Mapping[str, Any]) -> None:
        """Restore a :meth:`state_dict` (or ``torch.optim.RMSprop``'s), copying tensors."""
        groups = state_dict["param_groups"]
        if len(groups) != 1 or len(groups[0]["params"]) != len(self.params):
            raise ValueError(
                f"optimizer state for {sum(len(g['params']) for g in groups)} parameters in "
                f"{len(groups)} group(s), this model has {len(self.params)} in 1"
            )
        saved = {k: v for k, v in groups[0].items() if k != "params"}
        self.param_groups[0].update(saved)
        self.state = {}
        for i, entry in state_dict["state"].items():
            param = self.params[int(i)]
            self.state[param] = {
                "step": float(entry["step"]),
                "square_avg": entry["square_avg"].to(param.device, param.dtype).clone(),
            }
