"""What every learning-curve figure shares: its colours, the one y-scale rule, what each
column is called on an axis, and the reference line (:class:`Reference`, from
:func:`~.evaluation.reference_of`, the project's one reference).

The y-scale rule (:data:`Y_SCALES`): steps, returns, their parts and collisions are drawn
on a linear axis, always; only a ratio to the reference (the report's return ÷ the
reference's) is on a log axis, always. The scale never depends on the data, and each axis
label names it (:func:`axis_label`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..config import Scenario
from .run_series import collision_weight

__all__ = [
    "COLOURS",
    "COLUMNS",
    "Y_SCALES",
    "Reference",
    "axis_label",
    "draw_reference",
    "reference_for",
    "reference_level",
    "references_for",
]

COLOURS = ("#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#17becf")

COLUMNS = {
    "length": "steps per episode",
    "time": "return without the collision penalty",
    "collision_part": "return's collision penalty (collisions × penalty)",
    "collisions": "pursuer collisions per episode",
    "return": "return (raw team reward)",
    "relative": "return ÷ reference's return (1 = as good)",
}
"""What each drawn column is, on its axis. ``time`` and ``collision_part`` split the return:
``collision_part`` is the collisions times the scenario's collision penalty, ``time`` the
rest (the step, capture and wall rewards); they sum to the return."""

Y_SCALES = {column: "log" if column == "relative" else "linear" for column in COLUMNS}
"""The y scale of each column: linear for every count and return, log for a ratio."""


def axis_label(column: str) -> str:
    """The y label of ``column``, its scale named: ``steps per episode (linear scale)``."""
    return f"{COLUMNS[column]} ({Y_SCALES[column]} scale)"


@dataclass(frozen=True)
class Reference:
    """A dashed line: the optimum or a reference policy, or why there is none.

    ``time``, ``collision_part`` and ``collisions`` are the return's parts and the
    collisions per episode (``nan`` where not known); ``unavailable`` says why a scenario
    has no reference (then the figures say so instead of drawing a line)."""

    name: str
    length: float = math.nan
    ret: float = math.nan
    time: float = math.nan
    collision_part: float = math.nan
    collisions: float = math.nan
    unavailable: str | None = None


def reference_level(ref: Reference, column: str) -> float:
    """Where ``ref``'s line lies on a ``column`` axis (``nan``: not known)."""
    if column == "relative":
        return 1.0
    attr = {"length": "length", "return": "ret"}.get(column, column)
    return float(getattr(ref, attr, math.nan))


def reference_for(scenario: Scenario, episodes: int = 500) -> Reference:
    """The reference line of ``scenario`` (:func:`~.evaluation.reference_of`): the exact
    optimum on grids the oracle solves, else the reference policy played for ``episodes``
    episodes; where there is none (``episodes`` 0 in physics, a learned evader, an arena
    too large for the oracle) a :class:`Reference` whose ``unavailable`` says why."""
    from ..config import ConfigError
    from .evaluation import reference_of, reference_policy

    name = reference_policy(scenario)
    if scenario.mode != "grid" and not episodes:
        return Reference(name, unavailable="the reference policy was not played (0 episodes)")
    try:
        ref = reference_of(scenario, episodes=episodes)
    except (ConfigError, ValueError) as err:  # a physics game with a learned evader
        why = "no reference against a learned evader" if scenario.evader == "learned" else err
        return Reference(name, unavailable=str(why))
    if ref is None:
        return Reference(name, unavailable="no reference policy")
    if ref.unavailable is not None:
        return Reference(ref.label, unavailable=ref.unavailable)
    weight = collision_weight(scenario)
    if ref.exact:
        rw = scenario.rewards
        time = rw.step * ref.length if rw.capture == 0 and rw.wall == 0 else math.nan
        if not weight:
            time = ref.ret
        part = ref.ret - time
        part = 0.0 if abs(part) <= 1e-9 * max(abs(ref.ret), 1.0) else part  # rounding
        collisions = part / weight if weight and part else 0.0
        return Reference("optimum (exact oracle)", ref.length, ref.ret, time, part, collisions)
    collisions = float(ref.played.collisions.mean())
    part = weight * collisions + 0.0  # not -0.0
    return Reference(ref.label, ref.length, ref.ret, ref.ret - part, part, collisions)


def draw_reference(ax: object, ref: Reference, column: str, where: str = "") -> float:
    """``ref``'s dashed line on a ``column`` axis, labelled with its level (``where``: the
    scenario's name, where several share the axis); where there is none, a legend entry
    that says why. Return the level (``nan`` if none was drawn)."""
    prefix = f"{where}: " if where else ""
    if ref.unavailable is not None:
        ax.plot([], [], " ", label=f"{prefix}no reference line: {ref.unavailable}")
        return math.nan
    level = reference_level(ref, column)
    if not math.isfinite(level):
        ax.plot([], [], " ", label=f"{prefix}{ref.name}: not known for this axis")
        return math.nan
    ax.axhline(level, color="k", ls="--", lw=1.2, label=f"{prefix}{ref.name}: {level:.4g}")
    return level


def references_for(scenarios: list[Scenario | None], episodes: int = 500) -> dict[str, Reference]:
    """:func:`reference_for` of each distinct scenario (by name; ``None`` skipped)."""
    references: dict[str, Reference] = {}
    for sc in scenarios:
        if sc is not None and sc.name not in references:
            references[sc.name] = reference_for(sc, episodes)
    return references
