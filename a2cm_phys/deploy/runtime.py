"""Running an exported team with numpy and onnxruntime alone: :class:`Actor` (one robot's
ONNX model) and :class:`Team` (every actor of an exported folder, as the env's agents).

An actor's action is the one the env plays: an ``int`` move for discrete control (greedy:
the argmax of the logits; sampled: a softmax sample by Gumbel-max), a float32 command for
continuous control (greedy: the Gaussian's mean; sampled: ``mean + exp(log_std) · ε``),
limited as the env limits every command: a ``(vx, vy)`` velocity (a fraction of
``max_speed``) scaled back onto the unit circle when longer than 1, or a differential-drive
pursuer's ``(forward, turn)`` clipped to ``[-1, 1]`` each.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from .spec import INPUT, LOG_STD, LOGITS, MEAN, POLICY_FILE, DeployError, read_policy

EXTRA = "pip install 'a2cm_phys[deploy]'"
"""What installs the runtime's one dependency beyond numpy."""


def _session(path: Path) -> Any:
    """An onnxruntime session of ``path`` on one CPU thread (the actors are small)."""
    try:
        import onnxruntime as ort
    except ImportError:
        raise DeployError(f"running an exported team needs onnxruntime: {EXTRA}") from None
    options = ort.SessionOptions()
    options.intra_op_num_threads = options.inter_op_num_threads = 1
    options.log_severity_level = 3  # errors only: no warnings about unused initialisers
    try:
        return ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])
    except FileNotFoundError:
        raise DeployError(f"{path}: no such file") from None
    except Exception as err:  # onnxruntime's own exception types vary between versions
        raise DeployError(f"{path}: not a model onnxruntime can run ({err})") from None


def clip_to_disc(commands: np.ndarray) -> np.ndarray:
    """Velocity commands ``(..., 2)`` longer than 1 scaled back onto the unit circle (the
    env's rule: ``v / max(1, |v|)``), as float32."""
    v = np.asarray(commands, dtype=np.float64)
    norm = np.sqrt((v * v).sum(-1, keepdims=True))
    return (v / np.maximum(norm, 1.0)).astype(np.float32)


def clip_to_box(commands: np.ndarray) -> np.ndarray:
    """Differential-drive commands ``(..., 2)`` ``(forward, turn)`` clipped to ``[-1, 1]``
    each (the env's rule for them), as float32."""
    return np.clip(np.asarray(commands, dtype=np.float64), -1.0, 1.0).astype(np.float32)


Clip = Callable[[np.ndarray], np.ndarray]
"""How a continuous command is limited before the env plays it."""


class Actor:
    """One agent's exported actor: its ONNX model, run by onnxruntime.

    Use :meth:`load`; ``continuous`` says which outputs it has (``logits``, or ``mean`` and
    ``log_std``); ``clip`` limits its continuous commands (:func:`clip_to_disc` for velocity
    commands, :func:`clip_to_box` for a differential-drive pursuer's).
    """

    def __init__(
        self, session: Any, continuous: bool, name: str = "actor", clip: Clip = clip_to_disc
    ) -> None:
        self.session = session
        self.continuous = continuous
        self.name = name
        self.clip = clip
        inputs = session.get_inputs()
        if len(inputs) != 1 or inputs[0].name != INPUT:
            raise DeployError(f"{name}: expected one input named {INPUT!r}")
        self.obs_dim = int(inputs[0].shape[-1])
        outputs = [o.name for o in session.get_outputs()]
        want = [MEAN, LOG_STD] if continuous else [LOGITS]
        if outputs != want:
            raise DeployError(f"{name}: outputs {outputs}, expected {want}")

    @classmethod
    def load(cls, path: str | Path, clip: Clip = clip_to_disc) -> Actor:
        """The actor of one ``.onnx`` file (discrete or continuous, from its outputs), its
        commands limited by ``clip``."""
        path = Path(path)
        session = _session(path)
        names = [o.name for o in session.get_outputs()]
        return cls(session, continuous=MEAN in names, name=str(path), clip=clip)

    def outputs(self, obs: np.ndarray) -> dict[str, np.ndarray]:
        """The distribution's parameters for observations ``(B, obs_dim)`` (or one
        ``(obs_dim,)``): ``{"logits": (B, A)}`` or ``{"mean": (B, 2), "log_std": (B, 2)}``
        (without the batch axis for one observation)."""
        x = np.asarray(obs, dtype=np.float32)
        single = x.ndim == 1
        if x.ndim not in (1, 2) or x.shape[-1] != self.obs_dim:
            raise DeployError(
                f"{self.name}: observations of shape {x.shape}, expected ({self.obs_dim},) or"
                f" (batch, {self.obs_dim})"
            )
        x = np.ascontiguousarray(x[None] if single else x)
        names = [o.name for o in self.session.get_outputs()]
        values = self.session.run(names, {INPUT: x})
        return {n: v[0] if single else v for n, v in zip(names, values, strict=True)}

    def act(
        self, obs: np.ndarray, rng: np.random.Generator | None = None, greedy: bool = True
    ) -> np.ndarray:
        """Actions for observations ``(B, obs_dim)`` (``(B,)`` int64 moves or ``(B, 2)``
        float32 commands), or one action for one ``(obs_dim,)`` observation. Greedy by
        default; ``greedy=False`` samples with ``rng`` (a new unseeded generator if none)."""
        return choose(self.outputs(obs), self.continuous, rng, greedy, self.clip)


def choose(
    outputs: Mapping[str, np.ndarray],
    continuous: bool,
    rng: np.random.Generator | None = None,
    greedy: bool = True,
    clip: Clip = clip_to_disc,
) -> np.ndarray:
    """The actions of actors' ``outputs`` (``logits (..., A)``, or ``mean`` and ``log_std
    (..., 2)``): greedy, or sampled with ``rng`` drawing one variate per output, in the
    outputs' order, as the package's own actors do (so the same ``rng`` gives the same
    samples as the run's team when the outputs are stacked ``(B, N, ...)`` alike); continuous
    commands limited by ``clip``."""
    if not greedy and rng is None:
        rng = np.random.default_rng()
    if not continuous:
        logits = outputs[LOGITS]
        if not greedy:  # Gumbel-max: exact softmax samples
            logits = logits + rng.gumbel(size=logits.shape)
        return logits.argmax(-1).astype(np.int64)
    mean = outputs[MEAN]
    if not greedy:
        noise = rng.standard_normal(mean.shape, dtype=np.float32)
        mean = (mean + np.exp(outputs[LOG_STD]) * noise).astype(np.float32)
    return clip(mean)


def pursuer_clip(policy: Mapping[str, Any]) -> Clip:
    """How ``policy.json`` says the pursuers' commands are limited: :func:`clip_to_box` with
    differential drive (``actions.drive``), else :func:`clip_to_disc` (files exported before
    differential drive existed hold no ``drive``: holonomic)."""
    drive = policy["actions"].get("drive", "holonomic")
    if drive not in ("holonomic", "differential"):
        raise DeployError(
            f"{POLICY_FILE}: actions.drive {drive!r}, expected holonomic or differential"
        )
    return clip_to_box if drive == "differential" else clip_to_disc


class Team:
    """The actors of an exported folder (``policy.json`` and its ONNX models).

    ``agents`` names them in the env's order (``pursuer_0``, …, then ``evader`` for a
    learned evader); ``policy`` is the folder's ``policy.json``; ``scenario`` the scenario
    the actors were trained in (a plain dict, as the run's ``config.json`` holds it).
    """

    def __init__(self, actors: Mapping[str, Actor], policy: dict[str, Any]) -> None:
        self.actors = dict(actors)
        self.policy = policy
        self.scenario: dict[str, Any] = policy["scenario"]
        self.agents = list(self.actors)
        self.pursuers = [a for a in self.agents if a != "evader"]
        self.continuous = policy["actions"]["control"] == "continuous"
        self.clip = pursuer_clip(policy)
        """How the pursuers' continuous commands are limited (the evader's: its actor's)."""
        kind = policy["observation"]["encoding"]["kind"]
        self.encoding: str | None = None if kind in ("xy", "relative", "metric") else kind
        """``None`` when the actors read the observation itself (relative and metric inputs
        are folded into their first layers); ``"onehot"`` when they
        read one-hot cells."""
        self.arena_bound = kind in ("onehot", "metric")
        """Whether the actors know one arena size only (one-hot cells, metric offsets)."""
        size = policy["observation"]["size"]
        for agent, actor in self.actors.items():
            if actor.obs_dim != size or actor.continuous != self.continuous:
                raise DeployError(
                    f"{actor.name}: reads {actor.obs_dim} numbers and is"
                    f" {'continuous' if actor.continuous else 'discrete'}, but policy.json"
                    f" says {size} and {policy['actions']['control']} ({agent})"
                )

    @classmethod
    def load(cls, folder: str | Path) -> Team:
        """The team exported into ``folder`` (a :class:`DeployError` naming what is wrong)."""
        folder = Path(folder)
        policy = read_policy(folder)
        clip = pursuer_clip(policy)
        actors = {
            a["agent"]: Actor.load(
                folder / a["file"], clip_to_disc if a["agent"] == "evader" else clip
            )
            for a in policy["actors"]
        }
        return cls(actors, policy)

    def act(
        self,
        observations: Mapping[str, np.ndarray] | np.ndarray,
        rng: np.random.Generator | None = None,
        greedy: bool = True,
    ) -> dict[str, Any] | np.ndarray:
        """The team's actions, greedy by default (``greedy=False`` samples with ``rng``, a
        new unseeded generator if none).

        ``observations`` as the env gives them, ``{agent: obs}``: returns ``{agent: action}``
        for every agent of it the team has an actor for (an ``int`` move, or a float32
        command), ready for ``env.step``. Or an array ``(B, obs_dim)`` of observations:
        returns the pursuers' actions ``(B, N)`` or ``(B, N, 2)``, as the package's rollout
        policies do (``(N, ...)`` for one ``(obs_dim,)`` observation).
        """
        if isinstance(observations, Mapping):
            pursuers = [a for a in self.pursuers if a in observations]
            out = {}
            if pursuers:
                heads = self._outputs(pursuers, [observations[a] for a in pursuers])
                actions = choose(heads, self.continuous, rng, greedy, self.clip)
                out = dict(zip(pursuers, actions, strict=True))
            if "evader" in observations and "evader" in self.actors:
                out["evader"] = self.actors["evader"].act(observations["evader"], rng, greedy)
            return {a: v if self.continuous else int(v) for a, v in out.items()}
        obs = np.asarray(observations, dtype=np.float32)
        heads = self._outputs(self.pursuers, [obs] * len(self.pursuers))
        return choose(heads, self.continuous, rng, greedy, self.clip)

    def _outputs(self, agents: list[str], obs: list[np.ndarray]) -> dict[str, np.ndarray]:
        """The ``agents``' outputs on their observations, stacked ``(..., agents, O)``."""
        each = [self.actors[a].outputs(o) for a, o in zip(agents, obs, strict=True)]
        return {k: np.stack([e[k] for e in each], axis=-2) for k in each[0]}

    def rollout_policy(
        self, greedy: bool = True, side: str = "pursuers"
    ) -> Callable[[np.ndarray, np.random.Generator], np.ndarray]:
        """The team as a rollout policy ``policy(obs (B, obs_dim), rng) -> actions``: the
        pursuers' ``(B, N, ...)``, or with ``side="evader"`` the learned evader's
        ``(B, 1, ...)`` (a :class:`DeployError` if the team has none)."""
        if side == "pursuers":
            return lambda obs, rng: self.act(obs, rng, greedy)
        if "evader" not in self.actors:
            raise DeployError("this exported team has no learned evader (no evader.onnx)")
        evader = self.actors["evader"]
        return lambda obs, rng: np.expand_dims(evader.act(obs, rng, greedy), 1)
