//! The recorder's ROS parameters: its command-line settings, read-only, and the topic selection
//! (topics, all, regex, exclude), which may change while it records: newly wanted topics are
//! subscribed at the next discovery (within a second), topics no longer wanted stop being written.

use so101_core::ros::parameters::{Declaration, Parameters, Value};

use crate::{
    cli::Args,
    topics::{Selection, SelectionError},
};

/// The selection options as set now.
#[derive(Debug, Clone, PartialEq)]
pub struct SelectionOptions {
    pub topics: Vec<String>,
    pub all: bool,
    pub patterns: Vec<String>,
    pub exclude: Option<String>,
}

impl SelectionOptions {
    pub fn from_args(args: &Args) -> Self {
        Self {
            topics: args.topics.clone(),
            all: args.all,
            patterns: args.patterns.clone(),
            exclude: args.exclude.clone(),
        }
    }

    pub fn selection(&self, namespace: &str) -> Result<Selection, SelectionError> {
        Selection::new(
            namespace,
            &self.topics,
            self.all,
            &self.patterns,
            self.exclude.as_deref(),
        )
    }

    /// Applies an accepted change; false when `name` is not a selection option.
    pub fn apply(&mut self, name: &str, value: &Value) -> bool {
        match (name, value) {
            ("topics", Value::StringArray(topics)) => self.topics = topics.clone(),
            ("all", Value::Bool(all)) => self.all = *all,
            ("regex", Value::StringArray(patterns)) => self.patterns = patterns.clone(),
            ("exclude", Value::String(exclude)) => {
                self.exclude = (!exclude.is_empty()).then(|| exclude.clone())
            }
            _ => return false,
        }
        true
    }
}

fn valid_patterns(value: &Value) -> Result<(), String> {
    let patterns: Vec<&str> = match value {
        Value::StringArray(patterns) => patterns.iter().map(String::as_str).collect(),
        Value::String(pattern) => vec![pattern.as_str()],
        _ => return Ok(()),
    };
    for pattern in patterns {
        regex::Regex::new(pattern).map_err(|error| format!("bad pattern {pattern:?}: {error}"))?;
    }
    Ok(())
}

/// The node's parameters for `args`.
pub fn declarations(args: &Args) -> Parameters {
    let text = |value: &dyn std::fmt::Display| Value::String(value.to_string());
    let optional = |value: Option<f64>| Value::Double(value.unwrap_or(0.0));
    Parameters::new([
        Declaration::new(
            "output",
            text(&args.output.display()),
            "Directory of the episode bags.",
        ),
        Declaration::new(
            "topics",
            Value::StringArray(args.topics.clone()),
            "Topics recorded by name (relative names are in the namespace); with regex and all \
             empty, none means the default set. Applies from the next discovery.",
        )
        .dynamic(),
        Declaration::new(
            "all",
            Value::Bool(args.all),
            "Every topic whose type the recorder knows. Applies from the next discovery.",
        )
        .dynamic(),
        Declaration::new(
            "regex",
            Value::StringArray(args.patterns.clone()),
            "Topics whose whole name matches one of these regular expressions. Applies from the \
             next discovery.",
        )
        .dynamic()
        .check("valid regular expressions", valid_patterns),
        Declaration::new(
            "exclude",
            Value::String(args.exclude.clone().unwrap_or_default()),
            "Topics whose whole name matches this regular expression are left out (empty: none). \
             Applies from the next discovery.",
        )
        .dynamic()
        .check("a valid regular expression", valid_patterns),
        Declaration::new(
            "compression",
            Value::choice(&args.compression),
            "MCAP chunk compression.",
        ),
        Declaration::new(
            "chunk_size",
            Value::Integer(i64::try_from(args.chunk_size).unwrap_or(i64::MAX)),
            "MCAP chunk size, bytes.",
        ),
        Declaration::new(
            "max_chunk_age",
            Value::Double(args.max_chunk_age),
            "Seconds before an open chunk is written out.",
        ),
        Declaration::new(
            "split_size_mb",
            optional(args.split_size_mb),
            "MB per .mcap file of an episode (0: no split).",
        ),
        Declaration::new(
            "split_duration",
            optional(args.split_duration),
            "Seconds per .mcap file of an episode (0: no split).",
        ),
        Declaration::new(
            "task",
            Value::String(args.task.clone()),
            "Default task text.",
        ),
        Declaration::new(
            "prefix",
            Value::String(args.prefix.clone()),
            "Episode directory name.",
        ),
        Declaration::new(
            "start",
            Value::Bool(args.start),
            "Recording started at once.",
        ),
        Declaration::new(
            "queue_mb",
            Value::Double(args.queue_mb),
            "Most MB of messages waiting for the writer.",
        ),
    ])
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[test]
    fn every_dynamic_parameter_is_a_selection_option() {
        let args = Args::parse_from(["recorder_node", "--topics", "joint_states"]);
        let mut options = SelectionOptions::from_args(&args);
        for declaration in declarations(&args).declarations() {
            assert_eq!(
                options.apply(declaration.name(), declaration.value()),
                !declaration.read_only(),
                "{}",
                declaration.name()
            );
        }
    }

    #[test]
    fn a_new_selection_follows_the_options() {
        let args = Args::parse_from(["recorder_node", "--topics", "joint_states"]);
        let mut options = SelectionOptions::from_args(&args);
        assert!(!options.selection("/").unwrap().wants("/clock"));
        options.apply("topics", &Value::StringArray(vec!["clock".into()]));
        let selection = options.selection("/").unwrap();
        assert!(selection.wants("/clock") && !selection.wants("/joint_states"));
        options.apply("all", &Value::Bool(true));
        options.apply("exclude", &Value::String("/camera/.*".into()));
        let selection = options.selection("/").unwrap();
        assert!(selection.wants("/tf") && !selection.wants("/camera/top/image_raw"));
    }

    #[test]
    fn bad_patterns_are_refused() {
        let args = Args::parse_from(["recorder_node"]);
        let mut parameters = declarations(&args);
        let (results, _) =
            parameters.set_each([("regex".to_owned(), Ok(Value::StringArray(vec!["(".into()])))]);
        assert!(
            results[0].reason.contains("bad pattern"),
            "{:?}",
            results[0]
        );
    }
}
