//! Calibration like LeRobot's: with torque off the user centres the arm (that pose becomes tick
//! 2047 through Homing_Offset), then sweeps every joint through its range while the extremes are
//! recorded; wrist_roll turns all the way round, so it keeps the full 0..4095. The result goes to
//! the servos' EPROM and to the LeRobot calibration file.

use std::{
    io::Write,
    sync::mpsc,
    time::{Duration, Instant},
};

use anyhow::{Context, Result};
use so101_core::robot::{JOINT_COUNT, JOINT_NAMES};

use crate::{
    args::{CalibrationArgs, PortArgs},
    arm::{open_bus, write_motor_calibration},
    bus::{BusError, ServoBus},
    calibration::{validate_motor, ArmCalibration, MotorCalibration, MAX_HOMING_OFFSET, MAX_TICKS},
    protocol::registers,
};

#[derive(Debug, Clone, clap::Args)]
pub struct CalibrateArgs {
    #[command(flatten)]
    pub port: PortArgs,
    #[command(flatten)]
    pub calibration: CalibrationArgs,
}

/// Tick value of the centred pose (half a turn).
const HALF_TURN: i32 = 2047;
const WRIST_ROLL: usize = 4;
/// Failed reads in a row after which the sweep gives up (about a second).
const MAX_FAILED_SAMPLES: u32 = 50;
/// A sweep smaller than this (ticks, ~9 degrees) is most likely a joint the user forgot.
const MIN_SWEEP: i32 = 100;

#[derive(Debug, thiserror::Error)]
pub enum CalibrateError {
    #[error("{joint} reads {raw} ticks at the centre: its homing offset would be {offset}, beyond +-{MAX_HOMING_OFFSET}. Turn the horn a little away from the end of its turn and start again")]
    OffsetOutOfRange {
        joint: &'static str,
        raw: i32,
        offset: i32,
    },
    #[error("{joint} moved only {min}..{max} ticks: sweep it through its whole range")]
    NoSweep {
        joint: &'static str,
        min: i32,
        max: i32,
    },
    #[error("the calibration would not be valid: {0}")]
    Invalid(String),
    #[error(transparent)]
    Bus(#[from] BusError),
}

/// One calibration in progress, on an open bus.
pub struct Calibration<'a> {
    bus: &'a mut ServoBus,
    ids: [u8; JOINT_COUNT],
    offsets: [i32; JOINT_COUNT],
    min: [i32; JOINT_COUNT],
    max: [i32; JOINT_COUNT],
}

impl<'a> Calibration<'a> {
    /// Torque off, EPROM unlocked, the old calibration cleared so raw ticks come back.
    pub fn begin(bus: &'a mut ServoBus, ids: [u8; JOINT_COUNT]) -> Result<Self, CalibrateError> {
        for id in ids {
            bus.write(id, registers::TORQUE_ENABLE, 0)?;
            bus.write(id, registers::LOCK, 0)?;
            write_motor_calibration(
                bus,
                &MotorCalibration {
                    id,
                    drive_mode: 0,
                    homing_offset: 0,
                    range_min: 0,
                    range_max: MAX_TICKS,
                },
            )?;
        }
        Ok(Self {
            bus,
            ids,
            offsets: [0; JOINT_COUNT],
            min: [i32::MAX; JOINT_COUNT],
            max: [i32::MIN; JOINT_COUNT],
        })
    }

    /// The arm is centred now: each joint's present raw position becomes its half turn.
    pub fn set_centre(&mut self) -> Result<(), CalibrateError> {
        let raw = self
            .bus
            .sync_read_register(registers::PRESENT_POSITION, &self.ids)?;
        for joint in 0..JOINT_COUNT {
            let offset = raw[joint] - HALF_TURN;
            if offset.abs() > MAX_HOMING_OFFSET {
                return Err(CalibrateError::OffsetOutOfRange {
                    joint: JOINT_NAMES[joint],
                    raw: raw[joint],
                    offset,
                });
            }
            self.offsets[joint] = offset;
            self.bus
                .write(self.ids[joint], registers::HOMING_OFFSET, offset)?;
        }
        Ok(())
    }

    /// One look at the arm during the sweep; returns the present positions (centred ticks).
    pub fn sample(&mut self) -> Result<[i32; JOINT_COUNT], CalibrateError> {
        let values = self
            .bus
            .sync_read_register(registers::PRESENT_POSITION, &self.ids)?;
        let positions: [i32; JOINT_COUNT] = std::array::from_fn(|joint| values[joint]);
        for (joint, position) in positions.iter().enumerate() {
            self.min[joint] = self.min[joint].min(*position);
            self.max[joint] = self.max[joint].max(*position);
        }
        Ok(positions)
    }

    pub fn ranges(&self) -> ([i32; JOINT_COUNT], [i32; JOINT_COUNT]) {
        (self.min, self.max)
    }

    /// Checks the sweep, writes offsets and ranges to EPROM, locks it; the calibration to save.
    pub fn finish(self) -> Result<ArmCalibration, CalibrateError> {
        let mut motors = [MotorCalibration {
            id: 0,
            drive_mode: 0,
            homing_offset: 0,
            range_min: 0,
            range_max: MAX_TICKS,
        }; JOINT_COUNT];
        for joint in 0..JOINT_COUNT {
            let (range_min, range_max) = if joint == WRIST_ROLL {
                (0, MAX_TICKS)
            } else if self.max[joint].saturating_sub(self.min[joint]) < MIN_SWEEP {
                return Err(CalibrateError::NoSweep {
                    joint: JOINT_NAMES[joint],
                    min: self.min[joint],
                    max: self.max[joint],
                });
            } else {
                (self.min[joint], self.max[joint])
            };
            motors[joint] = MotorCalibration {
                id: self.ids[joint],
                drive_mode: 0,
                homing_offset: self.offsets[joint],
                range_min,
                range_max,
            };
        }
        // Everything is checked before the first EPROM write: all servos or none.
        for (name, motor) in JOINT_NAMES.iter().zip(&motors) {
            validate_motor(name, motor).map_err(CalibrateError::Invalid)?;
        }
        for motor in &motors {
            write_motor_calibration(self.bus, motor)?;
            self.bus.write(motor.id, registers::LOCK, 1)?;
        }
        Ok(ArmCalibration { motors })
    }
}

/// The `calibrate` subcommand: prompts in the terminal, a live table during the sweep.
pub fn run(args: &CalibrateArgs) -> Result<()> {
    let path = args.calibration.path();
    let ids = match ArmCalibration::load(&path) {
        Ok(existing) => existing.ids(),
        Err(_) => [1, 2, 3, 4, 5, 6],
    };
    let mut bus = open_bus(&args.port.port, args.port.bus_config())?;
    let mut calibration = Calibration::begin(&mut bus, ids)?;
    println!(
        "Calibrating the SO-101 on {} (torque is off).",
        args.port.port.display()
    );
    super::wait_for_enter("Move the arm to the middle of its range of motion, then press Enter.")?;
    calibration.set_centre()?;
    println!(
        "Now move every joint except wrist_roll through its whole range of motion.\nThe table shows the range seen so far; press Enter when done."
    );
    let enter = enter_pressed();
    let mut last_print = Instant::now() - Duration::from_secs(1);
    let mut failures_in_a_row = 0;
    loop {
        // One lost answer must not throw the sweep away; a bus that stays silent ends it.
        match calibration.sample() {
            Ok(positions) => {
                failures_in_a_row = 0;
                if last_print.elapsed() >= Duration::from_millis(200) {
                    last_print = Instant::now();
                    print_sweep(&positions, calibration.ranges());
                }
            }
            Err(error) => {
                failures_in_a_row += 1;
                tracing::warn!(%error, "a read during the sweep failed");
                if failures_in_a_row >= MAX_FAILED_SAMPLES {
                    return Err(error.into());
                }
            }
        }
        if enter.try_recv().is_ok() {
            break;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    let result = calibration.finish()?;
    result.save(&path).with_context(|| {
        "the servos hold the new calibration, but the file could not be written"
    })?;
    println!(
        "\nCalibration written to the servos and to {}",
        path.display()
    );
    Ok(())
}

/// A channel that receives once the user pressed Enter (or stdin closed).
fn enter_pressed() -> mpsc::Receiver<()> {
    let (sender, receiver) = mpsc::channel();
    std::thread::spawn(move || {
        let mut line = String::new();
        let _ = std::io::stdin().read_line(&mut line);
        let _ = sender.send(());
    });
    receiver
}

fn print_sweep(
    positions: &[i32; JOINT_COUNT],
    (min, max): ([i32; JOINT_COUNT], [i32; JOINT_COUNT]),
) {
    let mut out = String::from("\n-------------------------------------------\n");
    out.push_str(&format!(
        "{:<15}{:>8}{:>8}{:>8}\n",
        "joint", "min", "pos", "max"
    ));
    for joint in 0..JOINT_COUNT {
        out.push_str(&format!(
            "{:<15}{:>8}{:>8}{:>8}\n",
            JOINT_NAMES[joint], min[joint], positions[joint], max[joint]
        ));
    }
    print!("{out}");
    let _ = std::io::stdout().flush();
}
