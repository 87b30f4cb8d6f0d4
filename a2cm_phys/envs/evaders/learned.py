"""A learned evader (SPEC §1b, ``evader = "learned"``): an agent whose actions come from outside.

The cores play every evader as an injected :class:`~.core.EvaderPolicy`; a learned one is
:class:`LearnedEvader`, a policy that plays what it was *given* for the step. A core whose
policy has a ``give`` method takes the evader's actions with the step,
``core.step(actions, evader_actions)``, gives them to the policy and then plays the step
exactly as with a scripted evader, so the rules stay written once per mode. A core with a
scripted evader refuses ``evader_actions``; a core with a learned one refuses a step
without them (both :class:`ValueError`, see :func:`refuse_evader_actions` and
:meth:`LearnedEvader.give`).

The evader's actions have the pursuers' kind: ``(B,)`` integer moves in
``[0, scenario.actions)`` (grid and discrete physics), or ``(B, 2)`` velocity commands as
fractions of ``max_speed`` with continuous control, clipped to the unit disc by the core
like the pursuers' (NaN or inf is a ``ValueError`` naming the agent ``evader``).
"""

from __future__ import annotations

import numpy as np

from ...config import Scenario

EVADER = "evader"
"""The learned evader's agent name (last in the parallel API's ``possible_agents``)."""


def evader_action_shape(scenario: Scenario) -> tuple[int, ...]:
    """One game's evader action: ``()`` a move, or ``(2,)`` a command with continuous control."""
    return (2,) if scenario.continuous else ()


def check_evader_actions(scenario: Scenario, actions: object, num_envs: int) -> np.ndarray:
    """The evader's actions of ``num_envs`` games as a fresh ``(B,)`` int64 or ``(B, 2)``
    float64 array, or a ``ValueError`` naming the agent ``evader`` and the value at fault."""
    array = np.asarray(actions)
    shape = (num_envs, *evader_action_shape(scenario))
    kind = "(vx, vy) commands" if scenario.continuous else "integer moves"
    if array.shape != shape:
        raise ValueError(f"expected evader actions of shape {shape} ({kind}), got {array.shape}")
    if scenario.continuous:
        if array.dtype.kind not in "iuf":
            raise ValueError(f"expected real-valued evader commands, got dtype {array.dtype}")
        bad = ~np.isfinite(array).all(-1)
        if bad.any():
            env = int(np.argmax(bad))
            raise ValueError(
                f"invalid action {array[env].tolist()} for {EVADER}{_where(env, num_envs)}:"
                " expected a finite (vx, vy) command"
            )
        return array.astype(np.float64)
    n_actions = scenario.actions
    if array.dtype.kind not in "iu":
        raise ValueError(f"expected integer evader moves, got dtype {array.dtype}")
    bad = (array < 0) | (array >= n_actions)
    if bad.any():
        env = int(np.argmax(bad))
        raise ValueError(
            f"invalid action {int(array[env])} for {EVADER}{_where(env, num_envs)}:"
            f" expected an integer in [0, {n_actions})"
        )
    return array.astype(np.int64)


def take_evader_actions(scenario: Scenario, actions: object | None, num_envs: int) -> np.ndarray:
    """:func:`check_evader_actions`, and a ``ValueError`` for ``None``: a learned evader
    cannot step without its actions."""
    if actions is None:
        shape = (num_envs, *evader_action_shape(scenario))
        raise ValueError(
            f"scenario '{scenario.name}' has a learned evader (evader = 'learned'): "
            f"the step needs evader_actions of shape {shape}"
        )
    return check_evader_actions(scenario, actions, num_envs)


def _where(env: int, num_envs: int) -> str:
    return f" in env {env}" if num_envs > 1 else ""


def refuse_evader_actions(scenario: Scenario) -> ValueError:
    """The error of a step given evader actions in a scenario whose evader is scripted."""
    return ValueError(
        f"scenario '{scenario.name}' has a scripted evader (evader = '{scenario.evader}'):"
        " the step takes no evader_actions (set evader = 'learned' to act for it)"
    )


class LearnedEvader:
    """The evader of ``num_envs`` games as the agent ``evader``: each step plays the actions
    given to it for that step (implements :class:`~.core.EvaderPolicy`, plus :meth:`give`)."""

    needs_positions = False  # it reads nothing of the game: the agent decided already

    def __init__(self, scenario: Scenario, num_envs: int) -> None:
        self.scenario = scenario
        self.num_envs = num_envs
        self._given: np.ndarray | None = None

    def give(self, actions: object | None) -> None:
        """The evader's actions for the coming step, checked by :func:`take_evader_actions`
        (``None`` is a ``ValueError``)."""
        self._given = take_evader_actions(self.scenario, actions, self.num_envs)

    def restart(self, envs: np.ndarray, seeds: np.ndarray) -> None:
        """Nothing to do: the evader's actions come with each step."""

    def forget(self) -> None:
        """Drop actions given but not played yet."""
        self._given = None

    def moves(
        self,
        seed: np.ndarray,
        t: np.ndarray,
        evader_xy: np.ndarray | None = None,
        pursuer_xy: np.ndarray | None = None,
    ) -> np.ndarray:
        """The actions given for this step (each given set is played once)."""
        given, self._given = self._given, None
        if given is None:
            self.give(None)  # raises: nothing was given
        return given
