//! A node's ROS parameters made from its command-line options, so the two never disagree: a
//! parameter is named after its option (`--max-step` is `max_step`) and described by the option's
//! `--help` text. What only the parameter says (how a change at run time takes effect) is added
//! to that text; ranges come from the constants the option's parser checks too.

use clap::CommandFactory;

use super::store::{Declaration, Parameters, Value};

/// Options that are not settings of what the node does, so they have no parameter: `--help`,
/// `--version`, and the namespace (a node's parameters already live under it).
const NOT_PARAMETERS: [&str; 3] = ["help", "version", "namespace"];

/// The command-line options of one node, to declare its parameters from.
pub struct Options {
    command: clap::Command,
}

impl Options {
    /// The options of the node whose arguments are `A`.
    pub fn of<A: CommandFactory>() -> Self {
        let mut command = A::command();
        command.build();
        Self { command }
    }

    /// The options of subcommand `name` of the program whose arguments are `A` (with the
    /// program's global options).
    ///
    /// # Panics
    /// When the program has no such subcommand (a mistake its unit tests find).
    pub fn of_subcommand<A: CommandFactory>(name: &str) -> Self {
        let mut command = A::command();
        command.build();
        let command = command
            .find_subcommand(name)
            .unwrap_or_else(|| panic!("{} has no subcommand {name}", command.get_name()))
            .clone();
        Self { command }
    }

    /// The read-only parameter `name` of the option `--name` (with '-' for '_'), holding `value`,
    /// described by the option's help.
    ///
    /// # Panics
    /// When the node has no such option: a mistake in the node's code, which its
    /// `every_option_is_a_parameter` unit test finds.
    pub fn declare(&self, name: &str, value: Value) -> Declaration {
        Declaration::new(name, value, &self.help(name))
    }

    /// The help text of the option of parameter `name` (its long help where it has one).
    fn help(&self, name: &str) -> String {
        let arg = self
            .command
            .get_arguments()
            .find(|arg| parameter_name(arg).as_deref() == Some(name))
            .unwrap_or_else(|| panic!("{} has no option `{name}`", self.command.get_name()));
        let help = arg
            .get_long_help()
            .or_else(|| arg.get_help())
            .map(|help| {
                help.to_string()
                    .split_whitespace()
                    .collect::<Vec<_>>()
                    .join(" ")
            })
            .unwrap_or_default();
        // clap drops the full stop of a one-line help; a description is a sentence.
        if help.is_empty() || help.ends_with(['.', '!', '?']) {
            help
        } else {
            help + "."
        }
    }

    /// The options that should be parameters and are not among `parameters`, by parameter name.
    pub fn undeclared(&self, parameters: &Parameters) -> Vec<String> {
        self.command
            .get_arguments()
            .filter_map(parameter_name)
            .filter(|name| !NOT_PARAMETERS.contains(&name.as_str()))
            .filter(|name| parameters.get(name).is_none())
            .collect()
    }
}

/// The parameter name of an option: its long name with '_' (`--max-step` is `max_step`).
fn parameter_name(arg: &clap::Arg) -> Option<String> {
    arg.get_long().map(|long| long.replace('-', "_"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ros::NodeArgs;

    /// A node with two settings.
    #[derive(Debug, clap::Parser)]
    #[command(version)]
    struct Args {
        /// Control rate in Hz: one period per command.
        #[arg(long, default_value_t = 30.0)]
        rate: f64,
        /// Largest change of a joint target in one period, rad.
        ///
        /// Bigger changes are approached over several periods.
        #[arg(long, default_value_t = 0.1)]
        max_step: f64,
        #[command(flatten)]
        node: NodeArgs,
    }

    #[test]
    fn a_parameter_is_described_by_its_options_help() {
        let options = Options::of::<Args>();
        let rate = options.declare("rate", Value::Double(30.0));
        assert_eq!(rate.name(), "rate");
        assert_eq!(
            rate.description(),
            "Control rate in Hz: one period per command."
        );
        let max_step = options.declare("max_step", Value::Double(0.1));
        assert_eq!(
            max_step.description(),
            "Largest change of a joint target in one period, rad. Bigger changes are approached \
             over several periods."
        );
    }

    #[test]
    fn options_without_a_parameter_are_found() {
        let options = Options::of::<Args>();
        let only_rate = Parameters::new([options.declare("rate", Value::Double(30.0))]);
        assert_eq!(options.undeclared(&only_rate), ["max_step"]);
        let both = Parameters::new([
            options.declare("rate", Value::Double(30.0)),
            options.declare("max_step", Value::Double(0.1)),
        ]);
        assert!(options.undeclared(&both).is_empty());
    }

    #[test]
    #[should_panic(expected = "no option `speed`")]
    fn declaring_an_option_the_node_lacks_is_a_mistake() {
        Options::of::<Args>().declare("speed", Value::Double(1.0));
    }
}
