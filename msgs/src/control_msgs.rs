//! control_msgs (Jazzy, control_msgs 5.x): the FollowJointTrajectory action MoveIt's controller
//! manager sends to an arm controller, with its tolerance messages.

use serde::{Deserialize, Serialize};

use crate::{
    builtin_interfaces::Duration,
    std_msgs::Header,
    trajectory_msgs::{
        JointTrajectory, JointTrajectoryPoint, MultiDofJointTrajectory,
        MultiDofJointTrajectoryPoint,
    },
};

/// control_msgs/JointTolerance: 0 means the controller's default, -1 no check.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct JointTolerance {
    pub name: String,
    pub position: f64,
    pub velocity: f64,
    pub acceleration: f64,
}
crate::ros_message!(
    JointTolerance,
    "control_msgs",
    "JointTolerance",
    "string name\nfloat64 position\nfloat64 velocity\nfloat64 acceleration\n"
);

/// control_msgs/JointComponentTolerance (for multi-DOF joints; none here).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct JointComponentTolerance {
    pub joint_name: String,
    pub component: u16,
    pub position: f64,
    pub velocity: f64,
    pub acceleration: f64,
}
crate::ros_message!(
    JointComponentTolerance,
    "control_msgs",
    "JointComponentTolerance",
    "uint16 X_AXIS=1\nuint16 Y_AXIS=2\nuint16 Z_AXIS=3\nuint16 TRANSLATION=4\nuint16 ROTATION=5\nstring joint_name\nuint16 component\nfloat64 position\nfloat64 velocity\nfloat64 acceleration\n"
);

/// The goal of control_msgs/action/FollowJointTrajectory.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct FollowJointTrajectoryGoal {
    pub trajectory: JointTrajectory,
    pub multi_dof_trajectory: MultiDofJointTrajectory,
    pub path_tolerance: Vec<JointTolerance>,
    pub component_path_tolerance: Vec<JointComponentTolerance>,
    pub goal_tolerance: Vec<JointTolerance>,
    pub component_goal_tolerance: Vec<JointComponentTolerance>,
    pub goal_time_tolerance: Duration,
}
impl ros2_client::Message for FollowJointTrajectoryGoal {}

/// The result of control_msgs/action/FollowJointTrajectory.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct FollowJointTrajectoryResult {
    /// One of the `FollowJointTrajectoryResult::*` codes.
    pub error_code: i32,
    pub error_string: String,
}
impl FollowJointTrajectoryResult {
    pub const SUCCESSFUL: i32 = 0;
    pub const INVALID_GOAL: i32 = -1;
    pub const INVALID_JOINTS: i32 = -2;
    pub const OLD_HEADER_TIMESTAMP: i32 = -3;
    pub const PATH_TOLERANCE_VIOLATED: i32 = -4;
    pub const GOAL_TOLERANCE_VIOLATED: i32 = -5;
}
impl ros2_client::Message for FollowJointTrajectoryResult {}

/// The feedback of control_msgs/action/FollowJointTrajectory.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct FollowJointTrajectoryFeedback {
    pub header: Header,
    pub joint_names: Vec<String>,
    pub desired: JointTrajectoryPoint,
    pub actual: JointTrajectoryPoint,
    pub error: JointTrajectoryPoint,
    pub multi_dof_joint_names: Vec<String>,
    pub multi_dof_desired: MultiDofJointTrajectoryPoint,
    pub multi_dof_actual: MultiDofJointTrajectoryPoint,
    pub multi_dof_error: MultiDofJointTrajectoryPoint,
}
impl ros2_client::Message for FollowJointTrajectoryFeedback {}

/// control_msgs/action/FollowJointTrajectory: its type name and `.action` text (goal, `---`,
/// result, `---`, feedback), from which rosidl derives the type hash that
/// tests/integration/test_trajectories.py checks against the published one.
pub struct FollowJointTrajectory;
impl FollowJointTrajectory {
    pub const PACKAGE: &'static str = "control_msgs";
    pub const NAME: &'static str = "FollowJointTrajectory";
    pub const DEFINITION: &'static str = "trajectory_msgs/JointTrajectory trajectory\n\
trajectory_msgs/MultiDOFJointTrajectory multi_dof_trajectory\n\
JointTolerance[] path_tolerance\n\
JointComponentTolerance[] component_path_tolerance\n\
JointTolerance[] goal_tolerance\n\
JointComponentTolerance[] component_goal_tolerance\n\
builtin_interfaces/Duration goal_time_tolerance\n\
---\n\
int32 error_code\n\
int32 SUCCESSFUL = 0\n\
int32 INVALID_GOAL = -1\n\
int32 INVALID_JOINTS = -2\n\
int32 OLD_HEADER_TIMESTAMP = -3\n\
int32 PATH_TOLERANCE_VIOLATED = -4\n\
int32 GOAL_TOLERANCE_VIOLATED = -5\n\
string error_string\n\
---\n\
std_msgs/Header header\n\
string[] joint_names\n\
trajectory_msgs/JointTrajectoryPoint desired\n\
trajectory_msgs/JointTrajectoryPoint actual\n\
trajectory_msgs/JointTrajectoryPoint error\n\
string[] multi_dof_joint_names\n\
trajectory_msgs/MultiDOFJointTrajectoryPoint multi_dof_desired\n\
trajectory_msgs/MultiDOFJointTrajectoryPoint multi_dof_actual\n\
trajectory_msgs/MultiDOFJointTrajectoryPoint multi_dof_error\n";

    pub fn action_type_name() -> ros2_client::ActionTypeName {
        ros2_client::ActionTypeName::new(Self::PACKAGE, Self::NAME)
    }
}
