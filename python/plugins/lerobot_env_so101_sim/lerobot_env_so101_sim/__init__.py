"""LeRobot plugin entry (imported by lerobot.utils.import_utils.register_third_party_plugins):
registers env type `so101_sim`, whose code is so101.lerobot.env."""

from so101.lerobot.env import So101SimEnvConfig

__all__ = ["So101SimEnvConfig"]
