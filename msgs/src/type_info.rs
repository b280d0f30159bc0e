use ros2_client::{MessageTypeName, ServiceTypeName};

/// Name and definition of one ROS message type, with the message types its fields use.
#[derive(Debug)]
pub struct TypeInfo {
    pub package: &'static str,
    pub name: &'static str,
    /// The `.msg` text: one field or constant per line, no comments.
    pub definition: &'static str,
    /// Message types named in `definition` (direct dependencies only).
    pub dependencies: &'static [&'static TypeInfo],
}

impl TypeInfo {
    /// `pkg/msg/Name`, the form rosbag2 writes as MCAP schema name and `ros2 topic list -t` prints.
    pub fn full_name(&self) -> String {
        format!("{}/msg/{}", self.package, self.name)
    }

    /// The DDS-level type name used by ros2-client when creating topics.
    pub fn message_type_name(&self) -> MessageTypeName {
        MessageTypeName::new(self.package, self.name)
    }

    /// The complete `ros2msg` schema text: this definition first, then every dependency once
    /// (depth first), each after a line of 80 '=' and a `MSG: pkg/Name` line, as rosbag2 writes it.
    pub fn ros2msg_schema(&self) -> String {
        let mut text = self.definition.to_owned();
        let mut seen: Vec<*const TypeInfo> = Vec::new();
        self.append_dependencies(&mut text, &mut seen);
        text
    }

    fn append_dependencies(&self, text: &mut String, seen: &mut Vec<*const TypeInfo>) {
        for dependency in self.dependencies {
            let key = *dependency as *const TypeInfo;
            if seen.contains(&key) {
                continue;
            }
            seen.push(key);
            if !text.ends_with('\n') {
                text.push('\n');
            }
            text.push_str(&"=".repeat(80));
            text.push_str(&format!(
                "\nMSG: {}/{}\n",
                dependency.package, dependency.name
            ));
            text.push_str(dependency.definition);
            dependency.append_dependencies(text, seen);
        }
    }
}

/// A Rust type that is a ROS message.
pub trait RosMessage: ros2_client::Message {
    const INFO: &'static TypeInfo;
}

/// A ROS service: its request and response types and its `.srv` text.
pub trait RosService {
    type Request: ros2_client::Message;
    type Response: ros2_client::Message;
    const PACKAGE: &'static str;
    const NAME: &'static str;
    /// The `.srv` text: request fields, `---`, response fields.
    const DEFINITION: &'static str;

    fn service_type_name() -> ServiceTypeName {
        ServiceTypeName::new(Self::PACKAGE, Self::NAME)
    }
}
