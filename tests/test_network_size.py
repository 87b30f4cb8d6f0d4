"""The networks' size, counted before anything is built (``config.network_weights``, the
check that refuses runs too large for memory), equals the parameters the teams really
have, sensing scenarios included (A2CM's one critic reads the global state there)."""

from __future__ import annotations

import pytest

from a2cm_phys.config import load_scenario, load_train, network_weights, resolve_train
from a2cm_phys.training.teams import make_teams


@pytest.mark.parametrize(
    ("scenario", "encoding"),
    [
        ("grid", None),
        ("grid_vs", "onehot"),
        ("grid_pomdp", None),
        ("grid_pomdp_share", "onehot"),
        ("phys_cont_pomdp", None),
    ],
)
@pytest.mark.parametrize("algo", ["a2cm", "a2c"])
def test_counted_weights_are_the_built_ones(scenario: str, encoding: str | None, algo: str):
    sc = load_scenario(scenario)
    cfg = resolve_train(
        sc, load_train({"algo": algo, **({"encoding": encoding} if encoding else {})})
    )
    pursuers, evader = make_teams(sc, cfg)
    teams = [pursuers] + ([evader] if evader is not None else [])
    built = sum(p.numel() for team in teams for p in team.model.parameters())
    assert network_weights(sc, cfg) == built
