"""The Gymnasium ids of the SO-101 tasks, one per task of the generated contract
(contract.TASKS[task].gym_id: `so101/CubeToBin-v0`, `so101/TouchCube-v0`, ...), with the task's
episode length as max_episode_steps; registered by `import so101`.

`gym.make(id)` runs in-process (so101.envs.inprocess); `gym.make(id, backend="ros")` runs the same
task on so101_sim_node in lockstep over ROS (so101.envs.ros); `action_space="ee"` on either acts on
end-effector targets (so101.envs.ee). `gym.make_vec(id, num_envs=N)`
steps N in-process worlds in one native call (So101VectorEnv).
"""

from __future__ import annotations

import gymnasium as gym
from gymnasium.vector import VectorEnv

from .. import contract
from ..ee import checked_action_space
from .ee import EeActionEnv, EeActionVectorEnv
from .inprocess import So101InProcessEnv, So101VectorEnv
from .ros import So101RosEnv

BACKENDS = ("inprocess", "ros")


def make_env(task: str = "cube_to_bin", backend: str = "inprocess", action_space: str = "joint", **kwargs) -> gym.Env:
    """The env of `task` on `backend` ("inprocess" or "ros"), acting on joint targets or, with
    action_space="ee", on end-effector targets (so101.envs.ee)."""
    checked_action_space(action_space)
    if backend == "inprocess":
        env = So101InProcessEnv(task=task, **kwargs)
    elif backend == "ros":
        env = So101RosEnv(task=task, **kwargs)
    else:
        raise ValueError(f"backend {backend!r}: one of {', '.join(BACKENDS)}")
    return EeActionEnv(env) if action_space == "ee" else env


def make_vector_env(
    num_envs: int, task: str = "cube_to_bin", backend: str = "inprocess", action_space: str = "joint", **kwargs
) -> VectorEnv:
    """make_vec's entry point: the native batch in-process; one ROS env per world otherwise."""
    checked_action_space(action_space)
    if backend == "inprocess":
        env = So101VectorEnv(num_envs, task=task, **kwargs)
        return EeActionVectorEnv(env) if action_space == "ee" else env
    steps = kwargs.pop("max_episode_steps", None)

    def one():
        env = make_env(task, backend, action_space, **kwargs)
        return gym.wrappers.TimeLimit(env, steps) if steps else env

    return gym.vector.SyncVectorEnv([one] * num_envs)


def register_envs() -> None:
    """Registers every task's environment (`import so101` does)."""
    for task in contract.TASKS.values():
        if task.gym_id not in gym.registry:
            gym.register(
                task.gym_id,
                entry_point="so101.envs.registry:make_env",
                vector_entry_point="so101.envs.registry:make_vector_env",
                kwargs={"task": task.name},
                max_episode_steps=task.episode_steps,
            )
