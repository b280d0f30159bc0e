//! A node's declared parameters: values, descriptions, which may change at run time and within
//! what, with the rules of rcl's parameter services (list by prefix and depth, set one by one or
//! atomically). Pure: the services in [`super::server`] carry it over DDS.

use std::collections::BTreeMap;

use so101_msgs::rcl_interfaces::{
    FloatingPointRange, IntegerRange, ListParametersResult, ParameterDescriptor,
    ParameterValue as ValueMessage, SetParametersResult,
};

pub use super::value::{type_name, Value};

/// A further rule on a value, beyond its type and range.
pub type Check = fn(&Value) -> Result<(), String>;

/// One parameter as a node declares it. Read-only unless [`Declaration::dynamic`].
#[derive(Debug, Clone)]
pub struct Declaration {
    name: String,
    value: Value,
    description: String,
    read_only: bool,
    range: Option<Range>,
    constraints: String,
    check: Option<Check>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Range {
    Float { from: f64, to: f64 },
    Integer { from: i64, to: i64 },
}

impl Declaration {
    /// A read-only parameter: it reports a setting the node was started with.
    pub fn new(name: &str, value: Value, description: &str) -> Self {
        Self {
            name: name.to_owned(),
            value,
            description: description.to_owned(),
            read_only: true,
            range: None,
            constraints: String::new(),
            check: None,
        }
    }

    /// The parameter may be set while the node runs (the node applies the new value).
    pub fn dynamic(mut self) -> Self {
        self.read_only = false;
        self
    }

    /// Inclusive bounds of a double parameter.
    pub fn float_range(mut self, from: f64, to: f64) -> Self {
        self.range = Some(Range::Float { from, to });
        self
    }

    /// Inclusive bounds of an integer parameter.
    pub fn integer_range(mut self, from: i64, to: i64) -> Self {
        self.range = Some(Range::Integer { from, to });
        self
    }

    /// A further rule, with its plain-words description (shown by `ros2 param describe`).
    pub fn check(mut self, constraints: &str, check: Check) -> Self {
        self.constraints = constraints.to_owned();
        self.check = Some(check);
        self
    }

    pub fn name(&self) -> &str {
        &self.name
    }

    pub fn value(&self) -> &Value {
        &self.value
    }

    pub fn description(&self) -> &str {
        &self.description
    }

    /// Adds what only the parameter says to the description (how a change takes effect).
    pub fn effect(mut self, text: &str) -> Self {
        if !self.description.is_empty() {
            self.description.push(' ');
        }
        self.description += text;
        self
    }

    pub fn read_only(&self) -> bool {
        self.read_only
    }

    /// The wire form of the description.
    pub fn descriptor(&self) -> ParameterDescriptor {
        let (floating_point_range, integer_range) = match self.range {
            Some(Range::Float { from, to }) => (
                vec![FloatingPointRange {
                    from_value: from,
                    to_value: to,
                    step: 0.0,
                }],
                vec![],
            ),
            Some(Range::Integer { from, to }) => (
                vec![],
                vec![IntegerRange {
                    from_value: from,
                    to_value: to,
                    step: 0,
                }],
            ),
            None => (vec![], vec![]),
        };
        ParameterDescriptor {
            name: self.name.clone(),
            kind: self.value.kind(),
            description: self.description.clone(),
            additional_constraints: self.constraints.clone(),
            read_only: self.read_only,
            dynamic_typing: false,
            floating_point_range,
            integer_range,
        }
    }

    /// `value` as this parameter would take it (an integer for a double parameter is taken as
    /// that double), or why not.
    fn accept(&self, value: Value) -> Result<Value, String> {
        if self.read_only {
            return Err(format!(
                "parameter '{}' is read-only: it is set when the node starts (its command-line option)",
                self.name
            ));
        }
        let value = match (&self.value, value) {
            (Value::Double(_), Value::Integer(integer)) => Value::Double(integer as f64),
            (_, value) => value,
        };
        if value.kind() != self.value.kind() {
            return Err(format!(
                "parameter '{}' is a {}, not a {}",
                self.name,
                type_name(self.value.kind()),
                type_name(value.kind())
            ));
        }
        match (self.range, &value) {
            (Some(Range::Float { from, to }), Value::Double(x)) if !(from..=to).contains(x) => {
                return Err(format!(
                    "parameter '{}' must be from {from} to {to}, not {x}",
                    self.name
                ))
            }
            (Some(Range::Integer { from, to }), Value::Integer(x)) if !(from..=to).contains(x) => {
                return Err(format!(
                    "parameter '{}' must be from {from} to {to}, not {x}",
                    self.name
                ))
            }
            _ => {}
        }
        if let Some(check) = self.check {
            check(&value).map_err(|reason| format!("parameter '{}': {reason}", self.name))?;
        }
        Ok(value)
    }
}

/// A parameter that took a new value.
#[derive(Debug, Clone, PartialEq)]
pub struct Change {
    pub name: String,
    pub value: Value,
}

/// Every parameter of one node.
#[derive(Debug, Clone, Default)]
pub struct Parameters {
    declared: BTreeMap<String, Declaration>,
}

impl Parameters {
    pub fn new(declarations: impl IntoIterator<Item = Declaration>) -> Self {
        Self {
            declared: declarations
                .into_iter()
                .map(|declaration| (declaration.name.clone(), declaration))
                .collect(),
        }
    }

    pub fn get(&self, name: &str) -> Option<&Value> {
        self.declared
            .get(name)
            .map(|declaration| &declaration.value)
    }

    pub fn declarations(&self) -> impl Iterator<Item = &Declaration> {
        self.declared.values()
    }

    /// rcl's ListParameters: names under any of `prefixes` (all when none), with fewer than
    /// `depth` '.' separators below the prefix, counting the one after it, as rclcpp counts (0:
    /// any depth), and the prefixes of those names.
    pub fn list(&self, prefixes: &[String], depth: u64) -> ListParametersResult {
        let within_depth = |rest: &str| depth == 0 || (rest.matches('.').count() as u64) < depth;
        let mut result = ListParametersResult::default();
        for name in self.declared.keys() {
            let listed = if prefixes.is_empty() {
                within_depth(name)
            } else {
                prefixes.iter().any(|prefix| {
                    name == prefix
                        || name
                            .strip_prefix(prefix.as_str())
                            .filter(|rest| rest.starts_with('.'))
                            .is_some_and(within_depth)
                })
            };
            if !listed {
                continue;
            }
            result.names.push(name.clone());
            if let Some((prefix, _)) = name.rsplit_once('.') {
                if !result.prefixes.iter().any(|known| known == prefix) {
                    result.prefixes.push(prefix.to_owned());
                }
            }
        }
        result
    }

    /// rcl's GetParameters: the values; none at all when a name is not declared (as rclcpp and
    /// rclpy answer).
    pub fn values(&self, names: &[String]) -> Vec<ValueMessage> {
        names
            .iter()
            .map(|name| self.get(name).map(Value::to_message))
            .collect::<Option<_>>()
            .unwrap_or_default()
    }

    /// rcl's GetParameterTypes: none at all when a name is not declared (as rclcpp answers).
    pub fn types(&self, names: &[String]) -> Vec<u8> {
        names
            .iter()
            .map(|name| self.get(name).map(Value::kind))
            .collect::<Option<_>>()
            .unwrap_or_default()
    }

    /// rcl's DescribeParameters; `Err` names the first undeclared parameter (rclcpp refuses the
    /// whole request then, and rclpy's `ros2 param describe` reports it).
    pub fn describe(&self, names: &[String]) -> Result<Vec<ParameterDescriptor>, String> {
        names
            .iter()
            .map(|name| {
                self.declared
                    .get(name)
                    .map(Declaration::descriptor)
                    .ok_or_else(|| not_declared(name))
            })
            .collect()
    }

    /// rcl's SetParameters: each parameter set or refused on its own, in order.
    pub fn set_each(
        &mut self,
        requests: impl IntoIterator<Item = (String, Result<Value, String>)>,
    ) -> (Vec<SetParametersResult>, Vec<Change>) {
        let mut results = Vec::new();
        let mut changes = Vec::new();
        for (name, value) in requests {
            match self.accept(&name, value) {
                Ok(value) => {
                    self.store(&name, value.clone());
                    changes.push(Change { name, value });
                    results.push(success());
                }
                Err(reason) => results.push(failure(reason)),
            }
        }
        (results, changes)
    }

    /// rcl's SetParametersAtomically: every parameter set, or none when any is refused.
    pub fn set_all(
        &mut self,
        requests: impl IntoIterator<Item = (String, Result<Value, String>)>,
    ) -> (SetParametersResult, Vec<Change>) {
        let accepted: Result<Vec<Change>, String> = requests
            .into_iter()
            .map(|(name, value)| {
                let value = self.accept(&name, value)?;
                Ok(Change { name, value })
            })
            .collect();
        match accepted {
            Ok(changes) => {
                for change in &changes {
                    self.store(&change.name, change.value.clone());
                }
                (success(), changes)
            }
            Err(reason) => (failure(reason), Vec::new()),
        }
    }

    fn accept(&self, name: &str, value: Result<Value, String>) -> Result<Value, String> {
        let declaration = self.declared.get(name).ok_or_else(|| not_declared(name))?;
        declaration.accept(value.map_err(|reason| format!("parameter '{name}': {reason}"))?)
    }

    fn store(&mut self, name: &str, value: Value) {
        if let Some(declaration) = self.declared.get_mut(name) {
            declaration.value = value;
        }
    }
}

fn not_declared(name: &str) -> String {
    format!(
        "parameter '{name}' is not declared by this node (`ros2 param list` shows those that are)"
    )
}

fn success() -> SetParametersResult {
    SetParametersResult {
        successful: true,
        reason: String::new(),
    }
}

fn failure(reason: String) -> SetParametersResult {
    SetParametersResult {
        successful: false,
        reason,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parameters() -> Parameters {
        Parameters::new([
            Declaration::new("rate", Value::Double(100.0), "control rate"),
            Declaration::new("max_step", Value::Double(0.1), "largest move")
                .dynamic()
                .float_range(0.001, 0.5),
            Declaration::new("cameras.rate", Value::Double(30.0), "camera rate").dynamic(),
            Declaration::new("cameras.top.size", Value::String("640x480".into()), "size"),
            Declaration::new("episodes", Value::Integer(3), "count")
                .dynamic()
                .integer_range(1, 10),
            Declaration::new("topics", Value::StringArray(vec!["/a".into()]), "topics")
                .dynamic()
                .check("absolute names", |value| match value.as_strings() {
                    Some(names) if names.iter().all(|name| name.starts_with('/')) => Ok(()),
                    _ => Err("every topic must be an absolute name".into()),
                }),
        ])
    }

    fn set(name: &str, value: Value) -> (String, Result<Value, String>) {
        (name.to_owned(), Ok(value))
    }

    #[test]
    fn list_follows_rcl_prefix_and_depth_rules() {
        let all = parameters().list(&[], 0);
        assert_eq!(all.names.len(), 6);
        assert_eq!(all.prefixes, ["cameras", "cameras.top"]);
        let top_level = parameters().list(&[], 1);
        assert_eq!(top_level.names, ["episodes", "max_step", "rate", "topics"]);
        // rclcpp counts the separator after the prefix: depth 1 lists the prefix itself only.
        assert!(parameters().list(&["cameras".into()], 1).names.is_empty());
        let cameras = parameters().list(&["cameras".into()], 2);
        assert_eq!(cameras.names, ["cameras.rate"]);
        let cameras = parameters().list(&["cameras".into()], 0);
        assert_eq!(cameras.names, ["cameras.rate", "cameras.top.size"]);
    }

    #[test]
    fn an_undeclared_name_empties_the_answer_as_in_rclcpp() {
        let parameters = parameters();
        let known = vec!["max_step".to_owned(), "rate".to_owned()];
        let values = parameters.values(&known);
        assert_eq!(values[0].kind, ValueMessage::DOUBLE);
        assert_eq!(values[0].double_value, 0.1);
        assert_eq!(parameters.types(&known), [ValueMessage::DOUBLE; 2]);
        let with_unknown = vec!["max_step".to_owned(), "nope".to_owned()];
        assert!(parameters.values(&with_unknown).is_empty());
        assert!(parameters.types(&with_unknown).is_empty());
        assert!(parameters
            .describe(&with_unknown)
            .unwrap_err()
            .contains("'nope'"));
    }

    #[test]
    fn descriptors_carry_read_only_and_ranges() {
        let parameters = parameters();
        let described = parameters
            .describe(&["rate".into(), "max_step".into(), "episodes".into()])
            .unwrap();
        assert!(described[0].read_only);
        assert!(!described[1].read_only);
        assert_eq!(described[1].floating_point_range[0].to_value, 0.5);
        assert_eq!(described[2].integer_range[0].from_value, 1);
    }

    #[test]
    fn set_each_applies_the_valid_and_refuses_the_rest_with_a_reason() {
        let mut parameters = parameters();
        let (results, changes) = parameters.set_each([
            set("max_step", Value::Double(0.2)),
            set("rate", Value::Double(50.0)),
            set("max_step", Value::Double(0.9)),
            set("max_step", Value::String("big".into())),
            set("episodes", Value::Integer(11)),
            set("topics", Value::StringArray(vec!["relative".into()])),
            set("nope", Value::Bool(true)),
        ]);
        let reasons: Vec<&str> = results
            .iter()
            .map(|result| result.reason.as_str())
            .collect();
        assert!(results[0].successful);
        assert!(reasons[1].contains("read-only"), "{reasons:?}");
        assert!(reasons[2].contains("from 0.001 to 0.5"), "{reasons:?}");
        assert!(
            reasons[3].contains("is a double, not a string"),
            "{reasons:?}"
        );
        assert!(reasons[4].contains("from 1 to 10"), "{reasons:?}");
        assert!(reasons[5].contains("absolute name"), "{reasons:?}");
        assert!(reasons[6].contains("not declared"), "{reasons:?}");
        assert_eq!(
            changes,
            [Change {
                name: "max_step".into(),
                value: Value::Double(0.2)
            }]
        );
        assert_eq!(parameters.get("max_step"), Some(&Value::Double(0.2)));
        assert_eq!(parameters.get("rate"), Some(&Value::Double(100.0)));
    }

    #[test]
    fn an_integer_sets_a_double_parameter() {
        let mut parameters = parameters();
        let (results, _) = parameters.set_each([set("cameras.rate", Value::Integer(15))]);
        assert!(results[0].successful);
        assert_eq!(parameters.get("cameras.rate"), Some(&Value::Double(15.0)));
    }

    #[test]
    fn set_all_is_all_or_nothing() {
        let mut parameters = parameters();
        let (result, changes) = parameters.set_all([
            set("max_step", Value::Double(0.3)),
            set("episodes", Value::Integer(99)),
        ]);
        assert!(!result.successful);
        assert!(changes.is_empty());
        assert_eq!(parameters.get("max_step"), Some(&Value::Double(0.1)));
        let (result, changes) = parameters.set_all([
            set("max_step", Value::Double(0.3)),
            set("episodes", Value::Integer(9)),
        ]);
        assert!(result.successful);
        assert_eq!(changes.len(), 2);
        assert_eq!(parameters.get("episodes"), Some(&Value::Integer(9)));
    }
}
