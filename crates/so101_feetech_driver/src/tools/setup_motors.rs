//! Motor set-up like LeRobot's: new servos all answer to id 1, so each is connected alone, found at
//! whatever baud rate it speaks, and given its joint's id and the bus baud rate. Gripper first,
//! down to shoulder_pan.

use std::path::Path;

use anyhow::{bail, Context, Result};
use so101_core::robot::{joint_index, JOINT_NAMES};

use super::scan::{find_servos, probe_config};
use crate::{
    args::PortArgs,
    arm::{open_bus, ArmError},
    bus::{BusConfig, BusError, ServoBus},
    protocol::{
        registers::{self, baud_index, BAUD_RATES},
        MAX_ID,
    },
};

#[derive(Debug, Clone, clap::Args)]
pub struct SetupMotorsArgs {
    #[command(flatten)]
    pub port: PortArgs,
    /// Set up only these joints (default: all, gripper first like LeRobot).
    #[arg(long, value_delimiter = ',')]
    pub joints: Vec<String>,
}

#[derive(Debug, thiserror::Error)]
pub enum SetupError {
    #[error("no servo answers at any baud rate: is exactly one connected and powered?")]
    NoServo,
    #[error("{0} servos answer (ids {1:?}): connect only the one to set up")]
    SeveralServos(usize, Vec<u8>),
    #[error("servo id {id} is model {model}, not an STS3215 (777)")]
    WrongModel { id: u8, model: i32 },
    #[error("the bus baud rate {0} is not one the servos support")]
    UnsupportedBaud(u32),
    #[error(transparent)]
    Open(#[from] ArmError),
    #[error(transparent)]
    Bus(#[from] BusError),
}

/// Finds the only servo on the bus (trying `target_baud` first, then every rate the servos
/// support), gives it `new_id` and `target_baud`, and checks it answers there. Returns its old id.
pub fn assign(
    port: &Path,
    config: BusConfig,
    new_id: u8,
    target_baud: u32,
) -> Result<u8, SetupError> {
    let target_index = baud_index(target_baud).ok_or(SetupError::UnsupportedBaud(target_baud))?;
    // Searching pings many absent ids, so it waits briefly and never retries; the writes to the
    // servo that was found use the full settings (a reply late under load must not end the set-up).
    let probe = |baud: u32| open_bus(port, probe_config(BusConfig { baud, ..config }));
    let open = |baud: u32| open_bus(port, BusConfig { baud, ..config });
    let bauds = std::iter::once(target_baud).chain(
        BAUD_RATES
            .iter()
            .map(|(_, baud)| *baud)
            .filter(|b| *b != target_baud),
    );
    let mut found = None;
    for baud in bauds {
        let mut bus = probe(baud)?;
        match find_servos(&mut bus, MAX_ID, BusConfig { baud, ..config })?.as_slice() {
            [] => continue,
            [only] => {
                found = Some((baud, *only));
                break;
            }
            many => {
                return Err(SetupError::SeveralServos(
                    many.len(),
                    many.iter().map(|servo| servo.id).collect(),
                ))
            }
        }
    }
    let (baud, servo) = found.ok_or(SetupError::NoServo)?;
    if servo.model != i32::from(registers::STS3215_MODEL) {
        return Err(SetupError::WrongModel {
            id: servo.id,
            model: servo.model,
        });
    }
    let mut bus = open(baud)?;
    bus.write(servo.id, registers::TORQUE_ENABLE, 0)?;
    bus.write(servo.id, registers::LOCK, 0)?;
    if servo.id != new_id {
        bus.write_unacknowledged(servo.id, registers::ID, i32::from(new_id))?;
        bus.ping(new_id)?;
    }
    let mut bus: ServoBus = if baud != target_baud {
        // Takes effect at once: from here on the servo speaks the new rate.
        bus.write_unacknowledged(new_id, registers::BAUD_RATE, target_index)?;
        drop(bus);
        let mut bus = open(target_baud)?;
        bus.ping(new_id)?;
        bus
    } else {
        bus
    };
    bus.write(new_id, registers::LOCK, 1)?;
    Ok(servo.id)
}

pub fn run(args: &SetupMotorsArgs) -> Result<()> {
    let joints: Vec<usize> = if args.joints.is_empty() {
        (0..JOINT_NAMES.len()).rev().collect()
    } else {
        args.joints
            .iter()
            .map(|name| {
                joint_index(name)
                    .with_context(|| format!("unknown joint {name:?} (expected {JOINT_NAMES:?})"))
            })
            .collect::<Result<_>>()?
    };
    for joint in joints {
        let name = JOINT_NAMES[joint];
        let id = joint as u8 + 1;
        super::wait_for_enter(&format!(
            "Connect the controller board to the '{name}' servo ONLY, then press Enter."
        ))?;
        match assign(&args.port.port, args.port.bus_config(), id, args.port.baud) {
            Ok(old) => println!("'{name}' servo: id {old} -> {id}, baud {}", args.port.baud),
            Err(error) => bail!("'{name}' servo: {error}"),
        }
    }
    Ok(())
}
