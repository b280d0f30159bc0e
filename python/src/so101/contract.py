"""The topic contract's facts, generated from the Rust crate so101_core (contract.rs,
robot.rs) by `so101_contract --python`: do not edit; a test fails when they differ."""

JOINT_NAMES = ("shoulder_pan", "shoulder_lift", "elbow_flex", "wrist_flex", "wrist_roll", "gripper")
# (min, max) in rad, in JOINT_NAMES order.
JOINT_LIMITS = (
    (-1.9199, 1.9199),
    (-1.7453, 1.7453),
    (-1.69, 1.69),
    (-1.6581, 1.6581),
    (-2.7438, 2.8412),
    (-0.1745, 1.7453),
)
CAMERA_NAMES = ("top", "front", "wrist")

# Topics, services and actions, relative to the namespace.
JOINT_STATES = "joint_states"
JOINT_COMMANDS = "joint_commands"
FORWARD_POSITION_COMMANDS = "forward_position_controller/commands"
LEADER_JOINT_STATES = "leader/joint_states"
TASK_REWARD = "task/reward"
TASK_SUCCESS = "task/success"
CUBE_POSE = "cube/pose"
EPISODE_EVENTS = "episode/events"
DIAGNOSTICS = "diagnostics"
CLOCK = "clock"
CAMERA_PREFIX = "camera"
IMAGE_RAW = "image_raw"
IMAGE_COMPRESSED = "image_raw/compressed"
CAMERA_INFO = "camera_info"
JOINT_TRAJECTORY = "arm_controller/joint_trajectory"
FOLLOW_JOINT_TRAJECTORY = "arm_controller/follow_joint_trajectory"
SIM_RESET = "sim/reset"
SIM_STEP = "sim/step"
TORQUE_ENABLE = "torque_enable"
RECORDER_START = "recorder/start"
RECORDER_STOP = "recorder/stop"
RECORDER_DISCARD = "recorder/discard"
RECORDER_MARK_SUCCESS = "recorder/mark_success"

# The episode-bag layout (so101_core::episode_bag): directories <prefix>_<index:06>,
# rosbag2's metadata file, the keys of its custom_data.
EPISODE_METADATA_FILE = "metadata.yaml"
EPISODE_DEFAULT_PREFIX = "episode"
CUSTOM_EPISODE_INDEX = "episode_index"
CUSTOM_TASK = "task"
CUSTOM_SUCCESS = "success"
CUSTOM_SEED = "seed"


def camera_topic(name: str, leaf: str = IMAGE_RAW) -> str:
    """`camera/<name>/<leaf>` (leaf: IMAGE_RAW, IMAGE_COMPRESSED, CAMERA_INFO)."""
    return f"{CAMERA_PREFIX}/{name}/{leaf}"
