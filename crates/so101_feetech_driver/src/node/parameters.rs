//! The driver node's ROS parameters: its command-line settings, read-only, and the safety limits
//! that take effect while it runs (max_step, command_timeout). Names are the options' names with '_'.

use std::time::Duration;

use so101_core::{
    robot::{JointLimit, JOINT_COUNT},
    ros::parameters::{joint_declarations, Options, Parameters, Value},
};

use crate::{
    cli::{Cli, RunArgs, MAX_COMMAND_TIMEOUT, MAX_STEP_CEILING},
    safety::SafetyConfig,
};

/// The node's parameters for `args`, with the calibrated joint limits.
pub fn declarations(args: &RunArgs, limits: &[JointLimit; JOINT_COUNT]) -> Parameters {
    let options = Options::of::<Cli>();
    let text = |value: &dyn std::fmt::Display| Value::String(value.to_string());
    const NEXT_CYCLE: &str = "Takes effect at the next cycle.";
    let mut declarations = vec![
        options.declare("port", text(&args.port.port.display())),
        options.declare("baud", Value::Integer(i64::from(args.port.baud))),
        options.declare("retries", Value::Integer(i64::from(args.port.retries))),
        options.declare("bus_slack_ms", Value::Double(args.port.bus_slack_ms())),
        options.declare("robot_id", Value::String(args.calibration.robot_id.clone())),
        options
            .declare("calibration", text(&args.calibration.path().display()))
            .effect("Served as the file in use."),
        options.declare("leader", Value::Bool(args.calibration.leader)),
        options.declare("rate", text(&args.rate)),
        options.declare("telemetry_rate", Value::Double(args.telemetry_rate)),
        options
            .declare("max_step", Value::Double(args.max_step))
            .dynamic()
            .float_range(0.0, MAX_STEP_CEILING)
            .check("above 0", |value| match value.as_f64() {
                Some(step) if step > 0.0 => Ok(()),
                _ => Err("a step of 0 would never move the arm; above 0, please".to_owned()),
            })
            .effect(NEXT_CYCLE),
        options
            .declare("command_timeout", Value::Double(args.command_timeout))
            .dynamic()
            .float_range(0.0, MAX_COMMAND_TIMEOUT)
            .effect(NEXT_CYCLE),
        options.declare(
            "gripper_torque_limit",
            Value::Integer(i64::from(args.gripper_torque_limit)),
        ),
        options.declare("start_torque_off", Value::Bool(args.start_torque_off)),
        options.declare("keep_torque_on_exit", Value::Bool(args.keep_torque_on_exit)),
        options.declare("write_calibration", Value::Bool(args.write_calibration)),
        options.declare("reconnect_interval", Value::Double(args.reconnect_interval)),
        options.declare("reopen_after", Value::Double(args.reopen_after)),
    ];
    declarations.extend(joint_declarations(limits));
    Parameters::new(declarations)
}

/// `safety` with an accepted change applied; `None` when the change is not a safety limit.
pub fn safety_with(safety: SafetyConfig, name: &str, value: &Value) -> Option<SafetyConfig> {
    match (name, value.as_f64()?) {
        ("max_step", step) => Some(SafetyConfig {
            max_step: step,
            ..safety
        }),
        ("command_timeout", seconds) => Some(SafetyConfig {
            command_timeout: (seconds > 0.0).then(|| Duration::from_secs_f64(seconds)),
            ..safety
        }),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;
    use so101_core::{robot::JOINT_LIMITS, ros::parameters::documentation::assert_documented};

    fn parameters() -> Parameters {
        let cli = Cli::parse_from(["so101_feetech_driver", "--max-step", "0.05"]);
        declarations(&cli.run, &JOINT_LIMITS)
    }

    #[test]
    fn only_the_safety_limits_are_dynamic_and_each_applies() {
        let safety = SafetyConfig {
            max_step: 0.05,
            command_timeout: None,
        };
        for declaration in parameters().declarations() {
            let applied = safety_with(safety, declaration.name(), declaration.value());
            assert_eq!(
                applied.is_some(),
                !declaration.read_only(),
                "{}",
                declaration.name()
            );
        }
        let faster = safety_with(safety, "max_step", &Value::Double(0.2)).unwrap();
        assert_eq!(faster.max_step, 0.2);
        let watched = safety_with(safety, "command_timeout", &Value::Double(0.25)).unwrap();
        assert_eq!(watched.command_timeout, Some(Duration::from_millis(250)));
        let unwatched = safety_with(watched, "command_timeout", &Value::Double(0.0)).unwrap();
        assert_eq!(unwatched.command_timeout, None);
    }

    #[test]
    fn a_max_step_beyond_the_ceiling_or_zero_is_refused() {
        let mut parameters = parameters();
        let (results, changes) = parameters.set_each([
            ("max_step".to_owned(), Ok(Value::Double(0.8))),
            ("max_step".to_owned(), Ok(Value::Double(0.0))),
        ]);
        assert!(results.iter().all(|result| !result.successful));
        assert!(changes.is_empty());
        assert_eq!(parameters.get("max_step"), Some(&Value::Double(0.05)));
    }

    #[test]
    fn every_option_is_a_parameter() {
        // A run's length and where its summary goes are no settings of the arm.
        assert_eq!(
            Options::of::<Cli>().undeclared(&parameters()),
            ["duration", "stats_json"]
        );
        assert_documented(
            "so101_feetech_driver (also so101_leader_driver with --leader)",
            &parameters(),
        );
    }
}
