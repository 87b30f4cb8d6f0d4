"""A row of the claims table (:class:`Claim`), what the claims are measured on
(:class:`Data`), and how figures and rows are written."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ...analysis.stats import UNSURE, Interval
from .measure import RunResult


@dataclass
class Data:
    """What the claims are measured on."""

    by_cell: dict[tuple[str, str, str], list[RunResult]]
    references: dict[str, dict[str, Any] | None]
    pursuit: dict[str, dict[str, Any]] = field(default_factory=dict)
    exploit: dict[str, list[dict[str, Any]]] = field(default_factory=dict)
    oracle_worst_case: dict[str, Any] | None = None
    minimax: dict[str, Any] | None = None
    game_value: dict[str, Any] | None = None
    parity: dict[str, list[dict[str, Any]]] = field(default_factory=dict)
    crossplay: list[dict[str, Any]] = field(default_factory=list)
    modes: list[str] = field(default_factory=list)
    groups: list[str] = field(default_factory=list)

    def runs(self, group: str, scenario: str, algo: str) -> list[RunResult]:
        """The finished runs of a cell."""
        return self.by_cell.get((group, scenario, algo), [])


@dataclass
class Claim:
    """One row of the claims table. ``sizes`` are the samples its test compares (seeds per
    side, or per cell): a test of a spread decides nothing from one sample, so a claim with
    a side of fewer than two is inconclusive whatever its figures say."""

    who: str  # "paper" or "ours"
    claim: str
    scope: str
    measured: str
    interval: str
    verdict: str
    test: str
    anchor: str = ""
    sizes: tuple[int, ...] = ()

    def __post_init__(self) -> None:
        if self.sizes and min(self.sizes) < 2:
            self.verdict = UNSURE

    @property
    def evidence(self) -> str:
        """The sample sizes as the verdict names them: ``n = 5 vs 5``, ``n = 1``."""
        if not self.sizes:
            return ""
        if len(set(self.sizes)) == 1 and min(self.sizes) < 2:
            return f"n = {self.sizes[0]}"
        return "n = " + " vs ".join(str(n) for n in self.sizes)


def fmt(x: float, digits: int = 3) -> str:
    """A number to ``digits`` significant digits, thousands separated; ``—`` if not finite."""
    if x is None or not np.isfinite(x):
        return "—"
    if abs(x) >= 10**digits:
        return f"{x:,.0f}"
    return f"{x:.{digits}g}"


def ci_text(interval: Interval, digits: int = 3) -> str:
    """``[lo, hi]`` or ``—``."""
    _, lo, hi = interval
    if not (np.isfinite(lo) and np.isfinite(hi)):
        return "— (one seed)"
    return f"[{fmt(lo, digits)}, {fmt(hi, digits)}]"


def p_text(p: float) -> str:
    """A p-value as the claims table gives it: ``p = 0.0123``, or ``p = —`` without one."""
    return "p = —" if not np.isfinite(p) else f"p = {p:.3g}"


SELF_PLAY_KIND = {"selfplay": "self-play", "descent": "descent"}
"""How each self-play group's teams are named (``A2CM self-play``, ``A2CM descent``)."""


def team_name(key: str) -> str:
    """A self-play group's team of ``group/algo``: ``A2CM self-play``, ``A2C descent``."""
    group, algo = key.split("/")
    return f"{algo.upper()} {SELF_PLAY_KIND[group]}"


def claims_table(claims: list[Claim]) -> list[str]:
    """The claims as Markdown rows."""
    lines = [
        "| who | claim | scope | measured | 95% CI | verdict | test |",
        "|---|---|---|---|---|---|---|",
    ]
    for c in claims:
        scope = f"[{c.scope}]({c.anchor})" if c.anchor else c.scope
        evidence = f" ({c.evidence})" if c.evidence else ""
        lines.append(
            f"| {c.who} | {c.claim} | {scope} | {c.measured} | {c.interval} | "
            f"**{c.verdict}**{evidence} | {c.test} |"
        )
    return lines
