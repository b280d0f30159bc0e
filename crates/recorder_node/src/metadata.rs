//! rosbag2's bag metadata: the `metadata.yaml` beside the .mcap files (format version 9, what
//! Jazzy's `ros2 bag info` reads), the same YAML in the MCAP "rosbag2" metadata record, and the
//! `offered_qos_profiles` channel metadata. Pure text building.

/// QoS of a recorded topic, as rosbag2 writes it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct QosSummary {
    pub reliable: bool,
    pub depth: usize,
}

/// DDS "infinite" duration, as rosbag2 prints it.
const INFINITE: &str = "sec: 9223372036\nnsec: 854775807";

impl QosSummary {
    /// The YAML list `offered_qos_profiles` holds (one profile), indented by `indent` spaces.
    pub fn yaml(&self, indent: usize) -> String {
        let pad = " ".repeat(indent);
        // Nested two levels below the list item's keys.
        let infinite = INFINITE.replace('\n', &format!("\n{pad}    "));
        let reliability = if self.reliable {
            "reliable"
        } else {
            "best_effort"
        };
        [
            format!("{pad}- history: keep_last"),
            format!("{pad}  depth: {}", self.depth),
            format!("{pad}  reliability: {reliability}"),
            format!("{pad}  durability: volatile"),
            format!("{pad}  deadline:\n{pad}    {infinite}"),
            format!("{pad}  lifespan:\n{pad}    {infinite}"),
            format!("{pad}  liveliness: automatic"),
            format!("{pad}  liveliness_lease_duration:\n{pad}    {infinite}"),
            format!("{pad}  avoid_ros_namespace_conventions: false"),
        ]
        .join("\n")
    }
}

#[derive(Debug, Clone, PartialEq)]
pub struct TopicSummary {
    pub name: String,
    pub type_name: String,
    pub qos: QosSummary,
    pub message_count: u64,
}

#[derive(Debug, Clone, PartialEq)]
pub struct FileSummary {
    /// Relative to the bag directory.
    pub path: String,
    pub start_ns: u64,
    pub duration_ns: u64,
    pub message_count: u64,
}

#[derive(Debug, Clone, PartialEq)]
pub struct BagSummary {
    pub start_ns: u64,
    pub duration_ns: u64,
    pub message_count: u64,
    pub topics: Vec<TopicSummary>,
    pub files: Vec<FileSummary>,
    pub custom_data: Vec<(String, String)>,
}

/// A YAML double-quoted string (safe for any text).
pub fn quote(text: &str) -> String {
    let mut out = String::with_capacity(text.len() + 2);
    out.push('"');
    for c in text.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            '\t' => out.push_str("\\t"),
            c if c.is_control() => out.push_str(&format!("\\u{:04x}", c as u32)),
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

/// metadata.yaml as rosbag2 (version 9) writes it.
pub fn metadata_yaml(bag: &BagSummary) -> String {
    let mut out = String::from("rosbag2_bagfile_information:\n");
    let mut line = |text: String| {
        out.push_str(&text);
        out.push('\n');
    };
    line("  version: 9".into());
    line("  storage_identifier: mcap".into());
    line(format!("  duration:\n    nanoseconds: {}", bag.duration_ns));
    line(format!(
        "  starting_time:\n    nanoseconds_since_epoch: {}",
        bag.start_ns
    ));
    line(format!("  message_count: {}", bag.message_count));
    if bag.topics.is_empty() {
        line("  topics_with_message_count: []".into());
    } else {
        line("  topics_with_message_count:".into());
    }
    for topic in &bag.topics {
        line("    - topic_metadata:".into());
        line(format!("        name: {}", quote(&topic.name)));
        line(format!("        type: {}", quote(&topic.type_name)));
        line("        serialization_format: cdr".into());
        line("        offered_qos_profiles:".into());
        line(topic.qos.yaml(10));
        line("        type_description_hash: \"\"".into());
        line(format!("      message_count: {}", topic.message_count));
    }
    line("  compression_format: \"\"".into());
    line("  compression_mode: \"\"".into());
    line("  relative_file_paths:".into());
    for file in &bag.files {
        line(format!("    - {}", quote(&file.path)));
    }
    line("  files:".into());
    for file in &bag.files {
        line(format!("    - path: {}", quote(&file.path)));
        line(format!(
            "      starting_time:\n        nanoseconds_since_epoch: {}",
            file.start_ns
        ));
        line(format!(
            "      duration:\n        nanoseconds: {}",
            file.duration_ns
        ));
        line(format!("      message_count: {}", file.message_count));
    }
    if bag.custom_data.is_empty() {
        line("  custom_data: ~".into());
    } else {
        line("  custom_data:".into());
        for (key, value) in &bag.custom_data {
            line(format!("    {}: {}", quote(key), quote(value)));
        }
    }
    line("  ros_distro: jazzy".into());
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quoting_survives_any_text() {
        assert_eq!(quote("plain"), "\"plain\"");
        assert_eq!(quote("a \"b\"\n\\"), "\"a \\\"b\\\"\\n\\\\\"");
        assert_eq!(quote("\u{7}"), "\"\\u0007\"");
    }

    #[test]
    fn metadata_lists_topics_files_and_custom_data() {
        let yaml = metadata_yaml(&BagSummary {
            start_ns: 5,
            duration_ns: 7,
            message_count: 3,
            topics: vec![TopicSummary {
                name: "/joint_states".into(),
                type_name: "sensor_msgs/msg/JointState".into(),
                qos: QosSummary {
                    reliable: true,
                    depth: 10,
                },
                message_count: 3,
            }],
            files: vec![FileSummary {
                path: "e_0.mcap".into(),
                start_ns: 5,
                duration_ns: 7,
                message_count: 3,
            }],
            custom_data: vec![("task".into(), "pick: \"cube\"".into())],
        });
        assert!(yaml.contains("  storage_identifier: mcap\n"));
        assert!(yaml.contains("        name: \"/joint_states\"\n"));
        assert!(yaml.contains("          - history: keep_last\n            depth: 10\n"));
        assert!(yaml.contains("    \"task\": \"pick: \\\"cube\\\"\"\n"));
        assert!(yaml.ends_with("  ros_distro: jazzy\n"));
    }
}
