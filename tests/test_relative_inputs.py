"""Relative inputs (``encoding = "relative"``, issue 45): each actor reads the global
observation from its own body, the other bodies' positions as offsets from its own, and
everything else as it is; with ``encoding = "metric"`` the offsets in metres (cells on a
grid), and such a team plays its trained arena size only; torch and numpy agree; the
options that cannot have it are refused naming the key."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from a2cm_phys.algos.build import make_model
from a2cm_phys.algos.encoding import RelativePositions
from a2cm_phys.analysis.policies import check_layout, positions_from_obs
from a2cm_phys.config import ConfigError, load_scenario, load_train, resolve_train
from a2cm_phys.envs.vector import VectorEnv


def _observations(name: str, n: int = 64) -> np.ndarray:
    env = VectorEnv(load_scenario(name), n)
    obs = env.reset(3)
    env.close()
    return obs


@pytest.mark.parametrize("name", ["phys_cont_random", "grid_random", "phys_diff"])
def test_each_actor_sees_the_others_as_offsets_from_itself(name: str) -> None:
    sc = load_scenario(name)
    obs = _observations(name)
    bodies = sc.pursuers + 1
    rows = RelativePositions(bodies, sc.state_dim, 0, sc.pursuers).numpy(obs)
    assert rows.shape == (len(obs), sc.pursuers, sc.state_dim)
    xy = obs[:, : 2 * bodies].reshape(len(obs), bodies, 2)
    for i in range(sc.pursuers):
        seen = rows[:, i, : 2 * bodies].reshape(len(obs), bodies, 2)
        np.testing.assert_allclose(seen[:, i], xy[:, i])  # its own position, as it is
        others = [j for j in range(bodies) if j != i]
        np.testing.assert_allclose(seen[:, others], xy[:, others] - xy[:, [i]], atol=1e-7)
        np.testing.assert_array_equal(rows[:, i, 2 * bodies :], obs[:, 2 * bodies :])
    assert np.abs(rows[:, 0, 2:4] - obs[:, None, 2:4]).max() > 0.05  # not the raw input


def test_a_learned_evaders_view_is_from_its_own_body_and_torch_agrees() -> None:
    sc = load_scenario("grid_vs")
    obs = _observations("grid_vs")
    n = sc.pursuers
    view = RelativePositions(n + 1, sc.state_dim, n, 1)
    rows = view.numpy(obs)[:, 0]
    np.testing.assert_allclose(rows[:, 2 * n :], obs[:, 2 * n :])
    np.testing.assert_allclose(rows[:, :2], obs[:, :2] - obs[:, 2 * n :], atol=1e-7)
    np.testing.assert_allclose(view.torch(torch.from_numpy(obs)).numpy()[:, 0], rows, atol=1e-7)


@pytest.mark.parametrize(("name", "algo"), [("phys_cont_random", "a2cm"), ("grid_vs", "a2c")])
def test_a_relative_team_acts_as_its_networks_say(name: str, algo: str) -> None:
    """The rollout's numpy actors and the learner's torch actors read the same views, and
    moving every body by the same vector moves only what each actor sees of itself."""
    sc = load_scenario(name)
    cfg = resolve_train(sc, load_train({"algo": algo, "encoding": "relative", "seed": 2}))
    model = make_model(cfg, sc)
    obs = _observations(name, 32)
    with torch.no_grad():
        torch_out = model.actor_outputs(torch.from_numpy(obs)).numpy()
    np.testing.assert_allclose(model.outputs_np(obs), torch_out, atol=1e-5)
    shifted = obs.copy()
    shifted[:, : 2 * (sc.pursuers + 1)] += np.tile([0.1, -0.05], sc.pursuers + 1)
    moved = model.relative.numpy(shifted) - model.relative.numpy(obs)
    for i in range(sc.pursuers):
        expect = np.zeros(sc.state_dim, dtype=np.float32)
        expect[2 * i : 2 * i + 2] = [0.1, -0.05]
        np.testing.assert_allclose(
            moved[:, i], np.broadcast_to(expect, moved[:, i].shape), atol=1e-6
        )
    assert model.critic_hidden.weight.shape[-1] == sc.state_dim  # critics read it as it is


@pytest.mark.parametrize("name", ["phys_cont10_random", "phys_cont_random", "grid10_random"])
def test_metric_offsets_are_metres_or_cells_on_every_arena(name: str) -> None:
    """A metric team's actors see each other body's offset in metres (cells), what the
    arena's positions say, on 5 × 5 and 10 × 10 alike; the rest as a relative team sees it."""
    sc = load_scenario(name)
    obs = _observations(name)
    cfg = resolve_train(sc, load_train({"encoding": "metric", "seed": 1}))
    model = make_model(cfg, sc)
    assert model.arena_bound and model.relative.scale == sc.position_unit
    rows = model.relative.numpy(obs)
    plain = RelativePositions(sc.pursuers + 1, sc.state_dim, 0, sc.pursuers).numpy(obs)
    pos = positions_from_obs(sc, obs)  # metres, or integer cells
    bodies = sc.pursuers + 1
    for i in range(sc.pursuers):
        seen = rows[:, i, : 2 * bodies].reshape(len(obs), bodies, 2)
        others = [j for j in range(bodies) if j != i]
        np.testing.assert_allclose(seen[:, others], pos[:, others] - pos[:, [i]], atol=1e-5)
        np.testing.assert_array_equal(seen[:, i], plain[:, i, 2 * i : 2 * i + 2])
        np.testing.assert_array_equal(rows[:, i, 2 * bodies :], obs[:, 2 * bodies :])
    with torch.no_grad():
        torch_out = model.actor_outputs(torch.from_numpy(obs)).numpy()
    np.testing.assert_allclose(model.outputs_np(obs), torch_out, atol=1e-5)


def test_a_metric_team_plays_its_own_arena_size_only() -> None:
    """Its offsets are scaled by the trained arena: another size is refused naming the key,
    where a relative team (offsets as fractions of the arena) may play it."""
    small, large = load_scenario("phys_cont_random"), load_scenario("phys_cont10_random")
    for encoding, bound in (("metric", True), ("relative", False)):
        model = make_model(resolve_train(small, load_train({"encoding": encoding})), small)
        assert model.arena_bound is bound
        if bound:
            with pytest.raises(ConfigError, match="trained with size = 5"):
                check_layout(small, large, "RUN", model)
        else:
            check_layout(small, large, "RUN", model)
        check_layout(small, load_scenario("phys_cont"), "RUN", model)  # the same size


@pytest.mark.parametrize("encoding", ["relative", "metric"])
@pytest.mark.parametrize(
    ("name", "values", "what"),
    [("grid_pomdp", {}, "sensing"), ("grid_random", {"recurrent": "gru"}, "recurrent = 'gru'")],
)
def test_relative_inputs_are_refused_where_they_cannot_be_made(
    name, values, what, encoding
) -> None:
    sc = load_scenario(name)
    with pytest.raises(ConfigError, match=f"key 'encoding': {encoding} inputs.*{what}"):
        resolve_train(sc, load_train({"encoding": encoding, **values}))


def test_a_view_from_a_body_that_is_not_there_is_refused() -> None:
    with pytest.raises(ValueError, match="actors 3…4 need them among 4 bodies"):
        RelativePositions(4, 16, 3, 2)
