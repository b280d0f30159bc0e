"""LeRobot plugin entry (imported by lerobot.utils.import_utils.register_third_party_plugins):
registers policy type `pose_act`, whose code is so101.policies.pose_act."""

from so101.policies.pose_act import PoseACTConfig

__all__ = ["PoseACTConfig"]
