"""LeRobot plugin entry (imported by lerobot.utils.import_utils.register_third_party_plugins):
registers robot type `so101_ros`, whose code is so101.lerobot.robot."""

from so101.lerobot.robot import SO101ROS, SO101ROSConfig

__all__ = ["SO101ROS", "SO101ROSConfig"]
