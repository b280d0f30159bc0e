//! trajectory_msgs: what MoveIt and ros2_control's joint_trajectory_controller send.

use serde::{Deserialize, Serialize};

use crate::{
    builtin_interfaces::Duration,
    geometry_msgs::{Transform, Twist},
    std_msgs::Header,
};

/// trajectory_msgs/JointTrajectoryPoint: each array empty or one value per joint name.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct JointTrajectoryPoint {
    pub positions: Vec<f64>,
    pub velocities: Vec<f64>,
    pub accelerations: Vec<f64>,
    pub effort: Vec<f64>,
    pub time_from_start: Duration,
}
crate::ros_message!(
    JointTrajectoryPoint,
    "trajectory_msgs",
    "JointTrajectoryPoint",
    "float64[] positions\nfloat64[] velocities\nfloat64[] accelerations\nfloat64[] effort\nbuiltin_interfaces/Duration time_from_start\n",
    deps: [Duration]
);

/// trajectory_msgs/JointTrajectory
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct JointTrajectory {
    pub header: Header,
    pub joint_names: Vec<String>,
    pub points: Vec<JointTrajectoryPoint>,
}
crate::ros_message!(
    JointTrajectory,
    "trajectory_msgs",
    "JointTrajectory",
    "std_msgs/Header header\nstring[] joint_names\nJointTrajectoryPoint[] points\n",
    deps: [Header, JointTrajectoryPoint]
);

/// trajectory_msgs/MultiDOFJointTrajectoryPoint (part of FollowJointTrajectory; unused by an arm
/// of revolute joints, always empty here).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct MultiDofJointTrajectoryPoint {
    pub transforms: Vec<Transform>,
    pub velocities: Vec<Twist>,
    pub accelerations: Vec<Twist>,
    pub time_from_start: Duration,
}
crate::ros_message!(
    MultiDofJointTrajectoryPoint,
    "trajectory_msgs",
    "MultiDOFJointTrajectoryPoint",
    "geometry_msgs/Transform[] transforms\ngeometry_msgs/Twist[] velocities\ngeometry_msgs/Twist[] accelerations\nbuiltin_interfaces/Duration time_from_start\n",
    deps: [Transform, Twist, Duration]
);

/// trajectory_msgs/MultiDOFJointTrajectory
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct MultiDofJointTrajectory {
    pub header: Header,
    pub joint_names: Vec<String>,
    pub points: Vec<MultiDofJointTrajectoryPoint>,
}
crate::ros_message!(
    MultiDofJointTrajectory,
    "trajectory_msgs",
    "MultiDOFJointTrajectory",
    "std_msgs/Header header\nstring[] joint_names\nMultiDOFJointTrajectoryPoint[] points\n",
    deps: [Header, MultiDofJointTrajectoryPoint]
);
