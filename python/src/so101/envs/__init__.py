"""The Gymnasium environments of the SO-101 tasks, one id per task of the generated contract
(`so101/CubeToBin-v0`, `so101/TouchCube-v0`, `so101/TouchCubeSparse-v0`), registered by
`import so101`; in-process by default, `backend="ros"` for so101_sim_node in lockstep.

Layout (each module imports only those before it):
  spaces.py     what both backends share: spaces, observation_from_state, checked_action, STATE,
                task_facts (the contract's Task of a task name)
  inprocess.py  the simulation core through so101_native: So101InProcessEnv, So101VectorEnv
  ros.py        so101_sim_node in lockstep over rclpy: So101RosEnv (rclpy imported when built)
  ee.py         action_space="ee" on either: EeActionEnv, EeActionVectorEnv (the core's IK)
  registry.py   make_env, make_vector_env (the entry points of the ids), register_envs
"""

from .ee import EeActionEnv, EeActionVectorEnv
from .inprocess import So101InProcessEnv, So101VectorEnv, default_scene
from .registry import BACKENDS, make_env, make_vector_env, register_envs
from .ros import So101RosEnv
from .spaces import STATE, action_space, checked_action, observation_from_state, observation_space, task_facts

__all__ = [
    "BACKENDS",
    "EeActionEnv",
    "EeActionVectorEnv",
    "STATE",
    "So101InProcessEnv",
    "So101RosEnv",
    "So101VectorEnv",
    "action_space",
    "checked_action",
    "default_scene",
    "make_env",
    "make_vector_env",
    "observation_from_state",
    "observation_space",
    "register_envs",
    "task_facts",
]
