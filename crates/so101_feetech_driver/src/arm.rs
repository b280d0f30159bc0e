//! The SO-101 on its bus: finding the six servos, configuring them the way LeRobot does, keeping
//! their EPROM calibration in line with the calibration file, and the per-cycle reads and writes.

use std::{path::Path, time::Duration};

use so101_core::robot::{JOINT_COUNT, JOINT_NAMES};

use crate::{
    bus::{BusConfig, BusError, Connector, SerialConnector, SerialTransport, ServoBus, Transport},
    calibration::{ArmCalibration, ArmRole, MotorCalibration},
    protocol::registers::{self, Register, STS3215_MODEL},
};

/// Phase bit that LeRobot clears (it flips the servo's direction sense).
const PHASE_DIRECTION_BIT: i32 = 0x10;
/// First and length of the telemetry block: Present_Velocity (58) .. Present_Current (69, 2 bytes).
const TELEMETRY_ADDRESS: u8 = 58;
const TELEMETRY_LEN: u8 = 13;
const GRIPPER: usize = 5;

#[derive(Debug, thiserror::Error)]
pub enum ArmError {
    #[error("cannot open serial port {path}: {source}")]
    Open {
        path: String,
        source: std::io::Error,
    },
    #[error("{joint} (servo id {id}) does not answer: {source}. Check power, cabling, the id (`scan`) and the baud rate")]
    NoServo {
        joint: &'static str,
        id: u8,
        source: BusError,
    },
    #[error("{joint} (servo id {id}) is model {model}, not an STS3215 ({STS3215_MODEL})")]
    WrongModel {
        joint: &'static str,
        id: u8,
        model: i32,
    },
    #[error("the servos' EPROM calibration differs from the calibration file ({}): not the arm this file belongs to (swapped, or recalibrated elsewhere?). Nothing was written; torque is off. Plug in the arm that matches, calibrate this one, or start the driver with --write-calibration to write the file's values into these servos", .differences.join("; "))]
    CalibrationDiffers { differences: Vec<String> },
    #[error("torque off not acknowledged by servo(s) {unacknowledged:?}: not reconfiguring servos that may hold torque")]
    TorqueNotOff { unacknowledged: Vec<u8> },
    #[error(transparent)]
    Bus(#[from] BusError),
}

/// What a servo says about itself.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct ServoInfo {
    pub id: u8,
    pub model: i32,
    pub firmware: (u8, u8),
}

/// Slow-changing state of one servo, read at a lower rate than positions.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Telemetry {
    /// ticks/s
    pub velocity: i32,
    /// 0.1 % of the maximum torque, signed.
    pub load: i32,
    pub voltage: f64,
    pub temperature: i32,
    /// Present_Current in mA (6.5 mA per unit).
    pub current_ma: f64,
    pub moving: bool,
    pub status: u8,
}

/// How to set the arm up.
#[derive(Debug, Clone)]
pub struct ArmSettings {
    pub bus: BusConfig,
    pub role: ArmRole,
    /// Max_Torque_Limit of the gripper (of 1000): LeRobot's 500 keeps it from overheating.
    pub gripper_torque_limit: i32,
}

/// Opens the port with the bus settings.
pub fn open_bus(path: &Path, config: BusConfig) -> Result<ServoBus, ArmError> {
    let mut serial = SerialConnector {
        path: path.to_owned(),
        baud: config.baud,
    };
    connect_bus(&mut serial, config)
}

/// Opens a bus through `connector`.
pub fn connect_bus<C: Connector>(
    connector: &mut C,
    config: BusConfig,
) -> Result<ServoBus<C::Transport>, ArmError> {
    let transport = connector.open().map_err(|source| ArmError::Open {
        path: connector.describe(),
        source,
    })?;
    Ok(ServoBus::new(transport, config))
}

/// Torque_Enable = 0 to every servo that can hear the bus, without knowing or asking them
/// (twice: nobody acknowledges a broadcast, so a lost one would go unnoticed).
pub fn broadcast_torque_off<T: Transport>(bus: &mut ServoBus<T>) -> Result<(), BusError> {
    let first = bus.broadcast_write(registers::TORQUE_ENABLE, 0);
    let second = bus.broadcast_write(registers::TORQUE_ENABLE, 0);
    first.or(second)
}

/// Opens the port afresh and broadcasts torque off: the way out when the arm is not connected.
pub fn reopen_and_broadcast_torque_off<C: Connector>(
    connector: &mut C,
    config: BusConfig,
) -> Result<(), ArmError> {
    let mut bus = connect_bus(connector, config)?;
    Ok(broadcast_torque_off(&mut bus)?)
}

/// What a torque-off reached: the servos that acknowledged it one by one, and whether the
/// broadcast for the others went out.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TorqueOffReport {
    /// Servos that did not acknowledge their own Torque_Enable = 0.
    pub unacknowledged: Vec<u8>,
    /// The broadcast to them could not be sent either (the port is gone).
    pub broadcast_failed: bool,
}

impl TorqueOffReport {
    pub fn confirmed(&self) -> bool {
        self.unacknowledged.is_empty()
    }
}

/// Pings servo `id` and reads its model and firmware.
pub fn identify<T: Transport>(bus: &mut ServoBus<T>, id: u8) -> Result<ServoInfo, BusError> {
    bus.ping(id)?;
    let model = bus.read(id, registers::MODEL_NUMBER)?;
    let major = bus.read(id, registers::FIRMWARE_MAJOR_VERSION)?;
    let minor = bus.read(id, registers::FIRMWARE_MINOR_VERSION)?;
    Ok(ServoInfo {
        id,
        model,
        firmware: (major as u8, minor as u8),
    })
}

/// Writes `value` only where the servo holds something else (EPROM cells wear out).
pub fn ensure<T: Transport>(
    bus: &mut ServoBus<T>,
    id: u8,
    register: Register,
    value: i32,
) -> Result<bool, BusError> {
    if bus.read(id, register)? == value {
        return Ok(false);
    }
    bus.write(id, register, value)?;
    Ok(true)
}

/// Writes a motor's calibration into its EPROM (Homing_Offset, position limits); the caller
/// unlocks the EPROM first.
pub fn write_motor_calibration<T: Transport>(
    bus: &mut ServoBus<T>,
    motor: &MotorCalibration,
) -> Result<bool, BusError> {
    let mut changed = ensure(bus, motor.id, registers::HOMING_OFFSET, motor.homing_offset)?;
    changed |= ensure(
        bus,
        motor.id,
        registers::MIN_POSITION_LIMIT,
        motor.range_min,
    )?;
    changed |= ensure(
        bus,
        motor.id,
        registers::MAX_POSITION_LIMIT,
        motor.range_max,
    )?;
    Ok(changed)
}

/// Whether the driver may bring the servos' EPROM calibration in line with the file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CalibrationWrite {
    /// The user asked for it (`--write-calibration`, or the calibration tool).
    Allowed,
    /// Servos whose EPROM calibration differs are refused, never overwritten.
    Refused,
}

/// The SO-101 on an open, configured bus.
pub struct Arm<T: Transport = SerialTransport> {
    pub bus: ServoBus<T>,
    pub calibration: ArmCalibration,
    pub servos: Vec<ServoInfo>,
    ids: [u8; JOINT_COUNT],
}

impl Arm<SerialTransport> {
    /// Opens the serial port and connects (see [`Arm::connect_on`]).
    pub fn connect(
        port: &Path,
        settings: &ArmSettings,
        calibration: ArmCalibration,
        write: CalibrationWrite,
    ) -> Result<Self, ArmError> {
        Arm::connect_on(open_bus(port, settings.bus)?, settings, calibration, write)
    }
}

impl<T: Transport> Arm<T> {
    /// Finds the six servos on `bus`, checks their EPROM calibration against `calibration`
    /// (written only when `write` allows it), and configures them. Torque is off afterwards.
    pub fn connect_on(
        bus: ServoBus<T>,
        settings: &ArmSettings,
        calibration: ArmCalibration,
        write: CalibrationWrite,
    ) -> Result<Self, ArmError> {
        let mut arm = Self::find_matching(bus, calibration, write)?;
        arm.configure(settings, write)?;
        Ok(arm)
    }

    /// Reconnects after the link was lost, without writing any EPROM: servos whose calibration
    /// differs from the file are not the arm we knew (another arm was plugged in) and are refused
    /// with their torque off. Settings that live in RAM are rewritten (a power cycle resets them)
    /// after torque off was broadcast on opening; torque on is left to the caller.
    pub fn reattach_on(
        bus: ServoBus<T>,
        settings: &ArmSettings,
        calibration: ArmCalibration,
    ) -> Result<Self, ArmError> {
        let mut arm = Self::find_matching(bus, calibration, CalibrationWrite::Refused)?;
        for id in arm.ids {
            arm.bus.write(id, registers::ACCELERATION, 254)?;
        }
        arm.bus.write(
            arm.ids[GRIPPER],
            registers::TORQUE_LIMIT,
            settings.gripper_torque_limit,
        )?;
        arm.bus.set_return_delay(Duration::ZERO);
        Ok(arm)
    }

    /// Finds the six servos and compares their EPROM calibration with the file: servos that hold
    /// another one are refused (torque off, nothing written) unless `write` allows writing it.
    fn find_matching(
        bus: ServoBus<T>,
        calibration: ArmCalibration,
        write: CalibrationWrite,
    ) -> Result<Self, ArmError> {
        let mut arm = Self::find(bus, calibration)?;
        let differences = arm.calibration_differences()?;
        if !differences.is_empty() && write == CalibrationWrite::Refused {
            arm.torque_off_everywhere();
            return Err(ArmError::CalibrationDiffers { differences });
        }
        Ok(arm)
    }

    /// Finds the six servos. Torque off is broadcast first: whoever hears the bus is limp before
    /// anything else happens (a driver killed before, an arm still holding after an unplug), even
    /// when a servo turns out to be missing and nothing further is done.
    fn find(mut bus: ServoBus<T>, calibration: ArmCalibration) -> Result<Self, ArmError> {
        if let Err(error) = broadcast_torque_off(&mut bus) {
            tracing::debug!(%error, "torque off broadcast on opening failed");
        }
        let ids = calibration.ids();
        let mut servos = Vec::with_capacity(JOINT_COUNT);
        for (joint, id) in ids.iter().enumerate() {
            let joint_name = JOINT_NAMES[joint];
            let info = identify(&mut bus, *id).map_err(|source| ArmError::NoServo {
                joint: joint_name,
                id: *id,
                source,
            })?;
            if info.model != i32::from(STS3215_MODEL) {
                return Err(ArmError::WrongModel {
                    joint: joint_name,
                    id: *id,
                    model: info.model,
                });
            }
            servos.push(info);
        }
        if servos
            .iter()
            .any(|info| info.firmware != servos[0].firmware)
        {
            tracing::warn!(?servos, "the servos run different firmware versions");
        }
        Ok(Self {
            bus,
            calibration,
            servos,
            ids,
        })
    }

    /// Where the servos' EPROM calibration (Homing_Offset, position limits) differs from the
    /// file, in words; empty when it matches.
    pub fn calibration_differences(&mut self) -> Result<Vec<String>, BusError> {
        let mut differences = Vec::new();
        for (joint, motor) in self.calibration.motors.iter().enumerate() {
            for (register, expected) in [
                (registers::HOMING_OFFSET, motor.homing_offset),
                (registers::MIN_POSITION_LIMIT, motor.range_min),
                (registers::MAX_POSITION_LIMIT, motor.range_max),
            ] {
                let found = self.bus.read(motor.id, register)?;
                if found != expected {
                    differences.push(format!(
                        "{} {} is {found}, the file says {expected}",
                        JOINT_NAMES[joint], register.name
                    ));
                }
            }
        }
        Ok(differences)
    }

    /// Torque off on every servo whatever fails: each one told and acknowledged in turn (one that
    /// does not answer does not stop the others), then a broadcast for any that did not confirm.
    pub fn torque_off_everywhere(&mut self) -> TorqueOffReport {
        let mut unacknowledged = Vec::new();
        for id in self.ids {
            if let Err(error) = self.bus.write(id, registers::TORQUE_ENABLE, 0) {
                tracing::warn!(id, %error, "torque off not acknowledged");
                unacknowledged.push(id);
            }
        }
        let broadcast_failed =
            !unacknowledged.is_empty() && broadcast_torque_off(&mut self.bus).is_err();
        TorqueOffReport {
            unacknowledged,
            broadcast_failed,
        }
    }

    pub fn ids(&self) -> &[u8; JOINT_COUNT] {
        &self.ids
    }

    /// LeRobot's so101 set-up: answer at once, full acceleration, position mode, its PID gains,
    /// and a torque-limited gripper.
    fn configure(
        &mut self,
        settings: &ArmSettings,
        write: CalibrationWrite,
    ) -> Result<(), ArmError> {
        // No servo is reconfigured while any of them may still hold torque.
        let torque_off = self.torque_off_everywhere();
        if !torque_off.confirmed() {
            return Err(ArmError::TorqueNotOff {
                unacknowledged: torque_off.unacknowledged,
            });
        }
        for (joint, (&id, motor)) in self.ids.iter().zip(&self.calibration.motors).enumerate() {
            let bus = &mut self.bus;
            bus.write(id, registers::LOCK, 0)?;
            ensure(bus, id, registers::RETURN_DELAY_TIME, 0)?;
            ensure(bus, id, registers::MAXIMUM_ACCELERATION, 254)?;
            bus.write(id, registers::ACCELERATION, 254)?;
            let phase = bus.read(id, registers::PHASE)?;
            if phase & PHASE_DIRECTION_BIT != 0 {
                bus.write(id, registers::PHASE, phase & !PHASE_DIRECTION_BIT)?;
            }
            ensure(bus, id, registers::OPERATING_MODE, 0)?;
            ensure(bus, id, registers::P_COEFFICIENT, 16)?;
            ensure(bus, id, registers::I_COEFFICIENT, 0)?;
            ensure(bus, id, registers::D_COEFFICIENT, 32)?;
            if joint == GRIPPER {
                ensure(
                    bus,
                    id,
                    registers::MAX_TORQUE_LIMIT,
                    settings.gripper_torque_limit,
                )?;
                // Torque_Limit is loaded from Max_Torque_Limit only at power-on.
                bus.write(id, registers::TORQUE_LIMIT, settings.gripper_torque_limit)?;
                ensure(bus, id, registers::PROTECTION_CURRENT, 250)?;
                ensure(bus, id, registers::OVERLOAD_TORQUE, 25)?;
            }
            // Compared before; written only when asked (a misread must not lead to a write).
            if write == CalibrationWrite::Allowed && write_motor_calibration(bus, motor)? {
                tracing::warn!(
                    joint = JOINT_NAMES[joint],
                    id,
                    "the servo's EPROM calibration differed from the calibration file: wrote the file's values (--write-calibration)"
                );
            }
            bus.write(id, registers::LOCK, 1)?;
        }
        // Only now do all servos answer at once: until here the factory delay may still apply.
        self.bus.set_return_delay(Duration::ZERO);
        tracing::info!(ids = ?self.ids, role = ?settings.role, "servos configured");
        Ok(())
    }

    /// One SYNC_READ of every present position (ticks).
    pub fn read_positions(&mut self) -> Result<[i32; JOINT_COUNT], BusError> {
        let values = self
            .bus
            .sync_read_register(registers::PRESENT_POSITION, &self.ids)?;
        Ok(std::array::from_fn(|joint| values[joint]))
    }

    /// One SYNC_WRITE of every goal (ticks).
    pub fn write_goals(&mut self, goals: &[i32; JOINT_COUNT]) -> Result<(), BusError> {
        let entries: Vec<(u8, i32)> = self
            .ids
            .iter()
            .copied()
            .zip(goals.iter().copied())
            .collect();
        self.bus.sync_write(registers::GOAL_POSITION, &entries)
    }

    /// Torque on on every servo, each acknowledged; stops at the first that fails (the caller
    /// then turns torque off everywhere: the arm is never left half stiff).
    pub fn torque_on(&mut self) -> Result<(), BusError> {
        for id in self.ids {
            self.bus.write(id, registers::TORQUE_ENABLE, 1)?;
        }
        Ok(())
    }

    /// One SYNC_READ of velocity, load, voltage, temperature, status, moving and current.
    pub fn read_telemetry(&mut self) -> Result<[Telemetry; JOINT_COUNT], BusError> {
        let replies = self
            .bus
            .sync_read(TELEMETRY_ADDRESS, TELEMETRY_LEN, &self.ids)?;
        let mut telemetry = [Telemetry::default(); JOINT_COUNT];
        for (slot, reply) in telemetry.iter_mut().zip(&replies) {
            *slot = telemetry_from_block(&reply.data)?;
        }
        Ok(telemetry)
    }
}

/// Decodes the 13-byte block that starts at Present_Velocity.
fn telemetry_from_block(block: &[u8]) -> Result<Telemetry, BusError> {
    let field = |register: Register| {
        let start = usize::from(register.address - TELEMETRY_ADDRESS);
        let bytes = block
            .get(start..start + usize::from(register.size))
            .unwrap_or_default();
        register.decode(bytes)
    };
    Ok(Telemetry {
        velocity: field(registers::PRESENT_VELOCITY)?,
        load: field(registers::PRESENT_LOAD)?,
        voltage: f64::from(field(registers::PRESENT_VOLTAGE)?) / 10.0,
        temperature: field(registers::PRESENT_TEMPERATURE)?,
        current_ma: f64::from(field(registers::PRESENT_CURRENT)?) * 6.5,
        moving: field(registers::MOVING)? != 0,
        status: field(registers::STATUS)? as u8,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn telemetry_block_is_decoded_field_by_field() {
        let mut block = [0u8; TELEMETRY_LEN as usize];
        block[0..2].copy_from_slice(&(100u16 | 1 << 15).to_le_bytes()); // velocity -100
        block[2..4].copy_from_slice(&(250u16 | 1 << 10).to_le_bytes()); // load -250
        block[4] = 121; // 12.1 V
        block[5] = 41; // deg C
        block[7] = 0x20; // status
        block[8] = 1; // moving
        block[11..13].copy_from_slice(&20u16.to_le_bytes());
        let telemetry = telemetry_from_block(&block).unwrap();
        assert_eq!(telemetry.velocity, -100);
        assert_eq!(telemetry.load, -250);
        assert!((telemetry.voltage - 12.1).abs() < 1e-9);
        assert_eq!(telemetry.temperature, 41);
        assert!(telemetry.moving);
        assert_eq!(telemetry.status, 0x20);
        assert!((telemetry.current_ma - 130.0).abs() < 1e-9);
        assert!(telemetry_from_block(&block[..4]).is_err());
    }
}
