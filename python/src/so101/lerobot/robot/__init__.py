"""LeRobot robot type `so101_ros`: a LeRobot `Robot` over the stack's topic contract.

Observation: /joint_states (in LeRobot's SO-101 units, as the converter writes them) and the
configured camera topics (sensor_msgs/Image, or the CompressedImage JPEG frames of so101_camera_node
and the sim's --jpeg); action: sensor_msgs/JointState by name on
/joint_commands. Works against so101_sim_node and so101_feetech_driver alike (same topics);
calibration belongs to the driver node, so the robot is always calibrated.

Imported by every LeRobot CLI through the plugin distribution lerobot_robot_so101_ros: rclpy is
imported only in `connect()`.

Layout: config.py (SO101ROSConfig, registered as "so101_ros"), actions.py (the pure action logic),
robot.py (SO101ROS). LeRobot's make_robot_from_config finds SO101ROS in this package (the parent
of the config's module).
"""

from .actions import command_from_action
from .config import RosCameraConfig, SO101ROSConfig
from .robot import SO101ROS

__all__ = ["SO101ROS", "RosCameraConfig", "SO101ROSConfig", "command_from_action"]
