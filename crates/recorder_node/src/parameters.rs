//! The recorder's ROS parameters: its command-line settings, read-only, and the topic selection
//! (topics, all, regex, exclude), which may change while it records: newly wanted topics are
//! subscribed at the next discovery (within a second), topics no longer wanted stop being written.

use so101_core::ros::parameters::{Options, Parameters, Value};

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
    let options = Options::of::<Args>();
    let text = |value: &dyn std::fmt::Display| Value::String(value.to_string());
    let optional = |value: Option<f64>| Value::Double(value.unwrap_or(0.0));
    const SELECTION_EFFECT: &str = "Applies from the next discovery.";
    Parameters::new([
        options.declare("output", text(&args.output.display())),
        options
            .declare("topics", Value::StringArray(args.topics.clone()))
            .dynamic()
            .effect(SELECTION_EFFECT),
        options
            .declare("all", Value::Bool(args.all))
            .dynamic()
            .effect(SELECTION_EFFECT),
        options
            .declare("regex", Value::StringArray(args.patterns.clone()))
            .dynamic()
            .check("valid regular expressions", valid_patterns)
            .effect(SELECTION_EFFECT),
        options
            .declare(
                "exclude",
                Value::String(args.exclude.clone().unwrap_or_default()),
            )
            .dynamic()
            .check("a valid regular expression", valid_patterns)
            .effect("Empty: none. Applies from the next discovery."),
        options.declare("compression", Value::choice(&args.compression)),
        options.declare(
            "chunk_size",
            Value::Integer(i64::try_from(args.chunk_size).unwrap_or(i64::MAX)),
        ),
        options.declare("max_chunk_age", Value::Double(args.max_chunk_age)),
        options
            .declare("split_size_mb", optional(args.split_size_mb))
            .effect("0: no split."),
        options
            .declare("split_duration", optional(args.split_duration))
            .effect("0: no split."),
        options.declare("task", Value::String(args.task.clone())),
        options.declare("prefix", Value::String(args.prefix.clone())),
        options.declare("start", Value::Bool(args.start)),
        options.declare("queue_mb", Value::Double(args.queue_mb)),
    ])
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;
    use so101_core::ros::parameters::documentation::assert_documented;

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

    #[test]
    fn every_option_is_a_parameter() {
        let parameters = declarations(&Args::parse_from(["recorder_node"]));
        // How long this run lasts is no setting of the recorder.
        assert_eq!(Options::of::<Args>().undeclared(&parameters), ["duration"]);
        assert_documented("recorder_node", &parameters);
    }
}
