//! The topic contract's names, relative to a node's namespace (`Names::resolve` makes them
//! absolute), and the Python module generated from them, [`crate::robot`], [`crate::task`] and
//! [`crate::episode_bag`]: the facts the
//! Rust nodes and the Python package share live here once. `so101_contract --python` writes
//! python/src/so101/contract.py; a test fails when the committed file differs.

use crate::episode_bag;
use crate::robot::{JOINT_LIMITS, JOINT_NAMES};
use crate::task::{TaskKind, CONTROL_RATE_HZ};

/// Topics, relative to the namespace.
pub mod topics {
    /// sensor_msgs/JointState, published by the sim and the driver.
    pub const JOINT_STATES: &str = "joint_states";
    /// sensor_msgs/JointState, positions by name (partial sets allowed): what the arm obeys.
    pub const JOINT_COMMANDS: &str = "joint_commands";
    /// std_msgs/Float64MultiArray, six positions in joint order (ros2_control's forward controller).
    pub const FORWARD_POSITION_COMMANDS: &str = "forward_position_controller/commands";
    /// sensor_msgs/JointState of a leader arm (the driver in leader mode).
    pub const LEADER_JOINT_STATES: &str = "leader/joint_states";
    /// std_msgs/Float64, the task's reward (sim).
    pub const TASK_REWARD: &str = "task/reward";
    /// std_msgs/Bool, whether the task is solved (sim).
    pub const TASK_SUCCESS: &str = "task/success";
    /// geometry_msgs/PoseStamped, the cube in the world frame (sim).
    pub const CUBE_POSE: &str = "cube/pose";
    /// std_msgs/String, episode events (start, stop, success) from teleop to the recorder.
    pub const EPISODE_EVENTS: &str = "episode/events";
    /// std_msgs/String, latched: JSON of what the sim simulates the current episode with (servo
    /// model and parameters, randomization ranges and the episode's draw), after every reset.
    pub const SIM_EPISODE: &str = "sim/episode";
    /// diagnostic_msgs/DiagnosticArray.
    pub const DIAGNOSTICS: &str = "diagnostics";
    /// rosgraph_msgs/Clock (sim time).
    pub const CLOCK: &str = "clock";
    /// Prefix of the camera topics: `camera/<name>/image_raw`, `camera/<name>/camera_info`.
    pub const CAMERA_PREFIX: &str = "camera";
    /// sensor_msgs/Image (rgb8) of a camera, under `camera/<name>/`.
    pub const IMAGE_RAW: &str = "image_raw";
    /// sensor_msgs/CompressedImage (JPEG) of a camera, under `camera/<name>/`.
    pub const IMAGE_COMPRESSED: &str = "image_raw/compressed";
    /// sensor_msgs/CameraInfo of a camera, under `camera/<name>/`.
    pub const CAMERA_INFO: &str = "camera_info";

    /// trajectory_msgs/JointTrajectory for the arm, where ros2_control's joint_trajectory_controller
    /// named `arm_controller` listens.
    pub const JOINT_TRAJECTORY: &str = "arm_controller/joint_trajectory";

    /// `camera/<name>/<leaf>` (leaf: [`IMAGE_RAW`], [`IMAGE_COMPRESSED`], [`CAMERA_INFO`]).
    pub fn camera(name: &str, leaf: &str) -> String {
        format!("{CAMERA_PREFIX}/{name}/{leaf}")
    }

    /// The `format` of a JPEG on [`IMAGE_COMPRESSED`], as image_transport's compressed
    /// publisher writes it.
    pub const JPEG_FORMAT: &str = "rgb8; jpeg compressed bgr8";

    /// The TF frame of a camera's images: its optical frame (x right, y down, z forward).
    pub fn camera_optical_frame(name: &str) -> String {
        format!("{name}_camera_optical_frame")
    }
}

/// Services, relative to the namespace.
pub mod services {
    /// std_srvs/Trigger: a new episode (sim).
    pub const SIM_RESET: &str = "sim/reset";
    /// std_srvs/Trigger: one control period in lockstep mode (sim).
    pub const SIM_STEP: &str = "sim/step";
    /// std_srvs/SetBool: torque on or off (driver).
    pub const TORQUE_ENABLE: &str = "torque_enable";
    /// std_srvs/Trigger: the recorder's episode control.
    pub const RECORDER_START: &str = "recorder/start";
    pub const RECORDER_STOP: &str = "recorder/stop";
    pub const RECORDER_DISCARD: &str = "recorder/discard";
    /// Between episodes: deletes the one closed last (re-recording it).
    pub const RECORDER_DISCARD_LAST: &str = "recorder/discard_last";
    /// std_srvs/SetBool: marks the current (or last) episode a success or not.
    pub const RECORDER_MARK_SUCCESS: &str = "recorder/mark_success";
    /// std_srvs/Trigger: whether the recorder receives every publisher of the topics it records
    /// (false: the message names the topics still being matched).
    pub const RECORDER_READY: &str = "recorder/ready";
}

/// Actions, relative to the namespace.
pub mod actions {
    /// control_msgs/action/FollowJointTrajectory, as joint_trajectory_controller serves it (what
    /// MoveIt's controller manager sends).
    pub const FOLLOW_JOINT_TRAJECTORY: &str = "arm_controller/follow_joint_trajectory";
}

/// The cameras of the simulated scene, in the order the sim starts them.
pub const CAMERA_NAMES: [&str; 3] = ["top", "front", "wrist"];

/// The cameras that ride the arm: they move with it, so no board on the table places them.
pub const CAMERAS_ON_THE_ARM: [&str; 1] = ["wrist"];

/// The Python module `so101.contract` with the same facts (the text of python/src/so101/contract.py).
pub fn python_module() -> String {
    let mut out = String::from(
        "\"\"\"The topic contract's facts, generated from the Rust crate so101_core (contract.rs,\n\
         robot.rs, task.rs, servo/params.rs) by `so101_contract --python`: do not edit; a test fails when they differ.\"\"\"\n\n\
         from typing import NamedTuple\n\n",
    );
    let quoted = |names: &[&str]| {
        names
            .iter()
            .map(|name| format!("\"{name}\""))
            .collect::<Vec<_>>()
            .join(", ")
    };
    out += &format!("JOINT_NAMES = ({})\n", quoted(&JOINT_NAMES));
    out += "# (min, max) in rad, in JOINT_NAMES order.\nJOINT_LIMITS = (\n";
    for limit in JOINT_LIMITS {
        out += &format!("    ({:?}, {:?}),\n", limit.min, limit.max);
    }
    out += ")\n";
    out += &format!(
        "# An end-effector action or state (so101_core::ee_action): the grasp point in the base\n\
         # frame (m), the approach pitch and the jaws' roll (rad), the gripper's joint (rad).\n\
         EE_NAMES = ({})\n",
        quoted(&crate::ee_action::EE_NAMES)
    );
    out += &format!("CAMERA_NAMES = ({})\n", quoted(&CAMERA_NAMES));
    out += &format!("CAMERAS_ON_THE_ARM = ({},)\n", quoted(&CAMERAS_ON_THE_ARM));
    out += &format!(
        "# The arm's base body: its frame is the base frame cameras are placed in.\nBASE_LINK = \"{}\"\n",
        crate::kinematics::BASE_LINK
    );
    out += &format!(
        "# The STS3215's magnetic encoder: ticks per revolution.\nENCODER_TICKS_PER_REVOLUTION = {}\n",
        crate::servo::TICKS_PER_REVOLUTION
    );
    out += &format!(
        "# The servo models known by name (anything else is a so101-sysid parameter file), and the\n\
         # one the simulation uses unless told (so101_core::servo).\n\
         SERVO_MODELS = ({})\n\
         DEFAULT_SERVO_MODEL = \"{}\"\n\n",
        quoted(&crate::servo::SERVO_MODELS),
        crate::servo::DEFAULT_SERVO_MODEL
    );
    out += &tasks_python();
    out += "# Topics, services and actions, relative to the namespace.\n";
    let constants: &[(&str, &str)] = &[
        ("JOINT_STATES", topics::JOINT_STATES),
        ("JOINT_COMMANDS", topics::JOINT_COMMANDS),
        (
            "FORWARD_POSITION_COMMANDS",
            topics::FORWARD_POSITION_COMMANDS,
        ),
        ("LEADER_JOINT_STATES", topics::LEADER_JOINT_STATES),
        ("TASK_REWARD", topics::TASK_REWARD),
        ("TASK_SUCCESS", topics::TASK_SUCCESS),
        ("CUBE_POSE", topics::CUBE_POSE),
        ("EPISODE_EVENTS", topics::EPISODE_EVENTS),
        ("SIM_EPISODE", topics::SIM_EPISODE),
        ("DIAGNOSTICS", topics::DIAGNOSTICS),
        ("CLOCK", topics::CLOCK),
        ("CAMERA_PREFIX", topics::CAMERA_PREFIX),
        ("IMAGE_RAW", topics::IMAGE_RAW),
        ("IMAGE_COMPRESSED", topics::IMAGE_COMPRESSED),
        ("CAMERA_INFO", topics::CAMERA_INFO),
        ("JOINT_TRAJECTORY", topics::JOINT_TRAJECTORY),
        ("FOLLOW_JOINT_TRAJECTORY", actions::FOLLOW_JOINT_TRAJECTORY),
        ("SIM_RESET", services::SIM_RESET),
        ("SIM_STEP", services::SIM_STEP),
        ("TORQUE_ENABLE", services::TORQUE_ENABLE),
        ("RECORDER_START", services::RECORDER_START),
        ("RECORDER_STOP", services::RECORDER_STOP),
        ("RECORDER_DISCARD", services::RECORDER_DISCARD),
        ("RECORDER_DISCARD_LAST", services::RECORDER_DISCARD_LAST),
        ("RECORDER_MARK_SUCCESS", services::RECORDER_MARK_SUCCESS),
        ("RECORDER_READY", services::RECORDER_READY),
    ];
    for (name, value) in constants {
        out += &format!("{name} = \"{value}\"\n");
    }
    out +=
        "\n# The episode-bag layout (so101_core::episode_bag): directories <prefix>_<index:06>,\n\
            # rosbag2's metadata file, the keys of its custom_data.\n";
    let layout: &[(&str, &str)] = &[
        ("EPISODE_METADATA_FILE", episode_bag::METADATA_FILE),
        ("EPISODE_DEFAULT_PREFIX", episode_bag::DEFAULT_PREFIX),
        (
            "CUSTOM_EPISODE_INDEX",
            episode_bag::custom_data::EPISODE_INDEX,
        ),
        ("CUSTOM_TASK", episode_bag::custom_data::TASK),
        ("CUSTOM_SUCCESS", episode_bag::custom_data::SUCCESS),
        ("CUSTOM_SEED", episode_bag::custom_data::SEED),
        ("CUSTOM_SIMULATION", episode_bag::custom_data::SIMULATION),
    ];
    for (name, value) in layout {
        out += &format!("{name} = \"{value}\"\n");
    }
    out += "\n\ndef camera_topic(name: str, leaf: str = IMAGE_RAW) -> str:\n    \
            \"\"\"`camera/<name>/<leaf>` (leaf: IMAGE_RAW, IMAGE_COMPRESSED, CAMERA_INFO).\"\"\"\n    \
            return f\"{CAMERA_PREFIX}/{name}/{leaf}\"\n";
    out
}

/// The tasks' facts (so101_core::task) as a Python table keyed by task name.
fn tasks_python() -> String {
    let mut out = format!(
        "# The control rate of a policy and of teleoperated demonstrations: one action and one\n\
         # observation per period, a dataset's fps, every task's default (Hz).\n\
         CONTROL_RATE = {CONTROL_RATE_HZ:?}\n\n\n\
         class Task(NamedTuple):\n    \
             \"\"\"A task's facts (so101_core::task::TaskFacts).\"\"\"\n\n    \
             name: str\n    \
             gym_id: str  # the in-process Gymnasium environment\n    \
             description: str  # the task text of a LeRobot dataset's episodes\n    \
             episode_steps: int  # at control_rate\n    \
             terminates_on_success: bool\n    \
             reward_modes: tuple[str, ...]  # the first is the default\n    \
             control_rate: float\n\n\n\
         # Every task the simulation core knows, by name, in the order command lines list them.\n\
         TASKS = {{\n"
    );
    for kind in TaskKind::ALL {
        let facts = kind.facts();
        let modes: Vec<_> = facts.reward_modes.iter().map(|mode| mode.name()).collect();
        let modes = match modes.as_slice() {
            [one] => format!("(\"{one}\",)"),
            many => format!(
                "({})",
                many.iter()
                    .map(|mode| format!("\"{mode}\""))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        };
        let terminates = if facts.terminates_on_success {
            "True"
        } else {
            "False"
        };
        out += &format!(
            "    \"{name}\": Task(\n        \
                 name=\"{name}\",\n        \
                 gym_id=\"{gym_id}\",\n        \
                 description=\"{description}\",\n        \
                 episode_steps={steps},\n        \
                 terminates_on_success={terminates},\n        \
                 reward_modes={modes},\n        \
                 control_rate={rate:?},\n    \
             ),\n",
            name = facts.name,
            gym_id = facts.gym_id,
            description = facts.description,
            steps = facts.episode_steps,
            rate = facts.control_rate_hz,
        );
    }
    out += "}\n\n";
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn camera_topics_are_under_the_prefix() {
        assert_eq!(
            topics::camera("top", topics::IMAGE_RAW),
            "camera/top/image_raw"
        );
        assert_eq!(
            topics::camera("wrist", topics::IMAGE_COMPRESSED),
            "camera/wrist/image_raw/compressed"
        );
    }

    /// The committed Python module is what the generator writes now.
    #[test]
    fn python_contract_matches_the_rust_facts() {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../python/src/so101/contract.py"
        );
        let committed = std::fs::read_to_string(path).unwrap_or_default();
        assert!(
            committed == python_module(),
            "{path} differs from so101_core's contract: regenerate it with \
             `cargo run -p so101_core --bin so101_contract -- --python > python/src/so101/contract.py`"
        );
    }
}
