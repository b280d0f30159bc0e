"""The stack seen by LeRobot's CLIs, each type registered when LeRobot imports its plugin
distribution (python/plugins/, docs/lerobot.md):
  robot/      robot type `so101_ros`: a LeRobot Robot over the topic contract (plugin
              lerobot_robot_so101_ros)
  env.py      env type `so101_sim`: its config, and the Gymnasium ids lerobot_env_so101_sim/<task>
              of every task in so101.contract.TASKS (plugin lerobot_env_so101_sim)
  adapter.py  the Gymnasium env behind those ids: so101.envs in LeRobot's units

Nothing is imported here: each plugin imports only its own module. Inside this package `lerobot`
still names LeRobot itself (imports are absolute), so `from lerobot.envs.configs import ...` works.
"""
