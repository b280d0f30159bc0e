//! Motor set-up like LeRobot's: new servos all answer to id 1, so each is connected alone, found,
//! and given its joint's id and the bus baud rate. Gripper first, down to shoulder_pan.

use anyhow::{bail, Context, Result};
use so101_core::robot::{joint_index, JOINT_NAMES};

use super::scan::{baud_index, find_servos, probe_config};
use crate::{
    arm::open_bus,
    bus::{BusError, ServoBus},
    cli::SetupMotorsArgs,
    protocol::registers,
};

#[derive(Debug, thiserror::Error)]
pub enum SetupError {
    #[error("no servo answers on the bus: is exactly one connected and powered?")]
    NoServo,
    #[error("{0} servos answer (ids {1:?}): connect only the one to set up")]
    SeveralServos(usize, Vec<u8>),
    #[error("the bus baud rate {0} is not one the servos support")]
    UnsupportedBaud(u32),
    #[error(transparent)]
    Bus(#[from] BusError),
}

/// Gives the only servo on the bus `new_id` and the bus baud rate; returns its old id.
pub fn assign(bus: &mut ServoBus, new_id: u8, baud: u32) -> Result<u8, SetupError> {
    let index = baud_index(baud).ok_or(SetupError::UnsupportedBaud(baud))?;
    let servos = find_servos(bus, crate::protocol::MAX_ID)?;
    let old = match servos.as_slice() {
        [] => return Err(SetupError::NoServo),
        [only] => only.id,
        many => {
            return Err(SetupError::SeveralServos(
                many.len(),
                many.iter().map(|servo| servo.id).collect(),
            ))
        }
    };
    bus.write(old, registers::TORQUE_ENABLE, 0)?;
    bus.write(old, registers::LOCK, 0)?;
    if old != new_id {
        bus.write_unacknowledged(old, registers::ID, i32::from(new_id))?;
        bus.ping(new_id)?;
    }
    if bus.read(new_id, registers::BAUD_RATE)? != index {
        // Takes effect at once: the servo answers at the new rate from here on.
        bus.write_unacknowledged(new_id, registers::BAUD_RATE, index)?;
    }
    bus.write(new_id, registers::LOCK, 1)?;
    Ok(old)
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
        let mut bus = open_bus(&args.port.port, probe_config(args.port.bus_config()))?;
        match assign(&mut bus, id, args.port.baud) {
            Ok(old) => println!("'{name}' servo: id {old} -> {id}, baud {}", args.port.baud),
            Err(error) => bail!("'{name}' servo: {error}"),
        }
    }
    Ok(())
}
