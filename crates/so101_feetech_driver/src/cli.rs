//! Command-line interface of the so101_feetech_driver binary: the driver node (default, its
//! options here) and the set-up tools `calibrate`, `setup-motors`, `scan`, `find-port` and
//! `install-udev` (each tool's options live with the tool, the shared ones in `args`).

use std::{path::PathBuf, time::Duration};

use so101_core::ros::NodeArgs;

use crate::{
    args::{parse_positive, CalibrationArgs, PortArgs},
    tools::{
        calibrate::CalibrateArgs, find_port::FindPortArgs, scan::ScanArgs,
        setup_motors::SetupMotorsArgs, udev::InstallUdevArgs,
    },
};

/// The physical SO-101 over its Feetech STS3215 servo bus, behind the same ROS 2 topics as the
/// simulation: publishes /joint_states (rad), obeys /joint_commands and
/// /forward_position_controller/commands, serves /torque_enable (std_srvs/SetBool), reports
/// /diagnostics at 1 Hz. With --leader: torque off, publishes /leader/joint_states.
#[derive(Debug, clap::Parser)]
#[command(version, args_conflicts_with_subcommands = true)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Option<Command>,
    #[command(flatten)]
    pub run: RunArgs,
}

#[derive(Debug, clap::Subcommand)]
pub enum Command {
    /// Calibrate interactively in a terminal (centre, then sweep); writes the servos' EPROM and the
    /// LeRobot calibration file.
    Calibrate(CalibrateArgs),
    /// Give each servo its id and the bus baud rate, one servo connected at a time.
    SetupMotors(SetupMotorsArgs),
    /// Find the servos on the bus: ids, models, firmware, at one or every baud rate.
    Scan(ScanArgs),
    /// Find the adapter's serial port: unplug it when asked; the port that disappears is the one.
    FindPort(FindPortArgs),
    /// Print or install a udev rule: /dev/so101_follower and /dev/so101_leader by the adapters'
    /// USB serial numbers, access for the dialout group, FTDI latency timer at 1 ms.
    InstallUdev(InstallUdevArgs),
}

/// Options of the driver node.
#[derive(Debug, Clone, clap::Args)]
pub struct RunArgs {
    #[command(flatten)]
    pub port: PortArgs,
    #[command(flatten)]
    pub calibration: CalibrationArgs,
    /// Bus cycles per second (each: one SYNC_READ of positions, one SYNC_WRITE of goals), or
    /// "max" for as fast as the bus allows.
    #[arg(long, default_value_t = CycleRate::Hz(DEFAULT_CYCLE_RATE_HZ), value_parser = parse_rate)]
    pub rate: CycleRate,
    /// Reads per second of velocity, load, voltage, temperature and current.
    #[arg(long, default_value_t = 10.0, value_parser = parse_telemetry_rate)]
    pub telemetry_rate: f64,
    /// Largest distance (rad) a goal may be from the joint's present position and from the
    /// previous goal (like LeRobot's max_relative_target); bigger jumps are approached over
    /// several cycles. Above 0 and at most 0.5.
    #[arg(long, default_value_t = 0.1, value_parser = parse_max_step)]
    pub max_step: f64,
    /// Seconds without a command after which the arm holds where it is; 0 turns the watchdog off.
    #[arg(long, default_value_t = 0.5, value_parser = parse_seconds)]
    pub command_timeout: f64,
    /// Max_Torque_Limit of the gripper, of 1000 (LeRobot's 500 keeps it from overheating).
    #[arg(long, default_value_t = 500, value_parser = clap::value_parser!(i32).range(1..=1000))]
    pub gripper_torque_limit: i32,
    /// Start with torque off (enable later with the torque_enable service).
    #[arg(long)]
    pub start_torque_off: bool,
    /// Leave torque on when the node exits (default: torque off, the arm goes limp; also after a
    /// panic or a second Ctrl-C).
    #[arg(long)]
    pub keep_torque_on_exit: bool,
    /// At start, write the calibration file's Homing_Offset and position limits into servos whose
    /// EPROM holds other values (default: refuse such servos, they may be another arm).
    #[arg(long)]
    pub write_calibration: bool,
    /// Seconds between reconnection attempts after the bus was lost.
    #[arg(long, default_value_t = 0.5, value_parser = parse_interval)]
    pub reconnect_interval: f64,
    /// Seconds without a successful position read (any servo silent) after which the port is
    /// closed and the arm reconnected.
    #[arg(long, default_value_t = 1.0, value_parser = parse_interval)]
    pub reopen_after: f64,
    /// Exit cleanly after this many seconds.
    #[arg(long, value_parser = parse_non_negative)]
    pub duration: Option<f64>,
    /// Write a JSON summary of the run (cycles/s, jitter, CPU, bus counters) here on exit.
    #[arg(long)]
    pub stats_json: Option<PathBuf>,
    #[command(flatten)]
    pub node: NodeArgs,
}

/// Bus cycles per second unless --rate says otherwise: each reads the positions and writes the
/// goals, so /joint_states comes at this rate, well above the policy's control rate
/// (so101_core::task::CONTROL_RATE_HZ) and teleop's command rate.
pub const DEFAULT_CYCLE_RATE_HZ: f64 = 200.0;

/// How often the control loop runs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum CycleRate {
    Hz(f64),
    Max,
}

impl CycleRate {
    pub fn period(self) -> Option<Duration> {
        match self {
            Self::Hz(hz) => Some(Duration::from_secs_f64(1.0 / hz)),
            Self::Max => None,
        }
    }
}

/// As --rate takes it: the number of Hz, or "max".
impl std::fmt::Display for CycleRate {
    fn fmt(&self, formatter: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Hz(hz) => write!(formatter, "{hz}"),
            Self::Max => formatter.write_str("max"),
        }
    }
}

fn parse_rate(text: &str) -> Result<CycleRate, String> {
    if text == "max" {
        return Ok(CycleRate::Max);
    }
    match text.parse::<f64>() {
        Ok(hz) if hz.is_finite() && hz > 0.0 && hz <= 5000.0 => Ok(CycleRate::Hz(hz)),
        _ => Err(format!(
            "{text:?} is not \"max\" or a rate above 0 and at most 5000 Hz"
        )),
    }
}

/// Largest --max-step: 0.5 rad (~29 degrees) a cycle is already far beyond any servo's speed.
pub const MAX_STEP_CEILING: f64 = 0.5;

fn parse_max_step(text: &str) -> Result<f64, String> {
    parse_positive(text).and_then(|step| {
        if step <= MAX_STEP_CEILING {
            Ok(step)
        } else {
            Err(format!(
                "{text:?} rad is more than {MAX_STEP_CEILING} rad a cycle: not a safety limit"
            ))
        }
    })
}

fn parse_non_negative(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(value) if value.is_finite() && (0.0..=1e9).contains(&value) => Ok(value),
        _ => Err(format!("{text:?} is not a number from 0 to 1e9")),
    }
}

/// Longest --command-timeout, s: an hour.
pub const MAX_COMMAND_TIMEOUT: f64 = 3600.0;

/// A timeout of the node: 0 to an hour.
fn parse_seconds(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(value) if (0.0..=MAX_COMMAND_TIMEOUT).contains(&value) => Ok(value),
        _ => Err(format!(
            "{text:?} is not a number of seconds from 0 to {MAX_COMMAND_TIMEOUT}"
        )),
    }
}

/// An interval of the node: 1 ms to an hour.
fn parse_interval(text: &str) -> Result<f64, String> {
    parse_seconds(text).and_then(|value| {
        if value >= 0.001 {
            Ok(value)
        } else {
            Err(format!("{text:?} is shorter than 1 ms"))
        }
    })
}

fn parse_telemetry_rate(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(value) if value.is_finite() && (0.01..=1000.0).contains(&value) => Ok(value),
        _ => Err(format!("{text:?} is not a rate from 0.01 to 1000 Hz")),
    }
}
