//! One emulated STS3215: its 256-byte control table and a first-order model of the shaft.
//!
//! Only position mode is modelled: the shaft approaches the goal exponentially with time constant
//! `tau`; Acceleration, Goal_Time and Goal_Velocity are stored but do not shape the motion.

use std::time::Duration;

use crate::protocol::{
    registers::{self as reg, Register, RegisterError, EPROM_END, STS3215_MODEL},
    MAX_ID,
};

/// Time constant of the shaft's approach to the goal unless configured otherwise.
pub const DEFAULT_TAU: Duration = Duration::from_millis(40);
/// Where a factory servo's shaft rests: the middle of the revolution.
pub const DEFAULT_ACTUAL: f64 = 2048.0;

const TICKS: f64 = 4096.0;
/// Moving (66) reads 1 while the position error exceeds this many ticks.
const MOVING_THRESHOLD: f64 = 2.0;
/// Present_Load (0.1 % of full torque) per tick of position error: 500 ticks saturate it.
const LOAD_PER_TICK: f64 = 2.0;
const MAX_LOAD: f64 = 1000.0;
/// Present_Current (units of 6.5 mA) at rest, and its growth with load.
const IDLE_CURRENT: f64 = 3.0;
const CURRENT_PER_LOAD: f64 = 0.25;
const EPROM_LEN: usize = EPROM_END as usize;

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
    /// Absolute shaft position in ticks, 0..4096 (wrapping).
    actual: f64,
    /// Ticks per second over the last physics step.
    velocity: f64,
    tau: Duration,
    /// Error bits reported in every status packet (fault injection).
    pub errors: u8,
    /// A REG_WRITE waiting for ACTION.
    staged: Option<(u8, Vec<u8>)>,
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
            (reg::PROTECTION_CURRENT, 500),
            (reg::HOMING_OFFSET, 0),
            (reg::OPERATING_MODE, 0),
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
        servo.refresh_registers(0.0);
        servo.hold_position();
        servo
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
        // Enabling torque holds the shaft where it is (the arm must not jump to a stale goal),
        // unless the same write also sets a goal.
        if !torque_was_on && self.torque_on() && !wrote_goal {
            self.hold_position();
        }
        self.refresh_registers(0.0);
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

    /// Moves the shaft to `ticks` (absolute), as a hand does with torque off.
    pub fn set_actual(&mut self, ticks: f64) {
        if ticks.is_finite() {
            self.actual = ticks.rem_euclid(TICKS);
            self.refresh_registers(0.0);
        }
    }

    /// Lets `dt` of time pass: the shaft approaches the goal if torque is on; the Present_*
    /// registers follow.
    pub fn advance(&mut self, dt: Duration) {
        let seconds = dt.as_secs_f64();
        if seconds <= 0.0 {
            return;
        }
        let mut step = 0.0;
        if self.torque_on() {
            let tau = self.tau.as_secs_f64().max(1e-6);
            step = self.position_error() * (1.0 - (-seconds / tau).exp());
            self.actual = (self.actual + step).rem_euclid(TICKS);
        }
        self.velocity = step / seconds;
        self.refresh_registers(self.velocity);
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

    /// Present_Position: the shaft in the homing-offset frame.
    fn present(&self) -> f64 {
        let offset = f64::from(self.register(reg::HOMING_OFFSET));
        (self.actual - offset).rem_euclid(TICKS)
    }

    /// The goal in the offset frame, clamped to the position limits as the servo does.
    fn target(&self) -> f64 {
        let mut goal = self.register(reg::GOAL_POSITION).clamp(0, 4095);
        let (min, max) = (
            self.register(reg::MIN_POSITION_LIMIT),
            self.register(reg::MAX_POSITION_LIMIT),
        );
        if min < max {
            goal = goal.clamp(min, max);
        }
        f64::from(goal)
    }

    /// Signed distance to the goal, within the offset frame: the servo never crosses its own
    /// 0/4095 seam to take a shorter way round.
    fn position_error(&self) -> f64 {
        if self.torque_on() {
            self.target() - self.present()
        } else {
            0.0
        }
    }

    fn hold_position(&mut self) {
        let present = (self.present().round() as i32) % 4096;
        let _ = self.set_register(reg::GOAL_POSITION, present);
    }

    fn refresh_registers(&mut self, velocity: f64) {
        let error = self.position_error();
        let load = (error * LOAD_PER_TICK).clamp(-MAX_LOAD, MAX_LOAD).round() as i32;
        let current = (IDLE_CURRENT + f64::from(load.abs()) * CURRENT_PER_LOAD).round() as i32;
        let updates = [
            (
                reg::PRESENT_POSITION,
                (self.present().round() as i32) % 4096,
            ),
            (
                reg::PRESENT_VELOCITY,
                velocity.round().clamp(-32767.0, 32767.0) as i32,
            ),
            (reg::PRESENT_LOAD, load),
            (reg::PRESENT_CURRENT, current),
            (reg::MOVING, i32::from(error.abs() > MOVING_THRESHOLD)),
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
    fn present_position_is_the_shaft_minus_the_sign_magnitude_homing_offset() {
        let mut servo = servo().with_actual(100.0);
        servo.write(31, &reg::HOMING_OFFSET.encode(-447).unwrap());
        assert_eq!(servo.register(reg::HOMING_OFFSET), -447);
        assert_eq!(servo.register(reg::PRESENT_POSITION), 547);
        servo.write(31, &reg::HOMING_OFFSET.encode(300).unwrap());
        // 100 - 300 wraps to 3896; the register holds it with the sign bit clear.
        assert_eq!(servo.read(56, 2), 3896u16.to_le_bytes());
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
