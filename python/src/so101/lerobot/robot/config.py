"""The configuration of robot type `so101_ros` (registered with LeRobot's RobotConfig here)."""

from __future__ import annotations

from dataclasses import dataclass, field

from lerobot.robots import RobotConfig

from ... import contract
from ...ee import ACTION_SPACES


@dataclass
class RosCameraConfig:
    """One camera topic. width/height/fps are declared so the features are known before connect
    (LeRobot builds the dataset first); frames of another size are refused at connect. With
    `compressed` (or a topic ending in /compressed), sensor_msgs/CompressedImage (JPEG or PNG, what
    so101_camera_node and the sim's --jpeg publish) instead of sensor_msgs/Image."""

    topic: str = ""  # default: camera/<name>/image_raw (/compressed) under the namespace
    compressed: bool = False
    width: int = 640
    height: int = 480
    fps: int = int(contract.CONTROL_RATE)  # the cameras publish at the control rate by default


@RobotConfig.register_subclass("so101_ros")
@dataclass
class SO101ROSConfig(RobotConfig):
    # ROS namespace of the stack (e.g. "replay"); relative topic names resolve under it.
    namespace: str = ""
    joint_states_topic: str = contract.JOINT_STATES
    joint_commands_topic: str = contract.JOINT_COMMANDS
    # {name: RosCameraConfig}; on the CLI: '{top: {width: 64, height: 48, fps: 30}}', and for a
    # camera's JPEG frames '{top: {compressed: true}}'.
    cameras: dict[str, RosCameraConfig] = field(default_factory=dict)
    # How long connect() waits for the first /joint_states (and a first frame per camera).
    connect_timeout_s: float = 10.0
    # LeRobot's max_relative_target: the largest step (LeRobot units) from the present position
    # one action may ask of a joint; None: no limit.
    max_relative_target: float | None = None
    # What actions are: "joint" ("<joint>.pos", LeRobot units) or "ee" ("ee.x" ... "ee.gripper": the
    # gripper's target pose in the arm's base frame, m and rad, gripper 0-100; so101.ee), turned
    # into joint targets by the core's IK, then max_relative_target and the limits as for joints.
    action_space: str = "joint"
    # Name of the rclpy node.
    node_name: str = "so101_lerobot_robot"

    def __post_init__(self):
        if self.action_space not in ACTION_SPACES:
            raise ValueError(f"so101_ros: action_space {self.action_space!r}, not one of {', '.join(ACTION_SPACES)}")
        for name, camera in self.cameras.items():
            if not camera.topic:
                leaf = contract.IMAGE_COMPRESSED if camera.compressed else contract.IMAGE_RAW
                camera.topic = contract.camera_topic(name, leaf)
            camera.compressed = camera.compressed or camera.topic.endswith("/compressed")
        super().__post_init__()
