"""The TorchRL adapter (``a2cm_phys.integrations.torchrl``) and the BenchMARL task over it:
TorchRL's own spec check on every kind of scenario, terminated and truncated kept apart,
the step/reset contract over our auto-resetting games, determinism, and a short BenchMARL
MAPPO run that must learn to catch the evader faster than random pursuers do."""

from __future__ import annotations

import numpy as np
import pytest
import torch

torchrl = pytest.importorskip("torchrl")
benchmarl = pytest.importorskip("benchmarl")

from benchmarl.algorithms import MappoConfig  # noqa: E402
from benchmarl.experiment import Experiment, ExperimentConfig  # noqa: E402
from benchmarl.models.mlp import MlpConfig  # noqa: E402
from torchrl.envs.utils import check_env_specs  # noqa: E402

from a2cm_phys.analysis.evaluation import play  # noqa: E402
from a2cm_phys.config import load_scenario  # noqa: E402
from a2cm_phys.envs.vector import VectorEnv  # noqa: E402
from a2cm_phys.integrations.benchmarl import PursuitTask  # noqa: E402
from a2cm_phys.integrations.torchrl import EVADER, PURSUERS, PursuitEnv, team_policy  # noqa: E402


@pytest.mark.parametrize(
    "name", ["grid_collision", "grid_random", "phys_cont", "grid_pomdp", "grid_vs", "phys_cont_vs"]
)
def test_torchrl_accepts_the_specs(name: str) -> None:
    sc = load_scenario(name)
    env = PursuitEnv(sc, num_envs=3)
    check_env_specs(env, seed=1)
    groups = set(env.group_map)
    assert groups == ({PURSUERS, EVADER} if sc.evader == "learned" else {PURSUERS})
    td = env.rollout(20, break_when_any_done=False)
    assert td["next", PURSUERS, "reward"].shape == (3, 20, sc.pursuers, 1)
    env.close()


def test_terminated_and_truncated_stay_apart_and_the_last_observation_is_the_episodes() -> None:
    sc = load_scenario("grid", {"max_steps": 4})
    env = PursuitEnv(sc, num_envs=64, seed=5)
    games = VectorEnv(sc, 64)
    obs = games.reset(5)
    td = env.reset()
    rng = np.random.default_rng(0)
    seen_truncated = seen_terminated = False
    for _ in range(12):
        actions = rng.integers(0, sc.actions, size=(64, sc.pursuers))
        td.set((PURSUERS, "action"), torch.from_numpy(actions))
        td, after = env.step_and_maybe_reset(td)  # TorchRL's own step-then-reset
        step = games.step(actions)
        nxt = td["next"]
        terminated, truncated = nxt["terminated"][:, 0].numpy(), nxt["truncated"][:, 0].numpy()
        np.testing.assert_array_equal(terminated, step.terminated)
        np.testing.assert_array_equal(truncated, step.truncated)
        assert not (terminated & truncated).any()
        np.testing.assert_array_equal(nxt["done"][:, 0].numpy(), terminated | truncated)
        assert (nxt[PURSUERS, "truncated"][..., 0].numpy() == truncated[:, None]).all()
        # "next" holds the finished episodes' last observation, not the next one's first
        own = nxt[PURSUERS, "observation"][:, 0, : sc.state_dim].numpy()
        np.testing.assert_array_equal(own, step.final_obs.astype(np.float32))
        # and the reset that follows hands back the episodes the step started
        state = after[PURSUERS, "observation"][:, 0, : sc.state_dim].numpy()
        np.testing.assert_array_equal(state, step.obs.astype(np.float32))
        seen_truncated |= truncated.any()
        seen_terminated |= terminated.any()
        obs, td = step.obs, after
    assert seen_truncated and seen_terminated
    assert obs.shape == (64, sc.state_dim)


def test_a_reset_of_a_running_game_restarts_it_and_leaves_the_others() -> None:
    env = PursuitEnv(load_scenario("grid_random"), num_envs=4, seed=2)
    td = env.reset()
    td.set((PURSUERS, "action"), torch.zeros((4, 3), dtype=torch.int64))
    td = env.step_mdp(env.step(td))
    before = env.games.core.t.copy()
    mask = torch.tensor([[True], [False], [False], [False]])
    after = env.reset(td.empty().set("_reset", mask))
    t = env.games.core.t
    assert t[0] == 0 and (t[1:] == before[1:]).all()
    state = after[PURSUERS, "observation"][0, 0, : env.scenario.state_dim].numpy()
    np.testing.assert_array_equal(state, env.games.observe()[0].astype(np.float32))


def test_the_same_seed_gives_the_same_games() -> None:
    sc = load_scenario("phys_cont_random")
    a, b = (PursuitEnv(sc, num_envs=4, seed=9) for _ in range(2))
    torch.manual_seed(0)
    ra = a.rollout(40, break_when_any_done=False)
    torch.manual_seed(0)
    rb = b.rollout(40, break_when_any_done=False)
    assert (ra == rb).all()
    a.close()
    b.close()


def test_a_short_mappo_run_learns_to_catch_faster_than_random_pursuers(tmp_path) -> None:
    """BenchMARL's MAPPO on our games through the task, 51,200 frames: the greedy team,
    played by our own evaluation, must beat random pursuers by a wide margin (measured:
    3.3 steps against random pursuers' 11.6 on the 5×5 grid; the optimum 2.94)."""
    torch.manual_seed(0)
    sc = load_scenario("grid")
    cfg = ExperimentConfig.get_from_yaml()
    cfg.max_n_frames, cfg.lr, cfg.on_policy_n_minibatch_iters = 51_200, 3e-4, 4
    cfg.on_policy_n_envs_per_worker, cfg.on_policy_collected_frames_per_batch = 64, 6400
    cfg.loggers, cfg.evaluation, cfg.render, cfg.create_json = [], False, False, False
    cfg.save_folder, cfg.checkpoint_at_end = str(tmp_path), False
    exp = Experiment(
        task=PursuitTask(sc, reward_scale=1.0 / abs(sc.rewards.step)),
        algorithm_config=MappoConfig.get_from_yaml(),
        model_config=MlpConfig.get_from_yaml(),
        critic_model_config=MlpConfig.get_from_yaml(),
        seed=0,
        config=cfg,
    )
    exp.run()
    learned = play(sc, team_policy(sc, exp.policy), 500, 16, 1).lengths

    def random_team(obs: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        return rng.integers(0, sc.actions, size=(len(obs), sc.pursuers))

    chance = play(sc, random_team, 500, 16, 1).lengths
    # means over 500 episodes each; standard errors are a few tenths of a step
    assert learned.mean() < 0.75 * chance.mean(), (learned.mean(), chance.mean())
