//! docs/parameters.md's table of a node, written from the node's declarations: each node's unit
//! test compares the committed table with this one, so the page says what the node serves.

use so101_msgs::rcl_interfaces::ParameterValue as ValueMessage;

use super::store::Parameters;

/// The docs page, from the workspace root.
pub const PAGE: &str = "docs/parameters.md";

/// The table's rows (a line each, sorted by name): name, type, read-only or dynamic, description
/// with the range and constraints.
pub fn markdown_rows(parameters: &Parameters) -> String {
    let mut out = String::new();
    for declaration in parameters.declarations() {
        let descriptor = declaration.descriptor();
        let access = if descriptor.read_only {
            "read-only"
        } else {
            "**dynamic**"
        };
        let mut description = descriptor.description.clone();
        if let Some(range) = descriptor.floating_point_range.first() {
            description += &format!(" Range {} to {}.", range.from_value, range.to_value);
        }
        if let Some(range) = descriptor.integer_range.first() {
            description += &format!(" Range {} to {}.", range.from_value, range.to_value);
        }
        if !descriptor.additional_constraints.is_empty() {
            description += &format!(" Constraints: {}.", descriptor.additional_constraints);
        }
        out += &format!(
            "| `{}` | {} | {access} | {} |\n",
            descriptor.name,
            short_type_name(descriptor.kind),
            description.replace('|', "\\|")
        );
    }
    out
}

fn short_type_name(kind: u8) -> &'static str {
    match kind {
        ValueMessage::BOOL => "bool",
        ValueMessage::INTEGER => "integer",
        ValueMessage::DOUBLE => "double",
        ValueMessage::STRING => "string",
        ValueMessage::INTEGER_ARRAY => "integer[]",
        ValueMessage::DOUBLE_ARRAY => "double[]",
        ValueMessage::STRING_ARRAY => "string[]",
        ValueMessage::BOOL_ARRAY => "bool[]",
        _ => "byte[]",
    }
}

/// The rows of section `## {heading}` of `page` (the text of docs/parameters.md).
pub fn documented_rows(page: &str, heading: &str) -> Option<String> {
    let section = page.split(&format!("\n## {heading}\n")).nth(1)?;
    let section = section.split("\n## ").next().unwrap_or(section);
    Some(
        section
            .lines()
            .filter(|line| line.starts_with("| `"))
            .map(|line| format!("{line}\n"))
            .collect(),
    )
}

/// Asserts that docs/parameters.md's section `heading` lists exactly `parameters`, as
/// [`markdown_rows`] writes them; prints the rows to paste where it does not. For unit tests.
///
/// # Panics
/// When the page differs, or cannot be read.
pub fn assert_documented(heading: &str, parameters: &Parameters) {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../docs/parameters.md");
    let page = std::fs::read_to_string(path)
        .unwrap_or_else(|error| panic!("cannot read {PAGE} ({path}): {error}"));
    let expected = markdown_rows(parameters);
    let documented = documented_rows(&page, heading).unwrap_or_default();
    assert!(
        documented == expected,
        "{PAGE}, section \"{heading}\", differs from what the node serves; its rows are:\n{expected}"
    );
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ros::parameters::{Declaration, Value};

    #[test]
    fn rows_say_type_access_range_and_constraints() {
        let parameters = Parameters::new([
            Declaration::new("rate", Value::Double(30.0), "Control rate, Hz."),
            Declaration::new("max_step", Value::Double(0.1), "Largest step | rad.")
                .dynamic()
                .float_range(0.0, 0.5)
                .check("above 0", |_| Ok(())),
        ]);
        assert_eq!(
            markdown_rows(&parameters),
            "| `max_step` | double | **dynamic** | Largest step \\| rad. Range 0 to 0.5. Constraints: above 0. |\n\
             | `rate` | double | read-only | Control rate, Hz. |\n"
        );
    }

    #[test]
    fn a_section_is_read_up_to_the_next_heading() {
        let page = "# P\n\n## a_node (also b)\n\n| parameter |\n|---|\n| `x` | double |\n\n## c\n| `y` |\n";
        assert_eq!(
            documented_rows(page, "a_node (also b)").as_deref(),
            Some("| `x` | double |\n")
        );
        assert_eq!(documented_rows(page, "missing"), None);
    }
}
