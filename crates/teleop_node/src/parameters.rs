//! The teleop node's ROS parameters: its command-line settings, read-only, and the speeds and the
//! step limit that take effect while it runs. Names are the options' names with '_'.

use so101_core::ros::parameters::{Options, Parameters, Value};

use crate::{
    cli::{
        Args, MAX_ANGULAR_SPEED, MAX_GRIPPER_SPEED, MAX_JOINT_SPEED, MAX_LINEAR_SPEED, MAX_STEP,
    },
    motion::Speeds,
};

/// What the control loop may change while it runs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tunables {
    pub speeds: Speeds,
    /// Largest change of a joint target in one period for absolute sources, rad.
    pub max_step: f64,
}

impl Tunables {
    pub fn from_args(args: &Args) -> Self {
        Self {
            speeds: Speeds {
                joint: args.joint_speed,
                linear: args.linear_speed,
                angular: args.angular_speed,
                gripper: args.gripper_speed,
            },
            max_step: args.max_step,
        }
    }

    /// Applies an accepted change; false when `name` is not one of these.
    pub fn apply(&mut self, name: &str, value: &Value) -> bool {
        let Some(value) = value.as_f64() else {
            return false;
        };
        let field = match name {
            "joint_speed" => &mut self.speeds.joint,
            "linear_speed" => &mut self.speeds.linear,
            "angular_speed" => &mut self.speeds.angular,
            "gripper_speed" => &mut self.speeds.gripper,
            "max_step" => &mut self.max_step,
            _ => return false,
        };
        *field = value;
        true
    }
}

/// The node's parameters for `args`.
pub fn declarations(args: &Args) -> Parameters {
    let options = Options::of::<Args>();
    let text = |value: &str| Value::String(value.to_owned());
    let tunable = |name: &str, value: f64, max: f64| {
        options
            .declare(name, Value::Double(value))
            .dynamic()
            .float_range(0.0, max)
            .check("above 0", |value| match value.as_f64() {
                Some(speed) if speed > 0.0 => Ok(()),
                _ => Err("must be above 0".to_owned()),
            })
    };
    let script = args
        .script
        .as_ref()
        .map(|path| path.display().to_string())
        .unwrap_or_default();
    Parameters::new([
        options.declare("source", Value::choice(&args.source)),
        options.declare("mode", Value::choice(&args.mode)),
        options.declare("rate", Value::Double(args.rate)),
        options.declare("sim_time", Value::Bool(args.sim_time)),
        options.declare("lockstep", Value::Bool(args.lockstep)),
        tunable("joint_speed", args.joint_speed, MAX_JOINT_SPEED),
        tunable("linear_speed", args.linear_speed, MAX_LINEAR_SPEED),
        tunable("angular_speed", args.angular_speed, MAX_ANGULAR_SPEED),
        tunable("gripper_speed", args.gripper_speed, MAX_GRIPPER_SPEED),
        tunable("max_step", args.max_step, MAX_STEP),
        options.declare("deadzone", Value::Double(args.deadzone)),
        options.declare("leader_topic", text(&args.leader_topic)),
        options.declare("leader_timeout", Value::Double(args.leader_timeout)),
        options.declare("script", text(&script)),
        options.declare("episodes", Value::Integer(i64::from(args.episodes))),
        options.declare(
            "seed",
            Value::Integer(i64::try_from(args.seed).unwrap_or(i64::MAX)),
        ),
        options.declare("waypoint_noise", Value::Double(args.waypoint_noise)),
        options.declare("action_noise", Value::Double(args.action_noise)),
        options.declare("no_reset", Value::Bool(args.no_reset)),
        options.declare("base_xyz", Value::DoubleArray(args.base_xyz.to_vec())),
        options.declare("bin_xyz", Value::DoubleArray(args.bin_xyz.to_vec())),
        options.declare("task", text(&args.task_text())),
        options.declare("sim_task", text(args.sim_task.name())),
    ])
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;
    use so101_core::ros::parameters::documentation::assert_documented;

    #[test]
    fn every_dynamic_parameter_is_a_tunable() {
        let args = Args::parse_from(["teleop_node", "--source", "expert"]);
        let mut tunables = Tunables::from_args(&args);
        for declaration in declarations(&args).declarations() {
            assert_eq!(
                tunables.apply(declaration.name(), declaration.value()),
                !declaration.read_only(),
                "{}",
                declaration.name()
            );
        }
        tunables.apply("gripper_speed", &Value::Double(4.0));
        assert_eq!(tunables.speeds.gripper, 4.0);
    }

    #[test]
    fn every_option_is_a_parameter() {
        let parameters = declarations(&Args::parse_from(["teleop_node"]));
        // Where a run's report goes and how long it lasts are no settings of the node.
        assert_eq!(
            Options::of::<Args>().undeclared(&parameters),
            ["report", "duration"]
        );
        assert_documented("teleop_node", &parameters);
    }
}
