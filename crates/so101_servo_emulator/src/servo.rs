//! One emulated STS3215: its 256-byte control table and a model of the shaft.
//!
//! Only position mode is modelled. By default the shaft approaches the goal exponentially with
//! time constant `tau`; Acceleration, Goal_Time and Goal_Velocity are stored but do not shape the
//! motion. With [`ServoModel::set_dynamics`] it moves as the STS3215 model of so101_core::servo
//! says, from the registers in its table (P/D/I, Acceleration, Goal_Velocity, Torque_Limit, the
//! dead zones, the overload settings) and the given mechanics and load ([`crate::dynamics`]).
//!
//! Positions, as the servo has them: the magnetic encoder reads the shaft in 0..=4095 (a hand
//! turning it past the seam wraps it); Present_Position = encoder - Homing_Offset, NOT wrapped, so
//! it spans -2047..=6142 and is sign-magnitude with the sign at bit 15 (a shaft at 30 with offset
//! 100 reads -70, bytes `70 | 0x8000`). Goals are in the same frame and clamped to the position
//! limits (a goal the servo set itself to hold where it is, when torque came on without a goal,
//! is not). The motor never drives the shaft across the encoder's seam: a goal beyond it is
//! approached up to the seam.
//!
//! Overload protection: while torque is on and |Present_Load| stays above Overload_Torque (percent
//! of full torque) for Protection_Time (units of 10 ms), the servo latches the overload error
//! (0x20) in its status packets and Status register and, if Unloading_Condition has the overload
//! bit (0x20; factory setting), drops its torque (Torque_Enable reads 0). Enabling torque again
//! clears it. An obstacle (`set_stalled`) keeps the shaft from moving, so the position error and
//! the load build up.
//!
//! Present_Current is sign-magnitude at bit 15 (Feetech's own SMS_STS library decodes it so),
//! its sign that of the load.

use std::time::Duration;

use crate::dynamics::ShaftDynamics;

use so101_core::servo::{JointLoad, ServoMechanics, ServoRegisters, TICKS_PER_REVOLUTION};
use so101_feetech_driver::{
    calibration::{MotorCalibration, MAX_TICKS},
    protocol::{
        registers::{self as reg, Register, RegisterError, EPROM_END, STS3215_MODEL},
        ServoErrors, MAX_ID,
    },
};

/// Time constant of the shaft's approach to the goal unless configured otherwise.
pub const DEFAULT_TAU: Duration = Duration::from_millis(40);
/// Where a factory servo's shaft rests: the middle of the revolution.
pub const DEFAULT_ACTUAL: f64 = 2048.0;

/// Moving (66) reads 1 while the position error exceeds this many ticks.
const MOVING_THRESHOLD: f64 = 2.0;
/// Present_Load (0.1 % of full torque) per tick of position error: 500 ticks saturate it.
const LOAD_PER_TICK: f64 = 2.0;
const MAX_LOAD: f64 = 1000.0;
/// Present_Current (units of 6.5 mA) at rest, and its growth with load.
const IDLE_CURRENT: f64 = 3.0;
const CURRENT_PER_LOAD: f64 = 0.25;
const EPROM_LEN: usize = EPROM_END as usize;
/// Protection_Time counts in units of 10 ms.
const PROTECTION_TIME_UNIT: f64 = 0.010;
/// Present_Load counts in 0.1 %, Overload_Torque in 1 %.
const LOAD_PER_PERCENT: f64 = 10.0;
/// While the load is above the overload threshold and the shaft is moving, time advances in steps
/// this long (seconds), so the moment the load falls back is found.
const OVERLOAD_STEP: f64 = 0.001;
/// Unloading_Condition bit: drop torque on overload.
const UNLOAD_ON_OVERLOAD: i32 = 0x20;

/// Bytes the servo computes itself; writes to them are ignored.
fn is_read_only(address: usize) -> bool {
    matches!(address, 0 | 1 | 3 | 4 | 56..=63 | 65 | 66 | 69 | 70)
}

#[derive(Debug, Clone)]
pub struct ServoModel {
    table: [u8; 256],
    /// What the servo's flash holds: EPROM bytes written while Lock was 0. A write with Lock = 1
    /// changes the live table only, and is lost at the next power cycle.
    flash: [u8; EPROM_LEN],
    flash_dirty: bool,
    /// Absolute shaft position in encoder ticks, 0..4096 (a hand wraps it at the seam).
    actual: f64,
    /// Ticks per second over the last physics step.
    velocity: f64,
    tau: Duration,
    /// Error bits reported in every status packet (fault injection).
    pub errors: u8,
    /// A REG_WRITE waiting for ACTION.
    staged: Option<(u8, Vec<u8>)>,
    /// The goal was set by the servo itself (torque enabled without a goal) to hold the shaft
    /// where it was; the position limits do not apply to it.
    holding: bool,
    /// An obstacle blocks the shaft: the motor cannot move it.
    stalled: bool,
    /// How long the load has been above Overload_Torque without a break, in seconds.
    overloaded_for: f64,
    /// The overload protection tripped: error bit 0x20 until torque is enabled again.
    overload_tripped: bool,
    /// The STS3215 model moving the shaft instead of the first-order approach.
    dynamics: Option<ShaftDynamics>,
}

impl ServoModel {
    /// A servo as it leaves the factory, with the given id, shaft at mid-range and torque off.
    pub fn factory(id: u8) -> Self {
        let mut servo = Self {
            table: [0; 256],
            flash: [0; EPROM_LEN],
            flash_dirty: false,
            actual: DEFAULT_ACTUAL,
            velocity: 0.0,
            tau: DEFAULT_TAU,
            errors: 0,
            staged: None,
            holding: false,
            stalled: false,
            overloaded_for: 0.0,
            overload_tripped: false,
            dynamics: None,
        };
        let defaults = [
            (reg::MODEL_NUMBER, i32::from(STS3215_MODEL)),
            (reg::FIRMWARE_MAJOR_VERSION, 3),
            (reg::FIRMWARE_MINOR_VERSION, 10),
            (reg::ID, i32::from(id.min(MAX_ID))),
            (reg::BAUD_RATE, 0),
            (reg::RETURN_DELAY_TIME, 250),
            (reg::RESPONSE_STATUS_LEVEL, 1),
            (reg::MIN_POSITION_LIMIT, 0),
            (reg::MAX_POSITION_LIMIT, 4095),
            (reg::MAX_TEMPERATURE_LIMIT, 70),
            (reg::MAX_VOLTAGE_LIMIT, 140),
            (reg::MIN_VOLTAGE_LIMIT, 40),
            (reg::MAX_TORQUE_LIMIT, 1000),
            (reg::P_COEFFICIENT, 32),
            (reg::D_COEFFICIENT, 32),
            (reg::I_COEFFICIENT, 0),
            (reg::UNLOADING_CONDITION, 44),
            (reg::LED_ALARM_CONDITION, 47),
            (reg::PROTECTION_CURRENT, 500),
            (reg::HOMING_OFFSET, 0),
            (reg::OPERATING_MODE, 0),
            (reg::PROTECTIVE_TORQUE, 20),
            (reg::PROTECTION_TIME, 200),
            (reg::OVERLOAD_TORQUE, 80),
            (reg::TORQUE_ENABLE, 0),
            (reg::ACCELERATION, 0),
            (reg::TORQUE_LIMIT, 1000),
            (reg::LOCK, 1),
            (reg::MAXIMUM_ACCELERATION, 0),
            (reg::PRESENT_VOLTAGE, 120),
            (reg::PRESENT_TEMPERATURE, 30),
        ];
        for (register, value) in defaults {
            // Every default fits its register; a failure would leave that byte at zero.
            let _ = servo.set_register(register, value);
        }
        servo.flash.copy_from_slice(&servo.table[..EPROM_LEN]);
        servo.refresh_registers();
        servo.hold_position();
        servo
    }

    /// A servo of an arm calibrated and configured by LeRobot (or this driver), as it powers up:
    /// the calibration's id, Homing_Offset and position limits and LeRobot's configuration
    /// (Return_Delay_Time 0, position mode, P 16 / I 0 / D 32, Maximum_Acceleration and
    /// Acceleration 254; for the gripper Max_Torque_Limit 500, Protection_Current 250,
    /// Overload_Torque 25) in its flash, the shaft resting in the middle of the calibrated range,
    /// torque off.
    pub fn calibrated(motor: &MotorCalibration, gripper: bool) -> Self {
        let mut servo = Self::factory(motor.id);
        let mut eprom = vec![
            (reg::HOMING_OFFSET, motor.homing_offset),
            (reg::MIN_POSITION_LIMIT, motor.range_min),
            (reg::MAX_POSITION_LIMIT, motor.range_max),
            (reg::RETURN_DELAY_TIME, 0),
            (reg::OPERATING_MODE, 0),
            (reg::P_COEFFICIENT, 16),
            (reg::I_COEFFICIENT, 0),
            (reg::D_COEFFICIENT, 32),
        ];
        if gripper {
            eprom.extend([
                (reg::MAX_TORQUE_LIMIT, 500),
                (reg::PROTECTION_CURRENT, 250),
                (reg::OVERLOAD_TORQUE, 25),
            ]);
        }
        for (register, value) in eprom {
            // A validated calibration fits its registers; a failure would keep the factory value.
            let _ = servo.set_register(register, value);
        }
        servo.flash.copy_from_slice(&servo.table[..EPROM_LEN]);
        for register in [reg::MAXIMUM_ACCELERATION, reg::ACCELERATION] {
            let _ = servo.set_register(register, 254);
        }
        servo.power_up_torque_limit();
        let mid = (motor.range_min + motor.range_max) / 2;
        servo.with_actual(f64::from(mid + motor.homing_offset))
    }

    /// The same servo with its shaft at `ticks` (absolute, wrapped to one revolution).
    pub fn with_actual(mut self, ticks: f64) -> Self {
        self.set_actual(ticks);
        self.hold_position();
        self
    }

    pub fn set_tau(&mut self, tau: Duration) {
        self.tau = tau;
    }

    /// From now on the shaft moves as the STS3215 model with these mechanics, driving `load`.
    pub fn set_dynamics(&mut self, mechanics: ServoMechanics, load: JointLoad) {
        let mut dynamics = ShaftDynamics::new(mechanics, load);
        dynamics.place(self.actual, self.joint_zero());
        self.dynamics = Some(dynamics);
    }

    /// Sets an EPROM register in the live table and the flash, as the factory (or a past session)
    /// left it.
    pub fn set_factory_register(
        &mut self,
        register: Register,
        value: i32,
    ) -> Result<(), RegisterError> {
        self.set_register(register, value)?;
        let start = usize::from(register.address);
        let end = (start + usize::from(register.size)).min(EPROM_LEN);
        if start < end {
            self.flash[start..end].copy_from_slice(&self.table[start..end]);
        }
        Ok(())
    }

    /// The register values the STS3215 model reads, from the live table.
    pub fn model_registers(&self) -> ServoRegisters {
        let value = |register| f64::from(self.register(register));
        ServoRegisters {
            p_coefficient: value(reg::P_COEFFICIENT),
            d_coefficient: value(reg::D_COEFFICIENT),
            i_coefficient: value(reg::I_COEFFICIENT),
            acceleration: value(reg::ACCELERATION),
            goal_velocity: value(reg::GOAL_VELOCITY).abs(),
            torque_limit: value(reg::TORQUE_LIMIT),
            cw_dead_zone: value(reg::CW_DEAD_ZONE),
            ccw_dead_zone: value(reg::CCW_DEAD_ZONE),
            overload_torque: value(reg::OVERLOAD_TORQUE),
            protection_time: value(reg::PROTECTION_TIME),
            protective_torque: value(reg::PROTECTIVE_TORQUE),
        }
    }

    /// Where the joint's zero is, in encoder ticks: the middle of the position limits (the
    /// calibrated range) plus Homing_Offset, as the driver maps ticks to radians.
    fn joint_zero(&self) -> f64 {
        let mid = f64::from(
            self.register(reg::MIN_POSITION_LIMIT) + self.register(reg::MAX_POSITION_LIMIT),
        ) / 2.0;
        mid + f64::from(self.register(reg::HOMING_OFFSET))
    }

    /// The id the servo answers to (register ID, changed by writes).
    pub fn id(&self) -> u8 {
        self.table[usize::from(reg::ID.address)]
    }

    pub fn actual(&self) -> f64 {
        self.actual
    }

    pub fn velocity(&self) -> f64 {
        self.velocity
    }

    /// The decoded value of `register` in the live table.
    pub fn register(&self, register: Register) -> i32 {
        let start = usize::from(register.address);
        register
            .decode(&self.table[start..start + usize::from(register.size)])
            .unwrap_or(0)
    }

    /// Sets a register directly, as the emulator's operator (no lock, no read-only check, no
    /// persistence): initial configuration and tests.
    pub fn set_register(&mut self, register: Register, value: i32) -> Result<(), RegisterError> {
        let bytes = register.encode(value)?;
        let start = usize::from(register.address);
        self.table[start..start + bytes.len()].copy_from_slice(&bytes);
        Ok(())
    }

    /// `length` bytes from `address`, cut short at the end of the table.
    pub fn read(&self, address: u8, length: u8) -> Vec<u8> {
        let start = usize::from(address);
        let end = (start + usize::from(length)).min(self.table.len());
        self.table[start..end].to_vec()
    }

    /// A WRITE from the bus: read-only bytes and out-of-range ids are ignored, EPROM bytes reach
    /// the flash only while Lock is 0.
    pub fn write(&mut self, address: u8, data: &[u8]) {
        let lock_open = self.register(reg::LOCK) == 0;
        let torque_was_on = self.torque_on();
        let start = usize::from(address);
        let end = (start + data.len()).min(self.table.len());
        for (index, byte) in (start..end).zip(data.iter().copied()) {
            if is_read_only(index) || (index == usize::from(reg::ID.address) && byte > MAX_ID) {
                continue;
            }
            self.table[index] = byte;
            if index < EPROM_LEN && lock_open && self.flash[index] != byte {
                self.flash[index] = byte;
                self.flash_dirty = true;
            }
        }
        let goal_start = usize::from(reg::GOAL_POSITION.address);
        let wrote_goal = start < goal_start + 2 && end > goal_start;
        if wrote_goal {
            self.holding = false;
        }
        if !torque_was_on && self.torque_on() {
            // Enabling torque clears a tripped overload protection.
            self.overload_tripped = false;
            self.overloaded_for = 0.0;
            // It holds the shaft where it is (the arm must not jump to a stale goal), unless the
            // same write also sets a goal.
            if !wrote_goal {
                self.hold_position();
            }
        }
        self.refresh_registers();
    }

    /// A REG_WRITE: remembered until ACTION (a second one replaces the first).
    pub fn stage(&mut self, address: u8, data: &[u8]) {
        self.staged = Some((address, data.to_vec()));
    }

    /// ACTION: applies the staged REG_WRITE, if any.
    pub fn action(&mut self) {
        if let Some((address, data)) = self.staged.take() {
            self.write(address, &data);
        }
    }

    /// Moves the shaft to `ticks` (absolute encoder ticks, wrapped to one revolution), as a hand
    /// does with torque off.
    pub fn set_actual(&mut self, ticks: f64) {
        if ticks.is_finite() {
            self.actual = ticks.rem_euclid(f64::from(TICKS_PER_REVOLUTION));
            let zero = self.joint_zero();
            if let Some(dynamics) = &mut self.dynamics {
                dynamics.place(self.actual, zero);
            }
            self.refresh_registers();
        }
    }

    /// An obstacle blocks the shaft (`true`) or is taken away.
    pub fn set_stalled(&mut self, stalled: bool) {
        self.stalled = stalled;
    }

    pub fn stalled(&self) -> bool {
        self.stalled
    }

    /// Whether the overload protection has tripped (until torque is enabled again).
    pub fn overload_tripped(&self) -> bool {
        self.overload_tripped
    }

    /// Trips the overload protection now, as if the load had stayed above Overload_Torque for
    /// Protection_Time.
    pub fn trip_overload(&mut self) {
        self.overload_tripped = true;
        self.overloaded_for = 0.0;
        if self.register(reg::UNLOADING_CONDITION) & UNLOAD_ON_OVERLOAD != 0 {
            self.table[usize::from(reg::TORQUE_ENABLE.address)] = 0;
        }
        self.refresh_registers();
    }

    /// The error bits of its status packets: the injected ones and a tripped overload.
    pub fn status_errors(&self) -> u8 {
        let overload = if self.overload_tripped {
            ServoErrors::OVERLOAD
        } else {
            0
        };
        self.errors | overload
    }

    /// Lets `dt` of time pass: the shaft approaches the goal if torque is on and nothing blocks
    /// it; the overload protection watches the load; the Present_* registers follow.
    pub fn advance(&mut self, dt: Duration) {
        let seconds = dt.as_secs_f64();
        if seconds <= 0.0 {
            return;
        }
        let start = self.actual;
        let mut left = seconds;
        while left > 0.0 && self.torque_on() {
            let watching = !self.overload_tripped && self.load_above_overload_torque();
            if !watching {
                // The load only falls from here on (the goal is fixed and the error shrinks).
                self.overloaded_for = 0.0;
                self.move_shaft(left);
                break;
            }
            let until_trip = self.protection_time() - self.overloaded_for;
            if until_trip <= 0.0 {
                self.trip_overload();
                continue;
            }
            let step = if self.stalled {
                left.min(until_trip)
            } else {
                left.min(until_trip).min(OVERLOAD_STEP)
            };
            self.move_shaft(step);
            self.overloaded_for += step;
            left -= step;
            if self.overloaded_for >= self.protection_time() {
                self.trip_overload();
            }
        }
        if !self.torque_on() {
            self.overloaded_for = 0.0;
        }
        self.velocity = (self.actual - start) / seconds;
        self.refresh_registers();
    }

    /// The flash's EPROM bytes (what survives a power cycle).
    pub fn eprom(&self) -> [u8; EPROM_LEN] {
        self.flash
    }

    /// Powers up from saved flash and shaft position: the live EPROM is the flash.
    pub fn restore(&mut self, eprom: &[u8], actual: f64) {
        for (index, byte) in eprom.iter().copied().enumerate().take(EPROM_LEN) {
            if !is_read_only(index) {
                self.flash[index] = byte;
                self.table[index] = byte;
            }
        }
        self.power_up_torque_limit();
        self.set_actual(actual);
        self.hold_position();
    }

    /// Whether EPROM bytes reached the flash since the last call (the state file must be saved).
    pub fn take_eprom_dirty(&mut self) -> bool {
        std::mem::take(&mut self.flash_dirty)
    }

    fn torque_on(&self) -> bool {
        self.register(reg::TORQUE_ENABLE) != 0
    }

    /// At power-up Torque_Limit (SRAM) starts at Max_Torque_Limit (EPROM).
    fn power_up_torque_limit(&mut self) {
        let _ = self.set_register(reg::TORQUE_LIMIT, self.register(reg::MAX_TORQUE_LIMIT));
    }

    /// What the encoder reads: the shaft rounded to a tick, 0..=4095.
    fn encoder(&self) -> i32 {
        (self.actual.round() as i32).clamp(0, MAX_TICKS)
    }

    /// Present_Position: the encoder minus Homing_Offset, not wrapped.
    fn present(&self) -> i32 {
        self.encoder() - self.register(reg::HOMING_OFFSET)
    }

    /// Where the motor drives the shaft, in encoder ticks: the goal (clamped to the position
    /// limits unless the servo set it to hold) plus Homing_Offset, short of the encoder's seam.
    fn target(&self) -> f64 {
        let mut goal = self.register(reg::GOAL_POSITION);
        let (min, max) = (
            self.register(reg::MIN_POSITION_LIMIT),
            self.register(reg::MAX_POSITION_LIMIT),
        );
        if !self.holding && min < max {
            goal = goal.clamp(min, max);
        }
        f64::from((goal + self.register(reg::HOMING_OFFSET)).clamp(0, MAX_TICKS))
    }

    /// Signed distance from the shaft to where the motor drives it (zero with torque off).
    fn position_error(&self) -> f64 {
        if self.torque_on() {
            self.target() - self.actual
        } else {
            0.0
        }
    }

    /// Present_Load (0.1 % of full torque): the model's demand, or (first-order shaft, or a
    /// blocked one) proportional to the position error; saturating.
    fn load(&self) -> f64 {
        let load = match &self.dynamics {
            Some(dynamics) if self.torque_on() && !self.stalled => {
                dynamics.demand_fraction() * MAX_LOAD
            }
            _ => self.position_error() * LOAD_PER_TICK,
        };
        load.clamp(-MAX_LOAD, MAX_LOAD)
    }

    fn load_above_overload_torque(&self) -> bool {
        let threshold = f64::from(self.register(reg::OVERLOAD_TORQUE)) * LOAD_PER_PERCENT;
        self.load().abs() > threshold
    }

    fn protection_time(&self) -> f64 {
        f64::from(self.register(reg::PROTECTION_TIME)) * PROTECTION_TIME_UNIT
    }

    /// `seconds` of first-order approach to the target, unless the shaft is blocked.
    fn move_shaft(&mut self, seconds: f64) {
        if self.stalled {
            return;
        }
        if self.dynamics.is_some() {
            let (registers, zero, target) =
                (self.model_registers(), self.joint_zero(), self.target());
            if let Some(dynamics) = &mut self.dynamics {
                // The motor never drives the shaft across the encoder's seam.
                let moved = dynamics.advance(registers, zero, target, seconds, true);
                self.actual = moved.clamp(0.0, f64::from(MAX_TICKS));
            }
            return;
        }
        let tau = self.tau.as_secs_f64().max(1e-6);
        self.actual += self.position_error() * (1.0 - (-seconds / tau).exp());
    }

    fn hold_position(&mut self) {
        let _ = self.set_register(reg::GOAL_POSITION, self.present());
        self.holding = true;
        let zero = self.joint_zero();
        if let Some(dynamics) = &mut self.dynamics {
            dynamics.place(self.actual, zero);
        }
    }

    fn refresh_registers(&mut self) {
        let load = self.load().round() as i32;
        let current = (IDLE_CURRENT + f64::from(load.abs()) * CURRENT_PER_LOAD).round() as i32;
        // The current's sign is the load's direction (sign-magnitude at bit 15).
        let current = if load < 0 { -current } else { current };
        let updates = [
            (reg::PRESENT_POSITION, self.present()),
            (
                reg::PRESENT_VELOCITY,
                self.velocity.round().clamp(-32767.0, 32767.0) as i32,
            ),
            (reg::PRESENT_LOAD, load),
            (reg::PRESENT_CURRENT, current),
            (reg::STATUS, i32::from(self.status_errors())),
            (
                reg::MOVING,
                i32::from(self.position_error().abs() > MOVING_THRESHOLD),
            ),
        ];
        for (register, value) in updates {
            let _ = self.set_register(register, value);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn servo() -> ServoModel {
        ServoModel::factory(1)
    }

    #[test]
    fn factory_defaults_are_those_of_a_new_sts3215() {
        let servo = servo();
        assert_eq!(servo.register(reg::MODEL_NUMBER), 777);
        assert_eq!(servo.read(0, 2), [3, 10]);
        assert_eq!(servo.register(reg::RETURN_DELAY_TIME), 250);
        assert_eq!(servo.register(reg::MAX_POSITION_LIMIT), 4095);
        assert_eq!(servo.register(reg::LOCK), 1);
        assert_eq!(servo.register(reg::PRESENT_POSITION), 2048);
        assert_eq!(servo.register(reg::GOAL_POSITION), 2048);
        assert_eq!(servo.register(reg::PRESENT_VOLTAGE), 120);
    }

    #[test]
    fn present_position_is_the_shaft_minus_the_homing_offset_without_wrapping() {
        let mut servo = servo().with_actual(100.0);
        servo.write(31, &reg::HOMING_OFFSET.encode(-447).unwrap());
        assert_eq!(servo.register(reg::HOMING_OFFSET), -447);
        assert_eq!(servo.register(reg::PRESENT_POSITION), 547);
        servo.set_actual(30.0);
        servo.write(31, &reg::HOMING_OFFSET.encode(100).unwrap());
        // 30 - 100 = -70: sign-magnitude with the sign at bit 15, as a real STS3215 reports it.
        assert_eq!(servo.register(reg::PRESENT_POSITION), -70);
        assert_eq!(servo.read(56, 2), (70u16 | 0x8000).to_le_bytes());
        // Past the top of the revolution it does not wrap either.
        servo.set_actual(4000.0);
        servo.write(31, &reg::HOMING_OFFSET.encode(-500).unwrap());
        assert_eq!(servo.register(reg::PRESENT_POSITION), 4500);
        // A hand turning the shaft past the encoder's seam wraps the encoder, not the offset.
        servo.set_actual(4096.0 + 10.0);
        assert_eq!(servo.register(reg::PRESENT_POSITION), 510);
    }

    #[test]
    fn torque_on_holds_a_shaft_whose_present_position_is_negative() {
        let mut servo = servo().with_actual(30.0);
        servo.write(31, &reg::HOMING_OFFSET.encode(100).unwrap());
        servo.write(40, &[1]);
        assert_eq!(servo.register(reg::GOAL_POSITION), -70);
        assert_eq!(servo.read(42, 2), (70u16 | 0x8000).to_le_bytes());
        for _ in 0..100 {
            servo.advance(Duration::from_millis(10));
        }
        assert_eq!(
            servo.actual(),
            30.0,
            "the hold goal is outside 0..4095 but kept"
        );
        assert_eq!(servo.register(reg::PRESENT_POSITION), -70);
        assert_eq!(servo.register(reg::MOVING), 0);
        // A goal the host writes is clamped to the position limits (factory 0..4095).
        servo.write(42, &reg::GOAL_POSITION.encode(-70).unwrap());
        for _ in 0..100 {
            servo.advance(Duration::from_millis(10));
        }
        assert_eq!(servo.register(reg::PRESENT_POSITION), 0);
    }

    #[test]
    fn the_motor_never_drives_the_shaft_across_the_encoder_seam() {
        let mut servo = servo().with_actual(4000.0);
        servo.write(31, &reg::HOMING_OFFSET.encode(500).unwrap());
        assert_eq!(servo.register(reg::PRESENT_POSITION), 3500);
        servo.write(40, &[1, 0, 0xA0, 0x0F]); // torque on, goal 4000 = encoder 4500
        for _ in 0..200 {
            servo.advance(Duration::from_millis(10));
        }
        assert!((servo.actual() - 4095.0).abs() < 0.5, "{}", servo.actual());
        assert_eq!(servo.register(reg::PRESENT_POSITION), 3595);
    }

    #[test]
    fn present_current_is_sign_magnitude_in_the_direction_of_the_load() {
        let mut servo = servo();
        assert_eq!(servo.read(69, 2), 3u16.to_le_bytes(), "idle, torque off");
        servo.set_stalled(true);
        servo.write(40, &[1]);
        servo.write(42, &(2048u16 - 100).to_le_bytes());
        servo.advance(Duration::from_millis(10));
        assert_eq!(servo.register(reg::PRESENT_LOAD), -200);
        // 3 + 200 * 0.25 = 53 units of 6.5 mA, negative.
        assert_eq!(servo.register(reg::PRESENT_CURRENT), -53);
        assert_eq!(servo.read(69, 2), (53u16 | 0x8000).to_le_bytes());
        servo.write(42, &(2048u16 + 100).to_le_bytes());
        servo.advance(Duration::from_millis(10));
        assert_eq!(servo.register(reg::PRESENT_LOAD), 200);
        assert_eq!(servo.register(reg::PRESENT_CURRENT), 53);
    }

    /// A factory servo with torque on, pushing against an obstacle with full load.
    fn pushing_against_an_obstacle() -> ServoModel {
        let mut servo = servo();
        servo.set_stalled(true);
        servo.write(40, &[1]);
        servo.write(42, &3048u16.to_le_bytes());
        servo
    }

    #[test]
    fn a_stalled_shaft_trips_the_overload_protection_after_protection_time() {
        // Factory: Overload_Torque 80 %, Protection_Time 200 x 10 ms.
        let mut servo = pushing_against_an_obstacle();
        servo.advance(Duration::from_millis(1990));
        assert_eq!(servo.actual(), 2048.0, "the obstacle holds the shaft");
        assert_eq!(servo.register(reg::PRESENT_LOAD), 1000);
        assert_eq!(servo.register(reg::TORQUE_ENABLE), 1);
        assert_eq!(servo.status_errors(), 0);
        servo.advance(Duration::from_millis(20));
        assert_eq!(servo.register(reg::TORQUE_ENABLE), 0, "unloaded");
        assert_eq!(servo.status_errors(), ServoErrors::OVERLOAD);
        assert_eq!(servo.register(reg::STATUS), 0x20);
        assert_eq!(servo.register(reg::PRESENT_LOAD), 0);
        servo.advance(Duration::from_secs(1));
        assert_eq!(servo.status_errors(), ServoErrors::OVERLOAD, "latched");
        // Enabling torque again clears it, holding where the shaft is.
        servo.write(40, &[1]);
        assert_eq!(servo.status_errors(), 0);
        assert_eq!(servo.register(reg::GOAL_POSITION), 2048);
        assert_eq!(servo.register(reg::TORQUE_ENABLE), 1);
    }

    #[test]
    fn one_long_step_trips_it_too_and_protection_time_is_in_10_ms() {
        let mut servo = pushing_against_an_obstacle();
        servo.write(35, &[5]); // 50 ms
        servo.advance(Duration::from_millis(40));
        assert_eq!(servo.register(reg::TORQUE_ENABLE), 1);
        servo.advance(Duration::from_secs(10));
        assert!(servo.overload_tripped());
        assert_eq!(servo.register(reg::TORQUE_ENABLE), 0);
    }

    #[test]
    fn a_load_that_falls_back_in_time_does_not_trip_it() {
        // A free shaft: a large step loads the motor only briefly.
        let mut servo = servo();
        servo.write(35, &[5]);
        servo.write(40, &[1, 0, 0xE8, 0x0B]);
        for _ in 0..100 {
            servo.advance(Duration::from_millis(10));
        }
        assert!(!servo.overload_tripped());
        assert!((servo.actual() - 3048.0).abs() < 1.0);
        // Blocked, then freed before Protection_Time: the load falls below the threshold within
        // 37 ms (tau ln 2.5), and the count starts again.
        let mut servo = pushing_against_an_obstacle();
        servo.write(35, &[20]); // 200 ms
        servo.advance(Duration::from_millis(150));
        servo.set_stalled(false);
        servo.advance(Duration::from_millis(200));
        servo.set_stalled(true);
        servo.write(42, &2048u16.to_le_bytes());
        servo.advance(Duration::from_millis(150));
        assert!(!servo.overload_tripped());
        servo.advance(Duration::from_millis(60));
        assert!(servo.overload_tripped(), "200 ms blocked without a break");
        // Below Overload_Torque (load 200 < 250) it never trips.
        servo.set_actual(2048.0);
        servo.write(36, &[25]);
        servo.write(40, &[1]);
        servo.write(42, &2148u16.to_le_bytes());
        servo.advance(Duration::from_secs(5));
        assert_eq!(servo.register(reg::PRESENT_LOAD), 200);
        assert!(!servo.overload_tripped());
    }

    #[test]
    fn without_the_unloading_condition_bit_the_error_is_reported_but_torque_stays() {
        let mut servo = pushing_against_an_obstacle();
        servo.write(19, &[0x04]);
        servo.advance(Duration::from_secs(3));
        assert_eq!(servo.status_errors(), ServoErrors::OVERLOAD);
        assert_eq!(servo.register(reg::TORQUE_ENABLE), 1);
    }

    #[test]
    fn tripping_the_overload_at_once_unloads_the_servo() {
        let mut servo = servo();
        servo.write(40, &[1]);
        servo.trip_overload();
        assert_eq!(servo.register(reg::TORQUE_ENABLE), 0);
        assert_eq!(servo.status_errors(), ServoErrors::OVERLOAD);
        servo.errors = ServoErrors::OVERHEAT;
        assert_eq!(
            servo.status_errors(),
            ServoErrors::OVERLOAD | ServoErrors::OVERHEAT
        );
    }

    #[test]
    fn a_calibrated_servo_powers_up_with_its_calibration_and_lerobots_configuration() {
        let pan = MotorCalibration {
            id: 1,
            drive_mode: 0,
            homing_offset: -447,
            range_min: 760,
            range_max: 3300,
        };
        let servo = ServoModel::calibrated(&pan, false);
        assert_eq!(servo.id(), 1);
        assert_eq!(servo.register(reg::HOMING_OFFSET), -447);
        assert_eq!(servo.register(reg::MIN_POSITION_LIMIT), 760);
        assert_eq!(servo.register(reg::MAX_POSITION_LIMIT), 3300);
        assert_eq!(servo.register(reg::PRESENT_POSITION), 2030, "mid-range");
        assert_eq!(servo.register(reg::TORQUE_ENABLE), 0);
        for (register, value) in [
            (reg::RETURN_DELAY_TIME, 0),
            (reg::OPERATING_MODE, 0),
            (reg::P_COEFFICIENT, 16),
            (reg::I_COEFFICIENT, 0),
            (reg::D_COEFFICIENT, 32),
            (reg::MAXIMUM_ACCELERATION, 254),
            (reg::ACCELERATION, 254),
            (reg::MAX_TORQUE_LIMIT, 1000),
            (reg::OVERLOAD_TORQUE, 80),
        ] {
            assert_eq!(servo.register(register), value, "{}", register.name);
        }
        assert_eq!(
            servo.eprom()[31..33],
            reg::HOMING_OFFSET.encode(-447).unwrap()[..],
            "in the flash"
        );
        let gripper = ServoModel::calibrated(
            &MotorCalibration {
                id: 6,
                range_min: 2000,
                range_max: 3000,
                homing_offset: 0,
                drive_mode: 0,
            },
            true,
        );
        for (register, value) in [
            (reg::MAX_TORQUE_LIMIT, 500),
            (reg::TORQUE_LIMIT, 500),
            (reg::PROTECTION_CURRENT, 250),
            (reg::OVERLOAD_TORQUE, 25),
        ] {
            assert_eq!(gripper.register(register), value, "{}", register.name);
        }
        assert_eq!(gripper.register(reg::PRESENT_POSITION), 2500);
    }

    #[test]
    fn the_goal_is_clamped_to_the_position_limits() {
        let mut servo = servo();
        servo.write(9, &[0x00, 0x04, 0x00, 0x0C]); // limits 1024..3072
        servo.write(40, &[1]);
        servo.write(42, &4000u16.to_le_bytes());
        for _ in 0..100 {
            servo.advance(Duration::from_millis(10));
        }
        assert!((servo.actual() - 3072.0).abs() < 1.0, "{}", servo.actual());
        assert_eq!(servo.register(reg::MOVING), 0);
    }

    #[test]
    fn torque_on_moves_first_order_and_torque_off_stays() {
        let mut servo = servo();
        servo.write(42, &3048u16.to_le_bytes());
        servo.advance(Duration::from_millis(100));
        assert_eq!(servo.actual(), 2048.0, "torque off: the shaft stays");
        servo.write(40, &[1, 0, 0xE8, 0x0B]); // torque on and goal 3048 in one write
        servo.advance(DEFAULT_TAU);
        let expected = 2048.0 + 1000.0 * (1.0 - (-1.0f64).exp());
        assert!((servo.actual() - expected).abs() < 1e-6);
        assert_eq!(servo.register(reg::MOVING), 1);
        assert!(servo.register(reg::PRESENT_VELOCITY) > 0);
        assert!(servo.register(reg::PRESENT_LOAD) > 0);
    }

    #[test]
    fn enabling_torque_holds_the_current_position() {
        let mut servo = servo();
        servo.set_actual(1000.0);
        servo.write(40, &[1]);
        servo.advance(Duration::from_millis(100));
        assert_eq!(servo.actual(), 1000.0);
        assert_eq!(servo.register(reg::GOAL_POSITION), 1000);
    }

    #[test]
    fn read_only_registers_ignore_writes() {
        let mut servo = servo();
        servo.write(3, &[0, 0]);
        servo.write(56, &[0, 0]);
        assert_eq!(servo.register(reg::MODEL_NUMBER), 777);
        assert_eq!(servo.register(reg::PRESENT_POSITION), 2048);
        assert_eq!(
            servo.read(250, 20).len(),
            6,
            "reads stop at the end of the table"
        );
    }

    #[test]
    fn eprom_reaches_the_flash_only_while_unlocked() {
        let mut servo = servo();
        servo.write(7, &[0]);
        assert_eq!(servo.register(reg::RETURN_DELAY_TIME), 0);
        assert!(!servo.take_eprom_dirty());
        assert_eq!(servo.eprom()[7], 250);
        servo.write(55, &[0]);
        servo.write(5, &[9]);
        assert!(servo.take_eprom_dirty());
        assert!(!servo.take_eprom_dirty());
        assert_eq!(servo.id(), 9);
        assert_eq!(servo.eprom()[5], 9);
        assert_eq!(
            servo.eprom()[7],
            250,
            "a byte written while locked stays out of the flash"
        );
        servo.write(5, &[0xFE]);
        assert_eq!(servo.id(), 9, "the broadcast id cannot be assigned");
    }
}
