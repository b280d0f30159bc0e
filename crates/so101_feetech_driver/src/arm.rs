//! The SO-101 on its bus: finding the six servos, configuring them the way LeRobot does, keeping
//! their EPROM calibration in line with the calibration file, and the per-cycle reads and writes.

use std::{path::Path, time::Duration};

use so101_core::robot::{JOINT_COUNT, JOINT_NAMES};

use crate::{
    bus::{BusConfig, BusError, SerialTransport, ServoBus},
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
        source: serialport::Error,
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
    #[error("the servos' EPROM calibration differs from the calibration file: these are not the servos that were connected (recalibrated or swapped?). Restart the driver to configure them")]
    CalibrationChanged,
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
    let transport = SerialTransport::open(path, config.baud).map_err(|source| ArmError::Open {
        path: path.display().to_string(),
        source,
    })?;
    Ok(ServoBus::new(transport, config))
}

/// Torque off on every servo that can hear the port, without knowing or asking them: opens the
/// port and broadcasts Torque_Enable = 0 (twice, nobody acknowledges a broadcast). For the way
/// out when the arm is not connected properly.
pub fn broadcast_torque_off(path: &Path, config: BusConfig) -> Result<(), ArmError> {
    let mut bus = open_bus(path, config)?;
    bus.broadcast_write(registers::TORQUE_ENABLE, 0)?;
    bus.broadcast_write(registers::TORQUE_ENABLE, 0)?;
    Ok(())
}

/// Pings servo `id` and reads its model and firmware.
pub fn identify(bus: &mut ServoBus, id: u8) -> Result<ServoInfo, BusError> {
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
pub fn ensure(
    bus: &mut ServoBus,
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
pub fn write_motor_calibration(
    bus: &mut ServoBus,
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

/// The SO-101 on an open, configured bus.
pub struct Arm {
    pub bus: ServoBus,
    pub calibration: ArmCalibration,
    pub servos: Vec<ServoInfo>,
    ids: [u8; JOINT_COUNT],
}

impl Arm {
    /// Opens the port, finds the six servos, configures them and brings their EPROM calibration in
    /// line with `calibration`. Torque is off afterwards.
    pub fn connect(
        port: &Path,
        settings: &ArmSettings,
        calibration: ArmCalibration,
    ) -> Result<Self, ArmError> {
        let mut arm = Self::find(port, settings, calibration)?;
        arm.configure(settings)?;
        Ok(arm)
    }

    /// Reconnects after the adapter came back, without touching torque: the servos kept their
    /// power, so an arm holding a pose keeps holding it. Settings that live in RAM are rewritten
    /// (a power cycle resets them). An EPROM calibration that differs means these are not the
    /// servos we knew: refused, never overwritten behind the user's back.
    pub fn reattach(
        port: &Path,
        settings: &ArmSettings,
        calibration: ArmCalibration,
    ) -> Result<Self, ArmError> {
        let mut arm = Self::find(port, settings, calibration)?;
        let mut same = true;
        for motor in arm.calibration.motors {
            let bus = &mut arm.bus;
            same &= bus.read(motor.id, registers::HOMING_OFFSET)? == motor.homing_offset
                && bus.read(motor.id, registers::MIN_POSITION_LIMIT)? == motor.range_min
                && bus.read(motor.id, registers::MAX_POSITION_LIMIT)? == motor.range_max;
        }
        if !same {
            tracing::warn!(
                "after reconnecting, the servos' calibration differs: configuring them again"
            );
            arm.configure(settings)?;
            return Ok(arm);
        }
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

    fn find(
        port: &Path,
        settings: &ArmSettings,
        calibration: ArmCalibration,
    ) -> Result<Self, ArmError> {
        let mut bus = open_bus(port, settings.bus)?;
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

    pub fn ids(&self) -> &[u8; JOINT_COUNT] {
        &self.ids
    }

    /// LeRobot's so101 set-up: answer at once, full acceleration, position mode, its PID gains,
    /// and a torque-limited gripper.
    fn configure(&mut self, settings: &ArmSettings) -> Result<(), BusError> {
        for (joint, (&id, motor)) in self.ids.iter().zip(&self.calibration.motors).enumerate() {
            let bus = &mut self.bus;
            bus.write(id, registers::TORQUE_ENABLE, 0)?;
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
            if write_motor_calibration(bus, motor)? {
                tracing::warn!(
                    joint = JOINT_NAMES[joint],
                    id,
                    "the servo's EPROM calibration differed from the calibration file: wrote the file's values"
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

    /// Torque on or off on every servo, each acknowledged.
    pub fn set_torque(&mut self, on: bool) -> Result<(), BusError> {
        for id in self.ids {
            self.bus
                .write(id, registers::TORQUE_ENABLE, i32::from(on))?;
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
