"""Policy type `pose_act`: LeRobot's ACT on the joints and the cube's pose, the pose read from the
cameras by a small convolutional estimator trained beside it (configuration_pose_act says why).
Importing this package registers the type with LeRobot (lerobot-train --policy.type=pose_act);
lerobot_policy_so101_pose_act (python/plugins) imports it for LeRobot's own CLIs."""

from .configuration_pose_act import PoseACTConfig

__all__ = ["PoseACTConfig"]
