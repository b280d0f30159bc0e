//! The teleop node's ROS parameters: its command-line settings, read-only, and the speeds and the
//! step limit that take effect while it runs. Names are the options' names with '_'.

use so101_core::ros::parameters::{Declaration, Parameters, Value};

use crate::{cli::Args, motion::Speeds};

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
    let text = |value: &str| Value::String(value.to_owned());
    let speed = |name: &str, value: f64, max: f64, description: &str| {
        Declaration::new(name, Value::Double(value), description)
            .dynamic()
            .float_range(0.0, max)
            .check("above 0", |value| match value.as_f64() {
                Some(speed) if speed > 0.0 => Ok(()),
                _ => Err("must be above 0".to_owned()),
            })
    };
    let base = args.base_xyz.to_vec();
    let bin = args.bin_xyz.to_vec();
    Parameters::new([
        Declaration::new("source", Value::choice(&args.source), "Input source."),
        Declaration::new(
            "mode",
            Value::choice(&args.mode),
            "Mode at start (joint or Cartesian).",
        ),
        Declaration::new(
            "rate",
            Value::Double(args.rate),
            "/joint_commands per second.",
        ),
        Declaration::new("sim_time", Value::Bool(args.sim_time), "Runs on /clock."),
        speed(
            "joint_speed",
            args.joint_speed,
            10.0,
            "Full joint speed in joint mode, rad/s.",
        ),
        speed(
            "linear_speed",
            args.linear_speed,
            1.0,
            "Full grasp-point speed in Cartesian mode, m/s.",
        ),
        speed(
            "angular_speed",
            args.angular_speed,
            10.0,
            "Full pitch and roll speed in Cartesian mode, rad/s.",
        ),
        speed(
            "gripper_speed",
            args.gripper_speed,
            20.0,
            "Full gripper speed, rad/s.",
        ),
        speed(
            "max_step",
            args.max_step,
            3.2,
            "Largest change of a joint target in one period for absolute sources (leader, \
             expert), rad.",
        ),
        Declaration::new(
            "deadzone",
            Value::Double(args.deadzone),
            "Gamepad dead zone.",
        ),
        Declaration::new(
            "leader_topic",
            text(&args.leader_topic),
            "Leader arm's joint states.",
        ),
        Declaration::new(
            "leader_timeout",
            Value::Double(args.leader_timeout),
            "Seconds without a leader message before the follower holds.",
        ),
        Declaration::new(
            "script",
            text(
                &args
                    .script
                    .as_ref()
                    .map(|path| path.display().to_string())
                    .unwrap_or_default(),
            ),
            "Scripted source's JSON-lines file.",
        ),
        Declaration::new(
            "episodes",
            Value::Integer(i64::from(args.episodes)),
            "Expert: episodes before exit (0: until stopped).",
        ),
        Declaration::new(
            "seed",
            Value::Integer(i64::try_from(args.seed).unwrap_or(i64::MAX)),
            "Expert: seed of its noise.",
        ),
        Declaration::new(
            "waypoint_noise",
            Value::Double(args.waypoint_noise),
            "Expert: noise on each waypoint, m.",
        ),
        Declaration::new(
            "action_noise",
            Value::Double(args.action_noise),
            "Expert: noise on every joint target, rad.",
        ),
        Declaration::new(
            "no_reset",
            Value::Bool(args.no_reset),
            "Expert: no /sim/reset per episode.",
        ),
        Declaration::new(
            "base_xyz",
            Value::DoubleArray(base),
            "Expert: the arm's base in the world, m.",
        ),
        Declaration::new(
            "bin_xyz",
            Value::DoubleArray(bin),
            "Expert: where the cube is dropped, m.",
        ),
        Declaration::new("task", text(&args.task), "Task text of the episodes."),
    ])
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

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
}
