//! The standard ROS 2 messages and services the SO-101 stack speaks, as Rust types.
//!
//! Each type carries its ROS type name and its exact field definition (the `.msg`/`.srv` text without
//! comments), so nodes can create topics with the right DDS type and the recorder can write the
//! definition as an MCAP `ros2msg` schema. Only standard types are used, so every rclpy tool can talk to
//! the stack without building a message package. Field order must equal the `.msg` order: the CDR
//! encoding is positional.

pub mod builtin_interfaces;
pub mod control_msgs;
pub mod diagnostic_msgs;
pub mod geometry_msgs;
pub mod rcl_interfaces;
pub mod rosgraph_msgs;
pub mod sensor_msgs;
pub mod std_msgs;
pub mod std_srvs;
pub mod tf2_msgs;
pub mod trajectory_msgs;
mod type_info;

pub use type_info::{RosMessage, RosService, TypeInfo};

/// Implements [`ros2_client::Message`] and [`RosMessage`] for a message struct.
macro_rules! ros_message {
    ($ty:ty, $package:literal, $name:literal, $definition:expr $(, deps: [$($dep:ty),* $(,)?])? $(,)?) => {
        impl ros2_client::Message for $ty {}
        impl $crate::RosMessage for $ty {
            const INFO: &'static $crate::TypeInfo = &$crate::TypeInfo {
                package: $package,
                name: $name,
                definition: $definition,
                dependencies: &[$($(<$dep as $crate::RosMessage>::INFO),*)?],
            };
        }
    };
}
pub(crate) use ros_message;

/// The definition text of an interface the stack defines beyond the common ones, by its full name
/// (`pkg/msg/Name` or `pkg/action/Name`): what `ros2 interface show` prints, without comments.
/// `so101_contract --interface NAME` prints it; the tests hash it with rosidl and compare with the
/// published type hashes.
pub fn interface_definition(full_name: &str) -> Option<&'static str> {
    use control_msgs::{FollowJointTrajectory, JointComponentTolerance, JointTolerance};
    use rcl_interfaces::{
        FloatingPointRange, IntegerRange, ListParametersResult, Parameter, ParameterDescriptor,
        ParameterEvent, ParameterValue, SetParametersResult,
    };
    use trajectory_msgs::{
        JointTrajectory, JointTrajectoryPoint, MultiDofJointTrajectory,
        MultiDofJointTrajectoryPoint,
    };
    if full_name == "control_msgs/action/FollowJointTrajectory" {
        return Some(FollowJointTrajectory::DEFINITION);
    }
    let messages = [
        JointTolerance::INFO,
        JointComponentTolerance::INFO,
        JointTrajectory::INFO,
        JointTrajectoryPoint::INFO,
        MultiDofJointTrajectory::INFO,
        MultiDofJointTrajectoryPoint::INFO,
        ParameterValue::INFO,
        Parameter::INFO,
        ParameterDescriptor::INFO,
        FloatingPointRange::INFO,
        IntegerRange::INFO,
        SetParametersResult::INFO,
        ListParametersResult::INFO,
        ParameterEvent::INFO,
    ];
    messages
        .into_iter()
        .find(|info| info.full_name() == full_name)
        .map(|info| info.definition)
}
