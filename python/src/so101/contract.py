"""The topic contract's facts, generated from the Rust crate so101_core (contract.rs,
robot.rs, task.rs, servo/params.rs) by `so101_contract --python`: do not edit; a test fails when they differ."""

from typing import NamedTuple

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
# An end-effector action or state (so101_core::ee_action): the grasp point in the base
# frame (m), the approach pitch and the jaws' roll (rad), the gripper's joint (rad).
EE_NAMES = ("x", "y", "z", "pitch", "roll", "gripper")
CAMERA_NAMES = ("top", "front", "wrist")
CAMERAS_ON_THE_ARM = ("wrist",)
# The arm's base body: its frame is the base frame cameras are placed in.
BASE_LINK = "base"
# The STS3215's magnetic encoder: ticks per revolution.
ENCODER_TICKS_PER_REVOLUTION = 4096
# The servo models known by name (anything else is a so101-sysid parameter file), and the
# one the simulation uses unless told (so101_core::servo).
SERVO_MODELS = ("sts3215", "gain80")
DEFAULT_SERVO_MODEL = "sts3215"

# The control rate of a policy and of teleoperated demonstrations: one action and one
# observation per period, a dataset's fps, every task's default (Hz).
CONTROL_RATE = 30.0


class Task(NamedTuple):
    """A task's facts (so101_core::task::TaskFacts)."""

    name: str
    gym_id: str  # the in-process Gymnasium environment
    description: str  # the task text of a LeRobot dataset's episodes
    episode_steps: int  # at control_rate
    terminates_on_success: bool
    reward_modes: tuple[str, ...]  # the first is the default
    control_rate: float


# Every task the simulation core knows, by name, in the order command lines list them.
TASKS = {
    "cube_to_bin": Task(
        name="cube_to_bin",
        gym_id="so101/CubeToBin-v0",
        description="put the cube in the bin",
        episode_steps=600,
        terminates_on_success=True,
        reward_modes=("sparse", "dense"),
        control_rate=30.0,
    ),
    "lift_cube": Task(
        name="lift_cube",
        gym_id="so101/LiftCube-v0",
        description="lift the cube",
        episode_steps=300,
        terminates_on_success=True,
        reward_modes=("sparse", "dense"),
        control_rate=30.0,
    ),
    "place_cube": Task(
        name="place_cube",
        gym_id="so101/PlaceCube-v0",
        description="place the cube on the pad",
        episode_steps=600,
        terminates_on_success=True,
        reward_modes=("sparse", "dense"),
        control_rate=30.0,
    ),
    "push_cube": Task(
        name="push_cube",
        gym_id="so101/PushCube-v0",
        description="push the cube onto the target",
        episode_steps=600,
        terminates_on_success=True,
        reward_modes=("sparse", "dense"),
        control_rate=30.0,
    ),
    "stack_cube": Task(
        name="stack_cube",
        gym_id="so101/StackCube-v0",
        description="stack the red cube on the green cube",
        episode_steps=600,
        terminates_on_success=True,
        reward_modes=("sparse", "dense"),
        control_rate=30.0,
    ),
    "touch_cube": Task(
        name="touch_cube",
        gym_id="so101/TouchCube-v0",
        description="touch the cube",
        episode_steps=300,
        terminates_on_success=False,
        reward_modes=("dense",),
        control_rate=30.0,
    ),
    "touch_cube_sparse": Task(
        name="touch_cube_sparse",
        gym_id="so101/TouchCubeSparse-v0",
        description="touch the cube",
        episode_steps=300,
        terminates_on_success=False,
        reward_modes=("sparse",),
        control_rate=30.0,
    ),
}

# Topics, services and actions, relative to the namespace.
JOINT_STATES = "joint_states"
JOINT_COMMANDS = "joint_commands"
FORWARD_POSITION_COMMANDS = "forward_position_controller/commands"
LEADER_JOINT_STATES = "leader/joint_states"
TASK_REWARD = "task/reward"
TASK_SUCCESS = "task/success"
CUBE_POSE = "cube/pose"
EPISODE_EVENTS = "episode/events"
SIM_EPISODE = "sim/episode"
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
RECORDER_DISCARD_LAST = "recorder/discard_last"
RECORDER_MARK_SUCCESS = "recorder/mark_success"
RECORDER_READY = "recorder/ready"

# The episode-bag layout (so101_core::episode_bag): directories <prefix>_<index:06>,
# rosbag2's metadata file, the keys of its custom_data.
EPISODE_METADATA_FILE = "metadata.yaml"
EPISODE_DEFAULT_PREFIX = "episode"
CUSTOM_EPISODE_INDEX = "episode_index"
CUSTOM_TASK = "task"
CUSTOM_SUCCESS = "success"
CUSTOM_SEED = "seed"
CUSTOM_SIMULATION = "simulation"


def camera_topic(name: str, leaf: str = IMAGE_RAW) -> str:
    """`camera/<name>/<leaf>` (leaf: IMAGE_RAW, IMAGE_COMPRESSED, CAMERA_INFO)."""
    return f"{CAMERA_PREFIX}/{name}/{leaf}"
