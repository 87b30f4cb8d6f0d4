"""Every policy a command can name, once: what ``--pursuers`` and ``--evader`` accept.

``evaluate`` plays a named policy in episodes (:mod:`a2cm_phys.analysis.policies`), and
``oracle`` reads one as an exact policy table (:mod:`a2cm_phys.analysis.sources`); a name
means the same policy in both (``oracle`` against a learned evader: the team optimal
against the random evader, :func:`oracle_evader`). Every name has both forms on grids but
one: the best-response evader is solved for the pairing it plays, so it has no table of its
own (:attr:`NamedPolicy.no_table` says why). Anything else given for ``--pursuers`` or
``--evader`` is a run directory.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from ..config import SCRIPTED_EVADERS, Scenario

Side = Literal["pursuers", "evader"]


@dataclass(frozen=True)
class NamedPolicy:
    """One named policy: its side, what it is, and the forms it has (``played``: a rollout
    policy for ``evaluate``; ``tabled``: an exact table for ``oracle``, or ``no_table``:
    one line saying why not)."""

    name: str
    side: Side
    about: str
    played: bool = True
    no_table: str = ""

    @property
    def tabled(self) -> bool:
        """Whether ``oracle`` can read it as an exact table (on grids)."""
        return not self.no_table


NAMED_POLICIES: tuple[NamedPolicy, ...] = (
    NamedPolicy("random", "pursuers", "uniformly random moves (or commands in the unit square)"),
    NamedPolicy(
        "pursuit", "pursuers",
        "each pursuer straight at the evader (around obstacles, along a shortest path)",
    ),
    NamedPolicy(
        "oracle", "pursuers",
        "the exact optimum against the scenario's scripted evader (the random one where the"
        " evader is learned)",
    ),
    NamedPolicy("minimax", "pursuers", "the team optimal when the evader sees its move (grids)"),
    NamedPolicy(
        "qmdp", "pursuers",
        "belief planning on the oracle's values: a Bayes filter over the evader's cell from"
        " the team's pooled sightings (grids with sensing)",
        no_table="qmdp acts on its belief, which the whole episode's sightings make, not on"
        " the joint state alone, so it has no table over joint states",
    ),
    NamedPolicy(
        "search", "pursuers",
        "each pursuer sweeps its strip until the team sights the evader, then all chase it"
        " (physics, continuous control, with sensing)",
        no_table="search steers with velocity commands in physics and remembers its sweep,"
        " so it has no table over the grid's joint states",
    ),
    *(NamedPolicy(e, "evader", f"the scripted {e} evader") for e in SCRIPTED_EVADERS),
    NamedPolicy(
        "best-response", "evader", "the best response to the pursuers",
        no_table="the best-response evader is solved against the pursuers it plays, so it has"
        " no table of its own: ask for it with --best-response evader --pursuers P",
    ),
    NamedPolicy("equilibrium", "evader", "the game's equilibrium evader (grids; minutes to solve)"),
)  # fmt: skip
"""The registry: every name, in the order help texts list them."""


def policy_names(side: Side, form: Literal["played", "tabled"] = "played") -> tuple[str, ...]:
    """The names of ``side``'s policies that have ``form``."""
    return tuple(p.name for p in NAMED_POLICIES if p.side == side and getattr(p, form))


PURSUER_POLICIES = policy_names("pursuers")
"""Pursuers ``evaluate`` plays by name."""

PURSUER_TABLES = policy_names("pursuers", "tabled")
"""Pursuers ``oracle`` reads as exact tables by name."""

EVADER_POLICIES = SCRIPTED_EVADERS
"""Evaders the scenario's core plays by a fixed rule."""

BEST_RESPONSE = "best-response"
"""The evader that is the exact best response to the pursuers of the pairing."""

EQUILIBRIUM = "equilibrium"
"""The game's equilibrium evader: mixed, so always sampled; no team catches it sooner on
average than the game's value."""

SOLVED_EVADERS = tuple(n for n in policy_names("evader") if n not in EVADER_POLICIES)
"""Evaders the exact solvers give (grids only)."""

EVADER_TABLES = policy_names("evader", "tabled")
"""Evaders ``oracle`` reads as exact tables by name."""


def is_named(spec: str, side: Side) -> bool:
    """Whether ``spec`` names one of ``side``'s policies (else it is a run directory)."""
    return spec in policy_names(side)


def no_table(spec: str, side: Side) -> str:
    """Why ``oracle`` cannot read the named policy ``spec`` as a table (``""``: it can, or
    ``spec`` is no name)."""
    return next((p.no_table for p in NAMED_POLICIES if p.name == spec and p.side == side), "")


def oracle_evader(scenario: Scenario) -> str:
    """The evader the ``oracle`` team is optimal against: the scenario's scripted evader,
    or the random one where the scenario's evader is learned."""
    return "random" if scenario.evader not in SCRIPTED_EVADERS else scenario.evader
