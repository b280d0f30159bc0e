//! Absolute topic and service names under an optional namespace, so two arms can share one graph
//! (`--namespace left` gives `/left/joint_states`).

use ros2_client::{Name, NodeName};

#[derive(Debug, thiserror::Error)]
pub enum NameError {
    #[error("invalid namespace {0:?}: use letters, digits and '_', segments separated by '/', not starting with a digit")]
    BadNamespace(String),
    #[error("invalid name {name:?}: {reason}")]
    Bad { name: String, reason: String },
}

/// Resolves names relative to the node's namespace.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Names {
    /// "/" or "/a/b" (absolute, no trailing slash).
    namespace: String,
}

impl Names {
    /// `namespace` may be given with or without the leading slash; empty or "/" is the root.
    pub fn new(namespace: Option<&str>) -> Result<Self, NameError> {
        let trimmed = namespace.unwrap_or("").trim_matches('/');
        if trimmed.is_empty() {
            return Ok(Self {
                namespace: "/".into(),
            });
        }
        let valid_segment = |segment: &str| {
            !segment.is_empty()
                && !segment.starts_with(|c: char| c.is_ascii_digit())
                && !segment.contains("__")
                && segment
                    .chars()
                    .all(|c| c.is_ascii_alphanumeric() || c == '_')
        };
        if !trimmed.split('/').all(valid_segment) {
            return Err(NameError::BadNamespace(namespace.unwrap_or("").to_owned()));
        }
        Ok(Self {
            namespace: format!("/{trimmed}"),
        })
    }

    pub fn namespace(&self) -> &str {
        &self.namespace
    }

    /// The absolute name of `relative` (e.g. "joint_states", "sim/reset") in this namespace.
    pub fn resolve(&self, relative: &str) -> String {
        let relative = relative.trim_start_matches('/');
        if self.namespace == "/" {
            format!("/{relative}")
        } else {
            format!("{}/{relative}", self.namespace)
        }
    }

    /// `relative` as a ros2-client [`Name`]. ros2-client turns a relative name in the root namespace
    /// into "//name", so names are always built absolute.
    pub fn name(&self, relative: &str) -> Result<Name, NameError> {
        let absolute = self.resolve(relative);
        let (parent, base) = absolute.rsplit_once('/').unwrap_or(("", &absolute));
        let parent = if parent.is_empty() { "/" } else { parent };
        Name::new(parent, base).map_err(|error| NameError::Bad {
            name: absolute.clone(),
            reason: format!("{error:?}"),
        })
    }

    pub fn node_name(&self, base: &str) -> Result<NodeName, NameError> {
        NodeName::new(&self.namespace, base).map_err(|error| NameError::Bad {
            name: base.to_owned(),
            reason: format!("{error:?}"),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn root_namespace_gives_plain_absolute_names() {
        let names = Names::new(None).unwrap();
        assert_eq!(names.resolve("joint_states"), "/joint_states");
        assert_eq!(names.resolve("sim/reset"), "/sim/reset");
        assert_eq!(Names::new(Some("/")).unwrap(), names);
        assert_eq!(Names::new(Some("")).unwrap(), names);
    }

    #[test]
    fn namespace_prefixes_every_name() {
        for given in ["arm1", "/arm1", "/arm1/"] {
            let names = Names::new(Some(given)).unwrap();
            assert_eq!(names.resolve("joint_states"), "/arm1/joint_states");
            assert_eq!(names.resolve("/sim/step"), "/arm1/sim/step");
        }
        assert_eq!(
            Names::new(Some("lab/left")).unwrap().resolve("clock"),
            "/lab/left/clock"
        );
    }

    #[test]
    fn bad_namespaces_are_refused() {
        for bad in ["1arm", "arm-1", "a//b", "a b", "a__b"] {
            assert!(Names::new(Some(bad)).is_err(), "{bad}");
        }
    }

    #[test]
    fn ros_names_build_for_nested_paths() {
        let names = Names::new(Some("arm1")).unwrap();
        assert!(names.name("sim/reset").is_ok());
        assert!(names.name("forward_position_controller/commands").is_ok());
        assert!(Names::new(None).unwrap().name("joint_states").is_ok());
    }
}
