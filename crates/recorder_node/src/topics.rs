//! Which topics a recording holds, and what their types are: the default set of the stack, or
//! `--all`, or patterns; ROS names and types from what DDS discovery reports; the schemas the
//! recorder can write (the standard types of `so101_msgs`). Pure logic.

use regex::Regex;
use so101_core::contract::topics;
use so101_msgs::{
    builtin_interfaces, diagnostic_msgs, geometry_msgs, rosgraph_msgs, sensor_msgs, std_msgs,
    tf2_msgs, RosMessage, TypeInfo,
};

/// Topics recorded by default (relative to the namespace; regular expressions, whole-name match):
/// joint states and commands, cameras with their info, the task, episode events, diagnostics.
pub const DEFAULT_PATTERNS: &[&str] = &[
    "joint_states",
    "joint_commands",
    "forward_position_controller/commands",
    "leader/joint_states",
    "camera/[^/]+/image_raw",
    "camera/[^/]+/camera_info",
    "task/reward",
    "task/success",
    "cube/pose",
    "episode/events",
    "diagnostics",
];

/// Every message type whose definition the recorder has, so it can write its ros2msg schema.
pub fn known_types() -> Vec<&'static TypeInfo> {
    vec![
        builtin_interfaces::Time::INFO,
        std_msgs::Header::INFO,
        std_msgs::Bool::INFO,
        std_msgs::Float64::INFO,
        std_msgs::String::INFO,
        std_msgs::Float64MultiArray::INFO,
        sensor_msgs::JointState::INFO,
        sensor_msgs::Image::INFO,
        sensor_msgs::CompressedImage::INFO,
        sensor_msgs::CameraInfo::INFO,
        geometry_msgs::Pose::INFO,
        geometry_msgs::PoseStamped::INFO,
        geometry_msgs::Vector3::INFO,
        geometry_msgs::Transform::INFO,
        geometry_msgs::TransformStamped::INFO,
        tf2_msgs::TFMessage::INFO,
        rosgraph_msgs::Clock::INFO,
        diagnostic_msgs::DiagnosticArray::INFO,
    ]
}

/// The known type called `full_name` (`pkg/msg/Name`).
pub fn known_type(full_name: &str) -> Option<&'static TypeInfo> {
    known_types()
        .into_iter()
        .find(|info| info.full_name() == full_name)
}

/// ROS topic name of a discovered topic (`rt/joint_states` -> `/joint_states`; a name that is
/// already a ROS name stays); `None` for DDS topics that are not ROS topics (services, discovery).
pub fn ros_topic_name(dds_name: &str) -> Option<String> {
    if dds_name.starts_with('/') {
        return Some(dds_name.to_owned());
    }
    dds_name.strip_prefix("rt/").map(|rest| format!("/{rest}"))
}

/// The default topics whose type is fixed by the topic contract: subscribed at once, before
/// discovery has seen a publisher (the first messages of an episode that starts with the
/// recorder are not lost to discovery).
pub const DEFAULT_FIXED: &[(&str, &str)] = &[
    (topics::JOINT_STATES, "sensor_msgs/msg/JointState"),
    (topics::JOINT_COMMANDS, "sensor_msgs/msg/JointState"),
    (
        topics::FORWARD_POSITION_COMMANDS,
        "std_msgs/msg/Float64MultiArray",
    ),
    (topics::LEADER_JOINT_STATES, "sensor_msgs/msg/JointState"),
    (topics::TASK_REWARD, "std_msgs/msg/Float64"),
    (topics::TASK_SUCCESS, "std_msgs/msg/Bool"),
    (topics::CUBE_POSE, "geometry_msgs/msg/PoseStamped"),
    (topics::EPISODE_EVENTS, "std_msgs/msg/String"),
    (topics::DIAGNOSTICS, "diagnostic_msgs/msg/DiagnosticArray"),
];

/// ROS type name of a DDS type (`sensor_msgs::msg::dds_::JointState_` -> `sensor_msgs/msg/JointState`).
pub fn ros_type_name(dds_type: &str) -> Option<String> {
    let (package, rest) = dds_type.split_once("::msg::dds_::")?;
    let name = rest.strip_suffix('_')?;
    if package.is_empty() || name.is_empty() || name.contains("::") {
        return None;
    }
    Some(format!("{package}/msg/{name}"))
}

/// What the user asked to record.
#[derive(Debug, Clone)]
pub struct Selection {
    include: Vec<Regex>,
    exclude: Option<Regex>,
    /// Topics named exactly (recorded even when no pattern names them).
    exact: Vec<String>,
}

#[derive(Debug, thiserror::Error)]
pub enum SelectionError {
    #[error("bad topic pattern {pattern:?}: {source}")]
    Pattern {
        pattern: String,
        source: regex::Error,
    },
}

fn whole(pattern: &str) -> Result<Regex, SelectionError> {
    Regex::new(&format!("^(?:{pattern})$")).map_err(|source| SelectionError::Pattern {
        pattern: pattern.to_owned(),
        source,
    })
}

impl Selection {
    /// `namespace` is the recorder's (e.g. `/` or `/arm1`); patterns and topic names that do not
    /// start with `/` are taken relative to it.
    pub fn new(
        namespace: &str,
        topics: &[String],
        all: bool,
        patterns: &[String],
        exclude: Option<&str>,
    ) -> Result<Self, SelectionError> {
        let prefix = namespace.trim_end_matches('/').to_owned();
        let absolute = |name: &str| {
            if name.starts_with('/') {
                name.to_owned()
            } else {
                format!("{prefix}/{name}")
            }
        };
        let mut include = Vec::new();
        if all {
            include.push(whole(".*")?);
        }
        for pattern in patterns {
            include.push(whole(&absolute(pattern))?);
        }
        if !all && patterns.is_empty() && topics.is_empty() {
            for pattern in DEFAULT_PATTERNS {
                include.push(whole(&absolute(pattern))?);
            }
        }
        Ok(Self {
            include,
            exclude: exclude.map(whole).transpose()?,
            exact: topics.iter().map(|topic| absolute(topic)).collect(),
        })
    }

    pub fn wants(&self, topic: &str) -> bool {
        let included = self.exact.iter().any(|name| name == topic)
            || self.include.iter().any(|pattern| pattern.is_match(topic));
        included && !self.exclude.as_ref().is_some_and(|e| e.is_match(topic))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dds_names_map_to_ros_names() {
        assert_eq!(
            ros_topic_name("rt/camera/top/image_raw").as_deref(),
            Some("/camera/top/image_raw")
        );
        assert_eq!(ros_topic_name("rq/sim/resetRequest"), None);
        assert_eq!(ros_topic_name("ros_discovery_info"), None);
        assert_eq!(
            ros_type_name("sensor_msgs::msg::dds_::JointState_").as_deref(),
            Some("sensor_msgs/msg/JointState")
        );
        assert_eq!(ros_type_name("std_srvs::srv::dds_::Trigger_Request_"), None);
        assert_eq!(ros_type_name("garbage"), None);
    }

    #[test]
    fn every_known_type_has_a_complete_schema() {
        let image = known_type("sensor_msgs/msg/Image").unwrap();
        let schema = image.ros2msg_schema();
        assert!(schema.starts_with("std_msgs/Header header\n"));
        assert!(schema.contains("MSG: std_msgs/Header\n"));
        assert!(schema.contains("MSG: builtin_interfaces/Time\n"));
        assert!(known_type("sensor_msgs/msg/PointCloud2").is_none());
        for info in known_types() {
            assert!(!info.definition.is_empty(), "{}", info.full_name());
        }
    }

    #[test]
    fn the_default_set_follows_the_namespace_and_takes_any_camera() {
        let selection = Selection::new("/arm1", &[], false, &[], None).unwrap();
        assert!(selection.wants("/arm1/joint_states"));
        assert!(selection.wants("/arm1/camera/wrist/image_raw"));
        assert!(!selection.wants("/arm1/camera/wrist/image_raw/compressed"));
        assert!(!selection.wants("/joint_states"));
        assert!(!selection.wants("/arm1/clock"));
    }

    #[test]
    fn explicit_topics_patterns_all_and_exclusions() {
        let topics = vec!["clock".to_string()];
        let selection = Selection::new("/", &topics, false, &[], None).unwrap();
        assert!(selection.wants("/clock"));
        assert!(
            !selection.wants("/joint_states"),
            "naming topics replaces the default set"
        );
        let patterns = vec!["camera/.*".to_string()];
        let selection = Selection::new("/", &[], false, &patterns, Some(".*/compressed")).unwrap();
        assert!(selection.wants("/camera/top/image_raw"));
        assert!(!selection.wants("/camera/top/image_raw/compressed"));
        let all = Selection::new("/", &[], true, &[], None).unwrap();
        assert!(all.wants("/anything/at/all"));
        assert!(Selection::new("/", &[], false, &["(".to_string()], None).is_err());
    }
}
