"""The SO-101 ROS 2 stack's Python side: episode bags (recorder_node, rosbag2 MCAP) to LeRobot
datasets, policies run through rclpy, Gymnasium environments, the launcher, benchmarks.

`import so101` registers the Gymnasium environments of every task in so101.contract.TASKS
(`gym.make("so101/CubeToBin-v0")`, in-process; `backend="ros"` for so101_sim_node in lockstep):
so101.envs. LeRobot's robot and env types live in so101.lerobot.

Rooms, bottom up (docs/architecture.md says what each may import): the shared facts at top level
(contract, units, paths, messages, sim_options, subcommands); dataset (bags -> LeRobot datasets);
stack (the nodes started and stopped, replay); envs; evaluate (policies and their evaluation);
lerobot; learn, sysid, bench and tools (the commands built on them)."""

from .envs import register_envs

register_envs()
