//! ROS 2 parameters on every node: what `ros2 param list/get/set/describe` and rclpy's parameter
//! client expect, declared by each node with its description, read-only or settable at run time.

pub mod documentation;
pub mod options;
pub mod server;
pub mod store;
pub mod value;

pub use options::Options;
pub use server::ParameterServer;
pub use store::{Change, Declaration, Parameters, Value};

use crate::robot::{JointLimit, JOINT_COUNT, JOINT_NAMES};

/// The joints and the position limits a node enforces (read-only), as every arm node reports them.
pub fn joint_declarations(limits: &[JointLimit; JOINT_COUNT]) -> Vec<Declaration> {
    vec![
        Declaration::new(
            "joints.names",
            Value::StringArray(JOINT_NAMES.iter().map(|name| name.to_string()).collect()),
            "The arm's joints, in the order of every array parameter and of \
             /forward_position_controller/commands.",
        ),
        Declaration::new(
            "joints.min_positions",
            Value::DoubleArray(limits.iter().map(|limit| limit.min).collect()),
            "Lowest position each joint is commanded to (rad); commands beyond are clamped.",
        ),
        Declaration::new(
            "joints.max_positions",
            Value::DoubleArray(limits.iter().map(|limit| limit.max).collect()),
            "Highest position each joint is commanded to (rad); commands beyond are clamped.",
        ),
    ]
}
