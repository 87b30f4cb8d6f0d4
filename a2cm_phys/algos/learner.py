"""The A2C / A2CM loss and optimiser step over one time-major batch (SPEC §6).

A :class:`Learner` owns the RMSprop optimiser of an :class:`~a2cm_phys.algos.models.ActorCritic`
and turns one rollout batch into one gradient step:

1. values of ``obs`` and, as targets, of ``next_obs`` (bootstrap) and of the final
   observations of truncated steps;
2. team returns by eq. 13 (:func:`~a2cm_phys.algos.returns.discounted_returns`): A2CM feeds
   them to its one critic, A2C broadcasts the same team reward to each agent's critic, which
   bootstraps with its own values; advantages ``G − V`` per critic (eq. 12), detached;
3. loss ``Σ_i [−mean(A_i · log π_i(a_i|s)) − entropy_coef · H(π_i)] + value_coef · Σ_c MSE_c``
   where ``A_i`` is agent i's critic's advantage (A2C) or the shared one (A2CM).

Two interchangeable implementations (``backend``) compute the same loss and gradients:

- ``"torch"``: the reference, plain autograd over :meth:`ActorCritic.forward` and
  ``optimizer.step()``; any device.
- ``"numpy"`` (the default for a CPU float32 model): the gradient of this fixed two-layer
  architecture written out by hand (:class:`_NumpyGrad`), on the model's packed parameters
  (:meth:`~a2cm_phys.algos.models.ActorCritic.packed`). All first layers are one matmul, the
  second layers one batched matmul per kind; only the critics see the bootstrap and final
  observations. The matmuls run in numpy, whose BLAS is several times faster than torch's
  at these shapes on the target CPU, capped to torch's thread count. Gradients land in one
  flat buffer (``p.grad`` are views of it), so the norm, clipping and RMSprop (torch's own op
  sequence, on the packed buffers) are a handful of ops. About 4× faster than the reference
  at the paper's batch (T=8, B=16); tests check both against a plain float64 computation.
"""

from __future__ import annotations

import copy
import functools
import math
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
import torch
from threadpoolctl import ThreadpoolController

from a2cm_phys.algos.returns import advantages, discounted_returns, discounted_returns_np

if TYPE_CHECKING:
    from a2cm_phys.algos.models import ActorCritic, PackedParams
    from a2cm_phys.config import Train

BATCH_KEYS = ("obs", "actions", "rewards", "terminated", "truncated", "final_obs", "next_obs")
"""Keys :meth:`Learner.update` reads from a batch (all time-major except ``next_obs``)."""


@functools.cache
def _blas() -> ThreadpoolController:
    """numpy's BLAS thread pools, found once. OpenBLAS splits the learner's matmuls over
    every core; on a small shared machine a step then waits for a thread that is not
    scheduled (0.5 ms updates measured at 4 ms), so updates cap it to torch's thread count."""
    return ThreadpoolController()


LearnerBackend = Literal["auto", "numpy", "torch"]


class NonFiniteLoss(FloatingPointError):
    """The loss or its gradient was NaN/inf; the optimiser was NOT stepped.

    The model and optimiser are exactly as before the failed :meth:`Learner.update`, so a
    trainer can stop and keep its last good checkpoint. ``metrics`` holds what was computed.
    """

    def __init__(self, message: str, metrics: dict[str, float]) -> None:
        super().__init__(message)
        self.metrics = metrics


class Learner:
    """Loss and RMSprop step for A2C / A2CM.

    Args:
        model: the network to train (its ``n_critics`` decides A2C vs A2CM behaviour).
        train_cfg: hyperparameters: ``lr``, ``rmsprop_alpha`` (Keras rho), ``rmsprop_eps``,
            ``gamma``, ``entropy_coef``, ``value_coef``, ``reward_scale``, ``max_grad_norm``.
        backend: ``"numpy"`` (hand-written gradient, CPU float32 only), ``"torch"`` (autograd
            reference) or ``"auto"`` (numpy whenever the model allows it, else torch).
    """

    def __init__(
        self, model: ActorCritic, train_cfg: Train, *, backend: LearnerBackend = "auto"
    ) -> None:
        if backend not in ("auto", "numpy", "torch"):
            raise ValueError(f"unknown backend {backend!r}")
        self.model = model
        self.cfg = train_cfg
        self.backend = backend
        # torch RMSprop = Keras RMSprop (non-centred, no momentum, eps outside the sqrt)
        self.optimizer = torch.optim.RMSprop(
            model.parameters(),
            lr=train_cfg.lr,
            alpha=train_cfg.rmsprop_alpha,
            eps=train_cfg.rmsprop_eps,
        )
        self.device = next(model.parameters()).device
        self._fast: _NumpyGrad | None = None

    def update(self, batch: Mapping[str, Any]) -> dict[str, float]:
        """One gradient step on a rollout batch; returns scalar metrics.

        Args:
            batch: tensors (or arrays) keyed as in :data:`BATCH_KEYS`: ``obs (T,B,obs_dim)``,
                ``actions (T,B,N)`` int64, ``rewards (T,B)`` raw team reward (multiplied by
                ``reward_scale`` here), ``terminated (T,B)`` and ``truncated (T,B)`` bool,
                ``final_obs (T,B,obs_dim)`` (the episode's last observation where it ended;
                only read where truncated), ``next_obs (B,obs_dim)`` (after the batch).

        Returns:
            ``policy_loss`` (Σ over agents), ``value_loss`` (Σ over critics of the MSE, before
            ``value_coef``), ``entropy`` (mean over agents and steps), ``mean_advantage``,
            ``grad_norm`` (total, before clipping) and ``loss`` (the optimised total).

        Raises:
            NonFiniteLoss: the loss or the gradient norm is NaN/inf (no step was taken).
        """
        packed = self._numpy_packed()
        if packed is None:
            return self._update_torch(batch)
        if self._fast is None or self._fast.packed is not packed:
            self._fast = _NumpyGrad(self.model, packed)
        return self._update_numpy(self._fast, batch)

    @property
    def active_backend(self) -> Literal["numpy", "torch"]:
        """The implementation the next :meth:`update` will use."""
        return "torch" if self._numpy_packed() is None else "numpy"

    def _numpy_packed(self) -> PackedParams | None:
        """The model's packed parameters if the numpy path applies, else ``None``."""
        packed = None if self.backend == "torch" else self.model.packed()
        if packed is None or packed.flat.device.type != "cpu" or packed.flat.dtype != torch.float32:
            if self.backend == "numpy":
                raise ValueError("the numpy backend needs a packed CPU float32 model")
            return None
        return packed

    # ------------------------------------------------------------------ numpy fast path
    def _update_numpy(self, fast: _NumpyGrad, batch: Mapping[str, Any]) -> dict[str, float]:
        # non-finite values are reported by NonFiniteLoss, as on the torch path: no warnings
        with (
            _blas().limit(limits=torch.get_num_threads(), user_api="blas"),
            np.errstate(all="ignore"),
        ):
            metrics = fast.loss_and_grad(batch, self.cfg)
        if not math.isfinite(metrics["loss"]):
            raise NonFiniteLoss(f"non-finite loss {metrics['loss']} (no step taken)", metrics)
        grad = fast.grad_flat
        norm = torch.linalg.vector_norm(grad)
        metrics["grad_norm"] = norm.item()
        if not math.isfinite(metrics["grad_norm"]):
            self.optimizer.zero_grad(set_to_none=True)
            raise NonFiniteLoss(
                f"non-finite gradient norm {metrics['grad_norm']} (no step taken)", metrics
            )
        if self.cfg.max_grad_norm > 0:  # as torch.nn.utils.clip_grad_norm_
            grad.mul_(torch.clamp(self.cfg.max_grad_norm / (norm + 1e-6), max=1.0))
        fast.attach_grads()
        if not fast.rmsprop_step(self.optimizer):
            self.optimizer.step()
        self.model.refresh_snapshot()
        return metrics

    # ------------------------------------------------------------------ torch reference
    def _update_torch(self, batch: Mapping[str, Any]) -> dict[str, float]:
        b = {k: torch.as_tensor(batch[k], device=self.device) for k in BATCH_KEYS}
        obs = b["obs"].float()
        truncated = b["truncated"].bool()
        n_envs = obs.shape[1]

        logits, values = self.model(obs)  # (T,B,N,A), (T,B,C)
        with torch.no_grad():
            # one critic forward for the bootstrap state and every truncated final obs
            extra = torch.cat([b["next_obs"].float(), b["final_obs"].float()[truncated]])
            extra_values = self.model.value(extra)
            boot = extra_values[:n_envs]
            trunc_values = values.new_zeros(values.shape)
            trunc_values[truncated] = extra_values[n_envs:]
            returns = discounted_returns(
                b["rewards"].float() * self.cfg.reward_scale,
                b["terminated"],
                truncated,
                boot,
                trunc_values,
                self.cfg.gamma,
            ).to(values.dtype)  # (T,B,C): A2C broadcasts the team reward to every critic
            adv = advantages(returns, values.detach())  # (T,B,C), broadcasts over agents

        log_probs = torch.log_softmax(logits, -1)
        taken = log_probs.gather(-1, b["actions"].long().unsqueeze(-1)).squeeze(-1)  # (T,B,N)
        entropy = -(log_probs.exp() * log_probs).sum(-1)  # (T,B,N)
        policy_loss = -(adv * taken).mean(dim=(0, 1)).sum()
        entropy_sum = entropy.mean(dim=(0, 1)).sum()
        value_loss = (returns - values).pow(2).mean(dim=(0, 1)).sum()
        loss = policy_loss - self.cfg.entropy_coef * entropy_sum + self.cfg.value_coef * value_loss

        scalars = torch.stack([policy_loss, value_loss, entropy_sum, adv.mean(), loss])
        p_loss, v_loss, ent, mean_adv, total = scalars.tolist()
        metrics = {
            "policy_loss": p_loss,
            "value_loss": v_loss,
            "entropy": ent / self.model.n_agents,
            "mean_advantage": mean_adv,
            "loss": total,
            "grad_norm": math.nan,
        }
        if not math.isfinite(metrics["loss"]):
            raise NonFiniteLoss(f"non-finite loss {metrics['loss']} (no step taken)", metrics)

        self.optimizer.zero_grad(set_to_none=True)
        loss.backward()
        params = [p for p in self.model.parameters() if p.grad is not None]
        if self.cfg.max_grad_norm > 0:
            norm = torch.nn.utils.clip_grad_norm_(params, self.cfg.max_grad_norm)
        else:
            norm = torch.nn.utils.get_total_norm([p.grad for p in params])
        metrics["grad_norm"] = norm.item()
        if not math.isfinite(metrics["grad_norm"]):
            self.optimizer.zero_grad(set_to_none=True)
            raise NonFiniteLoss(
                f"non-finite gradient norm {metrics['grad_norm']} (no step taken)", metrics
            )
        self.optimizer.step()
        self.model.refresh_snapshot()
        return metrics

    # ------------------------------------------------------------------ checkpoints
    def state_dict(self) -> dict[str, Any]:
        """Model and optimiser state, for a bit-exact resume.

        A deep copy: torch's own state dicts alias the live tensors, so an in-memory "last
        good checkpoint" would otherwise change with every later update.
        """
        return copy.deepcopy(
            {"model": self.model.state_dict(), "optimizer": self.optimizer.state_dict()}
        )

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        """Restore what :meth:`state_dict` returned (model weights and RMSprop averages).

        ``state`` is copied, never aliased, so it can be loaded again later.
        """
        self.model.load_state_dict(state["model"])
        self.optimizer.load_state_dict(copy.deepcopy(state["optimizer"]))
        self.model.refresh_snapshot()


_NO_STATE: dict[str, Any] = {}


def _numpy_views(packed: PackedParams) -> PackedParams:
    """The same fields as numpy arrays sharing memory with the tensors."""
    return type(packed)(*(t.detach().numpy() for t in packed))


def _np(x: Any) -> np.ndarray:
    """A numpy view of a CPU tensor or array (no copy when possible)."""
    if isinstance(x, torch.Tensor):
        return x.detach().cpu().numpy()
    return np.asarray(x)


class _NumpyGrad:
    """Hand-written loss and gradient of an A2C/A2CM batch for a packed CPU float32 model.

    Feature-major ("transposed") layout, rows of a batch along the last axis. With K = N + C
    networks of hidden width H over D inputs and ``X`` the ``(rows, D + 1)`` inputs with a
    trailing column of ones: ``Zᵀ = [W1 | b1] Xᵀ`` (every first layer at once, ``(K·H, rows)``),
    ``Hᵀ = relu(Zᵀ)``, then per network k its second layer ``out_k = W2_k Hᵀ_k + b2_k`` as
    one batched matmul for the actors (``(N, A, rows)`` logits) and one for the critics
    (``(C, 1, rows)`` values). Backward from ``d_k = ∂loss/∂out_k`` (first R rows only):
    ``∂W2_k = d_k H_k``, ``∂b2_k = Σ_rows d_k``, ``∂Zᵀ_k = (W2_kᵀ d_k) ⊙ [Z > 0]``,
    ``∂[W1 | b1] = ∂Zᵀ X``.
    """

    def __init__(self, model: ActorCritic, packed: PackedParams) -> None:
        self.packed = packed
        self.n, self.c = model.n_agents, model.n_critics
        self.a, self.h, self.d = model.n_actions, model.hidden, model.obs_dim
        kh = (self.n + self.c) * self.h
        self.params = _numpy_views(packed)
        self.grad_flat = torch.zeros_like(packed.flat)
        self.grads = _numpy_views(model.packed_views(self.grad_flat))
        self.param_views = model.param_views
        self.grad_views = model.param_views(self.grad_flat)
        self.params_in_order = [p for p, _ in self.grad_views]
        self.w1b = np.empty((kh, self.d + 1), dtype=np.float32)  # [W1 | b1]
        self.x = np.ones((0, self.d + 1), dtype=np.float32)
        self._index, self._index_rows = np.zeros((0, 0), dtype=np.int64), -1
        self._ones_r = np.ones(0, dtype=np.float32)
        self._state: tuple[Any, ...] | None = None  # RMSprop state views (see rmsprop_step)

    def _inputs(self, rows: int) -> np.ndarray:
        """The ``(rows, D + 1)`` input buffer, last column all ones."""
        if rows > len(self.x):
            self.x = np.ones((max(rows, 2 * len(self.x)), self.d + 1), dtype=np.float32)
        return self.x[:rows]

    def _ones(self, r: int) -> np.ndarray:
        """``R`` float32 ones (row sums as matrix-vector products)."""
        if len(self._ones_r) != r:
            self._ones_r = np.ones(r, dtype=np.float32)
        return self._ones_r

    def _row_index(self, r: int) -> np.ndarray:
        """``(N, R)`` flat offsets of ``[n, 0, r]`` in a contiguous ``(N, A, R)`` array."""
        if self._index_rows != r:
            offsets = np.arange(self.n)[:, None] * (self.a * r) + np.arange(r)
            self._index, self._index_rows = offsets, r
        return self._index

    def loss_and_grad(self, batch: Mapping[str, Any], cfg: Train) -> dict[str, float]:
        """Forward, loss and backward: fills :attr:`grad_flat`, returns the loss metrics."""
        n, c, a, h, d = self.n, self.c, self.a, self.h, self.d
        nh, na = n * h, n * a
        obs = _np(batch["obs"])
        n_steps, n_envs = obs.shape[:2]
        r = n_steps * n_envs
        truncated = _np(batch["truncated"]).astype(bool, copy=False)
        n_trunc = int(np.count_nonzero(truncated))
        x = self._inputs(r + n_envs + n_trunc)
        x[:r, :d] = obs.reshape(r, d)
        x[r : r + n_envs, :d] = _np(batch["next_obs"])
        if n_trunc:
            x[r + n_envs :, :d] = _np(batch["final_obs"])[truncated]
        p = self.params
        w1b = self.w1b
        w1b[:, :d] = p.w1
        w1b[:, d] = p.b1

        # critics only, for the targets: bootstrap and truncated final observations
        extra = w1b[nh:] @ x[r:].T  # (C·H, B + n_trunc)
        np.maximum(extra, 0.0, out=extra)
        extra = (p.w2_critic @ extra.reshape(c, h, -1)).reshape(c, -1)
        extra += p.b2[na:].reshape(c, 1)

        # the batch through every actor and critic
        hidden = w1b @ x[:r].T  # (K·H, R)
        hidden_torch = torch.from_numpy(hidden)
        torch.relu_(hidden_torch)  # torch's relu is ~5x faster than np.maximum here
        logits = p.w2_actor @ hidden[:nh].reshape(n, h, r)  # (N, A, R)
        logits += p.b2[:na].reshape(n, a, 1)
        values = (p.w2_critic @ hidden[nh:].reshape(c, h, r)).reshape(c, r)  # (C, R)
        values += p.b2[na:].reshape(c, 1)

        # targets (eq. 13) and advantages (eq. 12), (C, R)
        trunc_values = np.zeros((n_steps, n_envs, c), dtype=np.float32)
        if n_trunc:
            trunc_values[truncated] = extra[:, n_envs:].T
        returns = discounted_returns_np(
            np.multiply(_np(batch["rewards"]), np.float32(cfg.reward_scale), dtype=np.float32),
            _np(batch["terminated"]),
            truncated,
            extra[:, :n_envs].T,
            trunc_values,
            cfg.gamma,
            dtype=np.float64,
        )
        # The loss and its gradient w.r.t. the network outputs in float64 (cheap at this size):
        # fewer rounding errors than float32 autograd, which RMSprop would amplify where the
        # gradient is nearly zero. The matmuls stay float32.
        adv = returns.reshape(r, c).T - values.astype(np.float64)  # (C, R)
        adv_agents = adv if c == n else np.broadcast_to(adv, (n, r))  # A_i for actor i

        # loss: softmax over the action axis of (N, A, R)
        logits = logits.astype(np.float64)
        shifted = logits - logits.max(1, keepdims=True)
        probs = np.exp(shifted)
        total = probs.sum(1, keepdims=True)
        probs /= total
        log_probs = shifted
        log_probs -= np.log(total)
        entropy = (probs * log_probs).sum(1)  # (N, R), negated below
        np.negative(entropy, out=entropy)
        actions = _np(batch["actions"]).reshape(r, n).T  # (N, R)
        if actions.min() < 0 or actions.max() >= a:
            raise ValueError(f"actions must be in [0, {a}), got {actions.min()}..{actions.max()}")
        taken_index = self._row_index(r) + actions * r
        taken = log_probs.reshape(-1)[taken_index]  # log π_i(a_i|s), (N, R)
        inv_r = 1.0 / r
        policy_loss = -float((adv_agents * taken).sum()) * inv_r
        entropy_sum = float(entropy.sum()) * inv_r
        value_loss = float(np.vdot(adv, adv)) * inv_r
        loss = policy_loss - cfg.entropy_coef * entropy_sum + cfg.value_coef * value_loss
        metrics = {
            "policy_loss": policy_loss,
            "value_loss": value_loss,
            "entropy": entropy_sum / n,
            "mean_advantage": float(adv.sum()) / adv.size,
            "loss": loss,
            "grad_norm": math.nan,
        }
        if not math.isfinite(loss):
            return metrics

        # ∂loss/∂logits = (1/R)·[π·(A + β·(log π + H)) − A·onehot(a)],
        # ∂loss/∂values = (1/R)·2·c_v·(V − G) = −(2·c_v/R)·A
        d_logits = log_probs
        d_logits += entropy[:, None]
        d_logits *= cfg.entropy_coef
        d_logits += adv_agents[:, None]
        d_logits *= probs
        d_logits.reshape(-1)[taken_index] -= adv_agents
        d_logits *= inv_r
        d_logits = d_logits.astype(np.float32)
        d_values = (adv * (-2.0 * cfg.value_coef * inv_r)).astype(np.float32)
        d_values = d_values.reshape(c, 1, r)

        # backward
        g = self.grads
        ones = self._ones(r)
        np.matmul(d_logits, hidden[:nh].reshape(n, h, r).transpose(0, 2, 1), out=g.w2_actor)
        np.matmul(d_values, hidden[nh:].reshape(c, h, r).transpose(0, 2, 1), out=g.w2_critic)
        np.matmul(d_logits.reshape(na, r), ones, out=g.b2[:na])
        np.matmul(d_values.reshape(c, r), ones, out=g.b2[na:])
        d_hidden = np.empty((n + c, h, r), dtype=np.float32)
        np.matmul(p.w2_actor.transpose(0, 2, 1), d_logits, out=d_hidden[:n])
        np.multiply(p.w2_critic.reshape(c, h, 1), d_values, out=d_hidden[n:])  # outer product
        d_pre = torch.ops.aten.threshold_backward(
            torch.from_numpy(d_hidden.reshape(-1, r)), hidden_torch, 0
        )
        d_w1b = d_pre.numpy() @ x[:r]  # (K·H, D + 1)
        g.w1[...] = d_w1b[:, :d]
        g.b1[...] = d_w1b[:, d]
        return metrics

    def attach_grads(self) -> None:
        """Make every ``p.grad`` the view of :attr:`grad_flat` (cheap if already)."""
        for p, view in self.grad_views:
            if p.grad is not view:
                p.grad = view

    def rmsprop_step(self, optimizer: torch.optim.Optimizer) -> bool:
        """``optimizer.step()`` for plain RMSprop, done on the packed buffers in a few ops.

        The op sequence of torch's single-tensor RMSprop (no momentum, not centred, no weight
        decay), applied to the whole parameter, gradient and ``square_avg`` buffers at once.
        The optimiser's state keeps torch's format: its ``square_avg`` and ``step`` tensors
        become views of two buffers (adopted again after ``load_state_dict``). Returns
        ``False``, doing nothing, for another optimiser or before torch has created the state.
        """
        group = optimizer.param_groups[0]
        if (
            len(optimizer.param_groups) != 1
            or group["momentum"] != 0
            or group["centered"]
            or group["weight_decay"] != 0
            or group["maximize"]
            or group["differentiable"]
            or group["capturable"]
            or isinstance(group["lr"], torch.Tensor)
        ):
            return False
        state = optimizer.state
        if self._state is None or any(
            state.get(p, _NO_STATE).get("square_avg") is not view
            for p, view in zip(self.params_in_order, self._state[1], strict=True)
        ):
            self._state = self._adopt_state(optimizer)
            if self._state is None:
                return False
        square_avg, _, steps = self._state
        lr, alpha, eps = group["lr"], group["alpha"], group["eps"]
        grad, flat = self.grad_flat, self.packed.flat
        with torch.no_grad():
            steps.add_(1)
            square_avg.mul_(alpha).addcmul_(grad, grad, value=1 - alpha)
            avg = square_avg.sqrt().add_(eps)
            flat.addcdiv_(grad, avg, value=-lr)
        return True

    def _adopt_state(self, optimizer: torch.optim.Optimizer) -> tuple[Any, ...] | None:
        """Move the RMSprop state of every parameter into two buffers (values unchanged)."""
        params = self.params_in_order
        group_params = optimizer.param_groups[0]["params"]
        if len(group_params) != len(params) or {id(p) for p in group_params} != {
            id(p) for p in params
        }:
            return None
        state = optimizer.state
        if not all({"square_avg", "step"} <= state.get(p, _NO_STATE).keys() for p in params):
            return None  # first step: let torch create the state
        with torch.no_grad():
            square_avg = torch.empty_like(self.grad_flat)
            views = [view for _, view in self.param_views(square_avg)]
            steps = torch.stack([state[p]["step"].reshape(()) for p in params])
            for i, (p, view) in enumerate(zip(params, views, strict=True)):
                view.copy_(state[p]["square_avg"])
                state[p]["square_avg"] = view
                state[p]["step"] = steps[i]
        return square_avg, views, steps
