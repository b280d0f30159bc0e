//! An STS3215 servo bus on a pseudo-terminal, for running the SO-101 driver without hardware.
//!
//! `--calibration FILE` makes it the arm of that LeRobot calibration file, as LeRobot left it
//! configured: the emulated arm out of the box.
//!
//! Prints `PTY <path>` once the port is ready, then reads control commands from stdin (one per
//! line, each answered with one line: `ok`, `error: ...` or the JSON of `dump`).

use std::{
    io::{BufRead, Write},
    path::PathBuf,
    sync::mpsc::{self, RecvTimeoutError},
    time::Duration,
};

use anyhow::{bail, Context};
use clap::{Parser, ValueEnum};
use so101_core::{
    ros::{logging, shutdown::Shutdown},
    servo::{ArmServoParams, ServoModelChoice},
};
use so101_feetech_driver::calibration::ArmCalibration;
use so101_servo_emulator::{ControlCommand, Emulator, EmulatorConfig, Timing};

const CONTROL_HELP: &str = "Control commands on stdin, one per line:
  move ID TICKS        set a servo's shaft (absolute ticks), as a hand does with torque off
  silent ID on|off     the servo obeys but stops answering
  error ID BITS        status error bits of every reply (decimal or 0x hex)
  stall ID on|off      an obstacle blocks the shaft: it does not move, the position error and
                       the load build up (past Overload_Torque for Protection_Time: overload)
  overload ID          trip the servo's overload protection now: status error 0x20 and torque
                       off until torque is enabled again
  drop P               probability (0..=1) that a reply is lost
  corrupt P            probability (0..=1) that a reply has a flipped bit
  delay MS             extra delay before replies, in milliseconds
  garbage N            N random bytes before the next reply
  unplug INDEX         detach the servo in slot INDEX (0-based)
  plug INDEX           attach it again
  hangup SECONDS       the adapter disappears; it comes back at the same link after SECONDS
  clear                all faults off, obstacles taken away
  dump                 one JSON line with every slot
  quit                 stop (as do stdin EOF, SIGINT and SIGTERM)";

#[derive(Debug, Clone, Copy, ValueEnum)]
enum TimingArg {
    /// Replies at once.
    Instant,
    /// Replies when a half-duplex wire at --baud would deliver them, return delays included.
    Realistic,
}

/// Emulates daisy-chained Feetech STS3215 servos behind a USB-serial adapter, on a pty.
#[derive(Debug, Parser)]
#[command(name = "so101_servo_emulator", version, after_help = CONTROL_HELP)]
struct Cli {
    /// Servo ids, one slot each, in bus order (factory servos).
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "1,2,3,4,5,6",
        conflicts_with = "calibration"
    )]
    ids: Vec<u8>,
    /// A LeRobot calibration file: the six servos of that arm (ids, Homing_Offset, position
    /// limits) with LeRobot's configuration in their EPROM (Return_Delay_Time 0, position mode,
    /// P 16 / I 0 / D 32; gripper Max_Torque_Limit 500, Protection_Current 250, Overload_Torque 25),
    /// shafts in the middle of the calibrated ranges. A --state file that exists wins over it.
    #[arg(long, value_name = "FILE")]
    calibration: Option<PathBuf>,
    /// Slot indices (0-based) plugged in at start; default all.
    #[arg(long, value_delimiter = ',')]
    plugged: Option<Vec<usize>>,
    /// Symlink to the pty, kept across hangups (what the driver should open).
    #[arg(long)]
    link: Option<PathBuf>,
    /// JSON file where the servos' EPROM and shaft positions persist; when it exists, the servos
    /// power up from it (it wins over --calibration).
    #[arg(long)]
    state: Option<PathBuf>,
    #[arg(long, value_enum, default_value_t = TimingArg::Realistic)]
    timing: TimingArg,
    /// Bus speed for realistic timing.
    #[arg(long, default_value_t = 1_000_000)]
    baud: u32,
    /// Time constant of a shaft's approach to its goal, in milliseconds.
    #[arg(long, default_value_t = 40.0)]
    tau_ms: f64,
    /// Seed of the fault injection's random numbers.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Every servo's initial Return_Delay_Time register (units of 2 us; factory 250).
    #[arg(long)]
    return_delay: Option<u8>,
    /// Move the shafts as the STS3215 model: "sts3215" (published mechanics) or a parameter
    /// file (.json, `so101-sysid fit`'s); the registers the driver writes shape the motion, the
    /// file's dead zones become the servos' own. Without it: the first-order approach of --tau-ms.
    #[arg(long, value_parser = parse_servo_params)]
    servo_params: Option<ArmServoParams>,
}

fn parse_servo_params(text: &str) -> Result<ArmServoParams, String> {
    ServoModelChoice::parse_params(text).map_err(|error| error.to_string())
}

impl Cli {
    fn config(&self) -> anyhow::Result<EmulatorConfig> {
        let calibration = match &self.calibration {
            Some(path) => Some(ArmCalibration::load(path)?),
            None => None,
        };
        let ids = match &calibration {
            Some(calibration) => calibration.ids().to_vec(),
            None => self.ids.clone(),
        };
        let plugged = match &self.plugged {
            Some(indices) => {
                if let Some(bad) = indices.iter().find(|index| **index >= ids.len()) {
                    bail!("--plugged {bad}: there are only {} slots", ids.len());
                }
                Some((0..ids.len()).map(|slot| indices.contains(&slot)).collect())
            }
            None => None,
        };
        if self.baud == 0 {
            bail!("--baud must be positive");
        }
        let tau = Duration::try_from_secs_f64(self.tau_ms / 1000.0)
            .context("--tau-ms must be a non-negative number")?;
        Ok(EmulatorConfig {
            ids,
            calibration,
            plugged,
            timing: match self.timing {
                TimingArg::Instant => Timing::Instant,
                TimingArg::Realistic => Timing::Realistic { baud: self.baud },
            },
            tau,
            state_file: self.state.clone(),
            link: self.link.clone(),
            seed: self.seed,
            return_delay: self.return_delay,
            servo_params: self.servo_params,
        })
    }
}

fn main() -> anyhow::Result<()> {
    logging::init();
    let cli = Cli::parse();
    let shutdown = Shutdown::on_signals().context("cannot install signal handlers")?;
    let emulator = Emulator::start(cli.config()?)?;
    let mut stdout = std::io::stdout().lock();
    writeln!(stdout, "PTY {}", emulator.port_path().display())?;
    stdout.flush()?;

    // stdin is read on its own thread so signals are noticed while no line arrives.
    let (sender, lines) = mpsc::channel();
    std::thread::Builder::new()
        .name("stdin".into())
        .spawn(move || {
            for line in std::io::stdin().lock().lines() {
                if sender.send(line).is_err() {
                    break;
                }
            }
        })?;

    while !shutdown.is_requested() {
        let line = match lines.recv_timeout(Duration::from_millis(50)) {
            Ok(Ok(line)) => line,
            Ok(Err(error)) => {
                tracing::warn!(%error, "cannot read stdin; stopping");
                break;
            }
            Err(RecvTimeoutError::Timeout) => continue,
            Err(RecvTimeoutError::Disconnected) => break,
        };
        if line.trim().is_empty() {
            continue;
        }
        let (answer, quit) = match line.parse::<ControlCommand>() {
            Ok(ControlCommand::Quit) => ("ok".to_owned(), true),
            Ok(command) => match emulator.control(command) {
                Ok(answer) => (answer, false),
                Err(error) => (format!("error: {error}"), false),
            },
            Err(error) => (format!("error: {error}"), false),
        };
        // A reader that went away cannot be answered; stop as on EOF.
        if writeln!(stdout, "{answer}")
            .and_then(|()| stdout.flush())
            .is_err()
            || quit
        {
            break;
        }
    }
    drop(emulator);
    Ok(())
}
