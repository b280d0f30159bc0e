//! A parameter's value as the nodes use it, and its wire form (rcl_interfaces/ParameterValue).

use so101_msgs::rcl_interfaces::ParameterValue as ValueMessage;

/// A parameter's value (the rcl types the stack uses).
#[derive(Debug, Clone, PartialEq)]
pub enum Value {
    Bool(bool),
    Integer(i64),
    Double(f64),
    String(String),
    DoubleArray(Vec<f64>),
    StringArray(Vec<String>),
}

impl Value {
    /// A command-line choice as its name on the command line.
    pub fn choice(value: &impl clap::ValueEnum) -> Self {
        Value::String(
            value
                .to_possible_value()
                .map(|possible| possible.get_name().to_owned())
                .unwrap_or_default(),
        )
    }

    /// The rcl_interfaces/ParameterType constant.
    pub fn kind(&self) -> u8 {
        match self {
            Value::Bool(_) => ValueMessage::BOOL,
            Value::Integer(_) => ValueMessage::INTEGER,
            Value::Double(_) => ValueMessage::DOUBLE,
            Value::String(_) => ValueMessage::STRING,
            Value::DoubleArray(_) => ValueMessage::DOUBLE_ARRAY,
            Value::StringArray(_) => ValueMessage::STRING_ARRAY,
        }
    }

    pub fn as_f64(&self) -> Option<f64> {
        match self {
            Value::Double(value) => Some(*value),
            _ => None,
        }
    }

    pub fn as_bool(&self) -> Option<bool> {
        match self {
            Value::Bool(value) => Some(*value),
            _ => None,
        }
    }

    pub fn as_strings(&self) -> Option<&[String]> {
        match self {
            Value::StringArray(values) => Some(values),
            _ => None,
        }
    }

    /// The wire form.
    pub fn to_message(&self) -> ValueMessage {
        let mut message = ValueMessage {
            kind: self.kind(),
            ..ValueMessage::default()
        };
        match self {
            Value::Bool(value) => message.bool_value = *value,
            Value::Integer(value) => message.integer_value = *value,
            Value::Double(value) => message.double_value = *value,
            Value::String(value) => message.string_value = value.clone(),
            Value::DoubleArray(values) => message.double_array_value = values.clone(),
            Value::StringArray(values) => message.string_array_value = values.clone(),
        }
        message
    }

    /// The value a request carries; `Err` names a type no parameter here has (or NOT_SET).
    pub fn from_message(message: &ValueMessage) -> Result<Self, String> {
        Ok(match message.kind {
            ValueMessage::BOOL => Value::Bool(message.bool_value),
            ValueMessage::INTEGER => Value::Integer(message.integer_value),
            ValueMessage::DOUBLE => Value::Double(message.double_value),
            ValueMessage::STRING => Value::String(message.string_value.clone()),
            ValueMessage::DOUBLE_ARRAY => Value::DoubleArray(message.double_array_value.clone()),
            ValueMessage::STRING_ARRAY => Value::StringArray(message.string_array_value.clone()),
            ValueMessage::NOT_SET => {
                return Err("parameters of this node cannot be undeclared".to_owned())
            }
            other => {
                return Err(format!(
                    "no parameter of this node has type {}",
                    type_name(other)
                ))
            }
        })
    }
}

impl std::fmt::Display for Value {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Value::Bool(value) => write!(f, "{value}"),
            Value::Integer(value) => write!(f, "{value}"),
            Value::Double(value) => write!(f, "{value}"),
            Value::String(value) => write!(f, "{value:?}"),
            Value::DoubleArray(values) => write!(f, "{values:?}"),
            Value::StringArray(values) => write!(f, "{values:?}"),
        }
    }
}

/// The name `ros2 param describe` prints for a type constant.
pub fn type_name(kind: u8) -> &'static str {
    match kind {
        ValueMessage::NOT_SET => "not set",
        ValueMessage::BOOL => "boolean",
        ValueMessage::INTEGER => "integer",
        ValueMessage::DOUBLE => "double",
        ValueMessage::STRING => "string",
        ValueMessage::BYTE_ARRAY => "byte array",
        ValueMessage::BOOL_ARRAY => "boolean array",
        ValueMessage::INTEGER_ARRAY => "integer array",
        ValueMessage::DOUBLE_ARRAY => "double array",
        ValueMessage::STRING_ARRAY => "string array",
        _ => "unknown",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wire_values_round_trip_and_unset_is_refused() {
        for value in [
            Value::Bool(true),
            Value::Integer(-3),
            Value::Double(0.25),
            Value::String("top".into()),
            Value::DoubleArray(vec![1.0, 2.0]),
            Value::StringArray(vec!["/a".into()]),
        ] {
            assert_eq!(Value::from_message(&value.to_message()), Ok(value));
        }
        assert!(Value::from_message(&ValueMessage::default())
            .unwrap_err()
            .contains("cannot be undeclared"));
    }
}
