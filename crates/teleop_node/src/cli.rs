//! Command-line options of teleop_node.

use std::path::PathBuf;

use so101_core::{contract::topics, ros::NodeArgs, task::TaskKind};

use crate::{input::keyboard::KEY_HELP, motion::Mode};

/// Teleop's command rate, /joint_commands per second, unless --rate says otherwise. Not the
/// policy's control rate (so101_core::task::CONTROL_RATE_HZ), at which a dataset samples the arm.
pub const DEFAULT_COMMAND_RATE_HZ: f64 = 50.0;

/// Highest speeds and step an operator may set (at start or as parameters at run time).
pub const MAX_JOINT_SPEED: f64 = 10.0;
pub const MAX_LINEAR_SPEED: f64 = 1.0;
pub const MAX_ANGULAR_SPEED: f64 = 10.0;
pub const MAX_GRIPPER_SPEED: f64 = 20.0;
pub const MAX_STEP: f64 = 3.2;

/// Where the operator's input comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum SourceKind {
    /// The keyboard of this terminal.
    Keyboard,
    /// The first gamepad connected (Xbox, PlayStation, 8BitDo, Logitech, ... layouts).
    Gamepad,
    /// A leader arm on /leader/joint_states (so101_feetech_driver --leader).
    Leader,
    /// The scripted cube_to_bin expert (sim): resets, picks, places, judges, episode after episode.
    Expert,
    /// Timed inputs from a JSON-lines file (--script): tests and demonstrations.
    Scripted,
}

/// Teleoperation of the SO-101: gamepad, keyboard or leader arm in joint or Cartesian space, or a
/// scripted expert, publishing /joint_commands at a fixed rate and episode controls on
/// /episode/events.
#[derive(Debug, clap::Parser)]
#[command(version, about, long_about = None, after_help = KEY_HELP)]
pub struct Args {
    /// Input source.
    #[arg(long, value_enum, default_value = "keyboard")]
    pub source: SourceKind,
    /// Joint space or Cartesian end-effector space (x, y, z, pitch, roll of the gripper).
    #[arg(long, value_enum, default_value = "joint")]
    pub mode: Mode,
    /// Command rate: /joint_commands per second.
    #[arg(long, default_value_t = DEFAULT_COMMAND_RATE_HZ, value_parser = parse_positive("rate", 1000.0))]
    pub rate: f64,
    /// Run on sim time (/clock) instead of wall time: the rate and the expert's timing follow the
    /// simulation at any --speed.
    #[arg(long)]
    pub sim_time: bool,
    /// Expert: advance in step with a sim started with --lockstep --step-on-command. Each command
    /// is one of the sim's control periods (its --rate, 100 Hz by default), the next computed
    /// once that period's /joint_states, /cube/pose and /task/success are in, time read from the
    /// states' stamps:
    /// the expert sees every period's state whatever the machine's load, so its motion repeats
    /// for one seed, as fast as the machine goes.
    #[arg(long, conflicts_with_all = ["sim_time", "rate", "no_reset"])]
    pub lockstep: bool,
    /// Full joint speed in joint mode, rad/s.
    #[arg(long, default_value_t = 1.0, value_parser = parse_positive("speed", MAX_JOINT_SPEED))]
    pub joint_speed: f64,
    /// Full speed of the grasp point in Cartesian mode, m/s.
    #[arg(long, default_value_t = 0.1, value_parser = parse_positive("speed", MAX_LINEAR_SPEED))]
    pub linear_speed: f64,
    /// Full pitch and roll speed in Cartesian mode, rad/s.
    #[arg(long, default_value_t = 1.0, value_parser = parse_positive("speed", MAX_ANGULAR_SPEED))]
    pub angular_speed: f64,
    /// Full gripper speed, rad/s.
    #[arg(long, default_value_t = 2.0, value_parser = parse_positive("speed", MAX_GRIPPER_SPEED))]
    pub gripper_speed: f64,
    /// Largest change of a joint target in one period for absolute sources (leader, expert), rad.
    #[arg(long, default_value_t = 0.1, value_parser = parse_positive("step", MAX_STEP))]
    pub max_step: f64,
    /// Gamepad stick and trigger dead zone (0..0.9).
    #[arg(long, default_value_t = 0.12, value_parser = parse_deadzone)]
    pub deadzone: f64,
    /// Leader: topic of the leader arm's joint states.
    #[arg(long, default_value = topics::LEADER_JOINT_STATES)]
    pub leader_topic: String,
    /// Leader: seconds without a message after which the follower holds.
    #[arg(long, default_value_t = 0.5, value_parser = parse_positive("timeout", 60.0))]
    pub leader_timeout: f64,
    /// Scripted: the JSON-lines script.
    #[arg(long, required_if_eq("source", "scripted"))]
    pub script: Option<PathBuf>,
    /// Expert: number of episodes, then exit (0: until stopped).
    #[arg(long, default_value_t = 0)]
    pub episodes: u32,
    /// Expert: seed of its noise (each episode's start event carries a seed derived from it).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Expert: standard deviation of the noise on each waypoint's position, m.
    #[arg(long, default_value_t = 0.0, value_parser = parse_noise)]
    pub waypoint_noise: f64,
    /// Expert: standard deviation of the noise on every joint target, rad.
    #[arg(long, default_value_t = 0.0, value_parser = parse_noise)]
    pub action_noise: f64,
    /// Expert: do not call /sim/reset before each episode.
    #[arg(long)]
    pub no_reset: bool,
    /// Expert: the arm's base in the world frame of /cube/pose (the sim scene's by default), m.
    #[arg(long, default_value = "0,0,0.75", value_parser = so101_core::cli_values::parse_point)]
    pub base_xyz: [f64; 3],
    /// Expert: where to drop the cube (world frame; the sim scene's bin centre by default), m.
    #[arg(long, default_value = "0.10,-0.22,0.77", value_parser = so101_core::cli_values::parse_point)]
    pub bin_xyz: [f64; 3],
    /// Expert: the task it plays (the sim node's --task).
    #[arg(long, value_enum, default_value_t = TaskKind::CubeToBin)]
    pub sim_task: TaskKind,
    /// Task text of the episodes (the recorder's metadata, LeRobot's task); default: the
    /// --sim-task's.
    #[arg(long)]
    pub task: Option<String>,
    /// Write a JSON summary here at exit (the expert's episode results).
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Exit after this many seconds.
    #[arg(long, value_parser = parse_positive("duration", 1e9))]
    pub duration: Option<f64>,
    #[command(flatten)]
    pub node: NodeArgs,
}

impl Args {
    /// The episodes' task text: --task, else the --sim-task's description.
    pub fn task_text(&self) -> String {
        self.task
            .clone()
            .unwrap_or_else(|| self.sim_task.facts().description.to_owned())
    }
}

fn parse_positive(what: &'static str, max: f64) -> impl Fn(&str) -> Result<f64, String> + Clone {
    move |text| match text.parse::<f64>() {
        Ok(value) if value.is_finite() && value > 0.0 && value <= max => Ok(value),
        _ => Err(format!(
            "{text:?} is not a {what} above 0 and at most {max}"
        )),
    }
}

fn parse_deadzone(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(value) if (0.0..=0.9).contains(&value) => Ok(value),
        _ => Err(format!("{text:?} is not a dead zone from 0 to 0.9")),
    }
}

fn parse_noise(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(value) if (0.0..=0.5).contains(&value) => Ok(value),
        _ => Err(format!(
            "{text:?} is not a standard deviation from 0 to 0.5"
        )),
    }
}

#[cfg(test)]
mod tests {
    use clap::Parser;
    use so101_core::{expert::SIM_BIN_IN_WORLD, kinematics::SIM_BASE_IN_WORLD};

    use super::Args;

    #[test]
    fn the_expert_defaults_are_the_sim_scenes() {
        let args = Args::parse_from(["teleop_node"]);
        assert_eq!(args.base_xyz, SIM_BASE_IN_WORLD);
        assert_eq!(args.bin_xyz, SIM_BIN_IN_WORLD);
    }

    #[test]
    fn lockstep_keeps_its_own_clock_rate_and_resets() {
        let lockstep = ["teleop_node", "--source", "expert", "--lockstep"];
        assert!(Args::try_parse_from(lockstep).unwrap().lockstep);
        for other in [
            ["--sim-time"].as_slice(),
            &["--rate", "50"],
            &["--no-reset"],
        ] {
            let argv = lockstep.iter().chain(other);
            assert!(Args::try_parse_from(argv).is_err(), "{other:?}");
        }
    }
}
