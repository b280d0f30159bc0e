"""The Gymnasium ids of the SO-101 tasks, one per task of the generated contract
(contract.TASKS[task].gym_id: `so101/CubeToBin-v0`, `so101/TouchCube-v0`, ...), with the task's
episode length as max_episode_steps; registered by `import so101`.

`gym.make(id)` runs in-process (so101.envs.inprocess); `gym.make(id, backend="ros")` runs the same
task on so101_sim_node in lockstep over ROS (so101.envs.ros). `gym.make_vec(id, num_envs=N)`
steps N in-process worlds in one native call (So101VectorEnv).
"""

from __future__ import annotations

import gymnasium as gym
from gymnasium.vector import VectorEnv

from .. import contract
from .inprocess import So101InProcessEnv, So101VectorEnv
from .ros import So101RosEnv

BACKENDS = ("inprocess", "ros")


def make_env(task: str = "cube_to_bin", backend: str = "inprocess", **kwargs) -> gym.Env:
    """The env of `task` on `backend` ("inprocess" or "ros")."""
    if backend == "inprocess":
        return So101InProcessEnv(task=task, **kwargs)
    if backend == "ros":
        return So101RosEnv(task=task, **kwargs)
    raise ValueError(f"backend {backend!r}: one of {', '.join(BACKENDS)}")


def make_vector_env(num_envs: int, task: str = "cube_to_bin", backend: str = "inprocess", **kwargs) -> VectorEnv:
    """make_vec's entry point: the native batch in-process; one ROS env per world otherwise."""
    if backend == "inprocess":
        return So101VectorEnv(num_envs, task=task, **kwargs)
    steps = kwargs.pop("max_episode_steps", None)
    return gym.vector.SyncVectorEnv(
        [lambda: gym.wrappers.TimeLimit(make_env(task, backend, **kwargs), steps) if steps else make_env(task, backend, **kwargs)]
        * num_envs
    )


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
