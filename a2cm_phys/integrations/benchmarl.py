"""BenchMARL over our scenarios: :class:`PursuitTask`, a BenchMARL task whose environment
is :class:`~a2cm_phys.integrations.torchrl.PursuitEnv` (our batched games), so that
BenchMARL's algorithms (MAPPO, IPPO, QMIX, MADDPG, …) train on any scenario unchanged.

The task is a :class:`benchmarl.environments.TaskClass` built from the scenario itself, not
from a file in BenchMARL's ``conf/task`` folder (BenchMARL is used, not forked): the
observation, action and state specs are the environment's, without the batch dimension,
and an evaluation rollout lasts the scenario's ``max_steps``. A scenario's control type
decides its actions (BenchMARL's ``prefer_continuous_actions`` cannot change it).
"""

from __future__ import annotations

from collections.abc import Callable

from benchmarl.environments import TaskClass
from torchrl.data import Composite
from torchrl.envs import EnvBase, RewardScaling, Transform

from ..config import Scenario, to_dict
from .torchrl import STATE, PursuitEnv


class PursuitTask(TaskClass):
    """A BenchMARL task for one ``scenario``; its ``config`` is the scenario as plain data
    (BenchMARL stores it with the experiment). ``reward_scale`` multiplies every group's
    reward on the way to the learner (TorchRL's ``RewardScaling``; 1: as the scenario
    gives them)."""

    def __init__(self, scenario: Scenario, reward_scale: float = 1.0) -> None:
        super().__init__(name=scenario.name, config=to_dict(scenario))
        self.scenario, self.reward_scale = scenario, reward_scale

    def get_env_transforms(self, env: EnvBase) -> list[Transform]:
        """The reward scaling, where there is one."""
        if self.reward_scale == 1.0:
            return []
        keys = [(group, "reward") for group in env.group_map]
        return [RewardScaling(0.0, self.reward_scale, in_keys=keys)]

    def get_env_fun(
        self, num_envs: int, continuous_actions: bool, seed: int | None, device: object
    ) -> Callable[[], EnvBase]:
        """A maker of ``num_envs`` batched games (the control type is the scenario's)."""
        return lambda: PursuitEnv(self.scenario, num_envs=num_envs, seed=seed or 0)

    def supports_continuous_actions(self) -> bool:
        """Whether the scenario's pursuers send commands."""
        return self.scenario.continuous

    def supports_discrete_actions(self) -> bool:
        """Whether the scenario's pursuers choose moves."""
        return not self.scenario.continuous

    def max_steps(self, env: EnvBase) -> int:
        """An episode's step limit."""
        return self.scenario.max_steps

    def has_render(self, env: EnvBase) -> bool:
        """No ``env.render()`` (our pictures come from the log: ``replay``)."""
        return False

    def group_map(self, env: EnvBase) -> dict[str, list[str]]:
        """The pursuers, and the learned evader as a group of its own."""
        return env.group_map

    def observation_spec(self, env: EnvBase) -> Composite:
        """Each group's observations (the global state is :meth:`state_spec`)."""
        spec = env.full_observation_spec_unbatched.clone()
        del spec[STATE]
        return spec

    def state_spec(self, env: EnvBase) -> Composite | None:
        """The global state, for centralised critics."""
        return Composite({STATE: env.full_observation_spec_unbatched[STATE].clone()})

    def info_spec(self, env: EnvBase) -> Composite | None:
        """No per-agent info."""
        return None

    def action_spec(self, env: EnvBase) -> Composite:
        """Each group's actions."""
        return env.full_action_spec_unbatched

    def action_mask_spec(self, env: EnvBase) -> Composite | None:
        """Every action is always allowed."""
        return None

    @staticmethod
    def env_name() -> str:
        """The environment's name in BenchMARL's logs."""
        return "a2cm_phys"
