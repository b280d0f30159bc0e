use so101_msgs::{
    diagnostic_msgs::DiagnosticArray, geometry_msgs::PoseStamped, sensor_msgs::JointState,
    RosMessage,
};

fn separator(name: &str) -> String {
    format!("{}\nMSG: {name}\n", "=".repeat(80))
}

#[test]
fn joint_state_schema_lists_each_dependency_once_in_depth_first_order() {
    let schema = JointState::INFO.ros2msg_schema();
    let expected = format!(
        "std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\nfloat64[] effort\n{}builtin_interfaces/Time stamp\nstring frame_id\n{}int32 sec\nuint32 nanosec\n",
        separator("std_msgs/Header"),
        separator("builtin_interfaces/Time"),
    );
    assert_eq!(schema, expected);
    assert_eq!(JointState::INFO.full_name(), "sensor_msgs/msg/JointState");
}

#[test]
fn shared_dependencies_are_not_repeated() {
    // PoseStamped reaches Time only through Header; DiagnosticArray reaches KeyValue through status.
    let schema = PoseStamped::INFO.ros2msg_schema();
    for name in [
        "std_msgs/Header",
        "builtin_interfaces/Time",
        "geometry_msgs/Pose",
        "geometry_msgs/Point",
    ] {
        assert_eq!(
            schema.matches(&format!("MSG: {name}\n")).count(),
            1,
            "{name} in\n{schema}"
        );
    }
    let schema = DiagnosticArray::INFO.ros2msg_schema();
    assert_eq!(schema.matches("MSG: diagnostic_msgs/KeyValue\n").count(), 1);
    assert!(schema.starts_with("std_msgs/Header header\nDiagnosticStatus[] status\n"));
}
