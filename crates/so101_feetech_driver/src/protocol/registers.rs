//! The STS3215 control table by name, and the conversion of register bytes to values.

/// One register: where it is, how wide, and whether it is sign-magnitude (and at which bit).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Register {
    pub name: &'static str,
    pub address: u8,
    pub size: u8,
    /// Sign-magnitude registers store the sign at this bit and the magnitude below it.
    pub sign_bit: Option<u8>,
}

const fn register(name: &'static str, address: u8, size: u8) -> Register {
    Register {
        name,
        address,
        size,
        sign_bit: None,
    }
}

const fn signed(name: &'static str, address: u8, size: u8, sign_bit: u8) -> Register {
    Register {
        name,
        address,
        size,
        sign_bit: Some(sign_bit),
    }
}

pub const FIRMWARE_MAJOR_VERSION: Register = register("Firmware_Major_Version", 0, 1);
pub const FIRMWARE_MINOR_VERSION: Register = register("Firmware_Minor_Version", 1, 1);
pub const MODEL_NUMBER: Register = register("Model_Number", 3, 2);
pub const ID: Register = register("ID", 5, 1);
pub const BAUD_RATE: Register = register("Baud_Rate", 6, 1);
pub const RETURN_DELAY_TIME: Register = register("Return_Delay_Time", 7, 1);
pub const RESPONSE_STATUS_LEVEL: Register = register("Response_Status_Level", 8, 1);
pub const MIN_POSITION_LIMIT: Register = register("Min_Position_Limit", 9, 2);
pub const MAX_POSITION_LIMIT: Register = register("Max_Position_Limit", 11, 2);
pub const MAX_TEMPERATURE_LIMIT: Register = register("Max_Temperature_Limit", 13, 1);
pub const MAX_VOLTAGE_LIMIT: Register = register("Max_Voltage_Limit", 14, 1);
pub const MIN_VOLTAGE_LIMIT: Register = register("Min_Voltage_Limit", 15, 1);
pub const MAX_TORQUE_LIMIT: Register = register("Max_Torque_Limit", 16, 2);
pub const PHASE: Register = register("Phase", 18, 1);
pub const UNLOADING_CONDITION: Register = register("Unloading_Condition", 19, 1);
pub const LED_ALARM_CONDITION: Register = register("LED_Alarm_Condition", 20, 1);
pub const P_COEFFICIENT: Register = register("P_Coefficient", 21, 1);
pub const D_COEFFICIENT: Register = register("D_Coefficient", 22, 1);
pub const I_COEFFICIENT: Register = register("I_Coefficient", 23, 1);
pub const MINIMUM_STARTUP_FORCE: Register = register("Minimum_Startup_Force", 24, 2);
pub const CW_DEAD_ZONE: Register = register("CW_Dead_Zone", 26, 1);
pub const CCW_DEAD_ZONE: Register = register("CCW_Dead_Zone", 27, 1);
pub const PROTECTION_CURRENT: Register = register("Protection_Current", 28, 2);
pub const ANGULAR_RESOLUTION: Register = register("Angular_Resolution", 30, 1);
pub const HOMING_OFFSET: Register = signed("Homing_Offset", 31, 2, 11);
pub const OPERATING_MODE: Register = register("Operating_Mode", 33, 1);
pub const PROTECTIVE_TORQUE: Register = register("Protective_Torque", 34, 1);
pub const PROTECTION_TIME: Register = register("Protection_Time", 35, 1);
pub const OVERLOAD_TORQUE: Register = register("Overload_Torque", 36, 1);
pub const VELOCITY_P_COEFFICIENT: Register =
    register("Velocity_closed_loop_P_proportional_coefficient", 37, 1);
pub const OVER_CURRENT_PROTECTION_TIME: Register = register("Over_Current_Protection_Time", 38, 1);
pub const VELOCITY_I_COEFFICIENT: Register =
    register("Velocity_closed_loop_I_integral_coefficient", 39, 1);
pub const TORQUE_ENABLE: Register = register("Torque_Enable", 40, 1);
pub const ACCELERATION: Register = register("Acceleration", 41, 1);
pub const GOAL_POSITION: Register = signed("Goal_Position", 42, 2, 15);
pub const GOAL_TIME: Register = register("Goal_Time", 44, 2);
pub const GOAL_VELOCITY: Register = signed("Goal_Velocity", 46, 2, 15);
pub const TORQUE_LIMIT: Register = register("Torque_Limit", 48, 2);
pub const LOCK: Register = register("Lock", 55, 1);
pub const PRESENT_POSITION: Register = signed("Present_Position", 56, 2, 15);
pub const PRESENT_VELOCITY: Register = signed("Present_Velocity", 58, 2, 15);
pub const PRESENT_LOAD: Register = signed("Present_Load", 60, 2, 10);
pub const PRESENT_VOLTAGE: Register = register("Present_Voltage", 62, 1);
pub const PRESENT_TEMPERATURE: Register = register("Present_Temperature", 63, 1);
pub const STATUS: Register = register("Status", 65, 1);
pub const MOVING: Register = register("Moving", 66, 1);
/// Sign-magnitude at bit 15 as Feetech's SMS_STS library reads it (LeRobot 0.6.1 reads it unsigned).
pub const PRESENT_CURRENT: Register = signed("Present_Current", 69, 2, 15);
pub const MAXIMUM_VELOCITY_LIMIT: Register = register("Maximum_Velocity_Limit", 84, 1);
pub const MAXIMUM_ACCELERATION: Register = register("Maximum_Acceleration", 85, 1);

/// Every register, in address order.
pub const ALL: [Register; 49] = [
    FIRMWARE_MAJOR_VERSION,
    FIRMWARE_MINOR_VERSION,
    MODEL_NUMBER,
    ID,
    BAUD_RATE,
    RETURN_DELAY_TIME,
    RESPONSE_STATUS_LEVEL,
    MIN_POSITION_LIMIT,
    MAX_POSITION_LIMIT,
    MAX_TEMPERATURE_LIMIT,
    MAX_VOLTAGE_LIMIT,
    MIN_VOLTAGE_LIMIT,
    MAX_TORQUE_LIMIT,
    PHASE,
    UNLOADING_CONDITION,
    LED_ALARM_CONDITION,
    P_COEFFICIENT,
    D_COEFFICIENT,
    I_COEFFICIENT,
    MINIMUM_STARTUP_FORCE,
    CW_DEAD_ZONE,
    CCW_DEAD_ZONE,
    PROTECTION_CURRENT,
    ANGULAR_RESOLUTION,
    HOMING_OFFSET,
    OPERATING_MODE,
    PROTECTIVE_TORQUE,
    PROTECTION_TIME,
    OVERLOAD_TORQUE,
    VELOCITY_P_COEFFICIENT,
    OVER_CURRENT_PROTECTION_TIME,
    VELOCITY_I_COEFFICIENT,
    TORQUE_ENABLE,
    ACCELERATION,
    GOAL_POSITION,
    GOAL_TIME,
    GOAL_VELOCITY,
    TORQUE_LIMIT,
    LOCK,
    PRESENT_POSITION,
    PRESENT_VELOCITY,
    PRESENT_LOAD,
    PRESENT_VOLTAGE,
    PRESENT_TEMPERATURE,
    STATUS,
    MOVING,
    PRESENT_CURRENT,
    MAXIMUM_VELOCITY_LIMIT,
    MAXIMUM_ACCELERATION,
];

/// Model number of the STS3215 (register Model_Number).
pub const STS3215_MODEL: u16 = 777;
/// Addresses below this are EPROM (kept across power cycles, written only with Lock = 0).
pub const EPROM_END: u8 = 40;

/// Baud rates by Baud_Rate register index (indices 0-4 agree between LeRobot and Feetech).
pub const BAUD_RATES: [(i32, u32); 5] = [
    (0, 1_000_000),
    (1, 500_000),
    (2, 250_000),
    (3, 128_000),
    (4, 115_200),
];

/// The Baud_Rate register index of `baud`.
pub fn baud_index(baud: u32) -> Option<i32> {
    BAUD_RATES
        .iter()
        .find(|(_, rate)| *rate == baud)
        .map(|(index, _)| *index)
}

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RegisterError {
    #[error("{value} does not fit register {name} ({size} bytes{})", if *signed { ", sign-magnitude" } else { "" })]
    OutOfRange {
        name: &'static str,
        value: i32,
        size: u8,
        signed: bool,
    },
    #[error("register {name} has {expected} bytes, got {got}")]
    WrongSize {
        name: &'static str,
        expected: u8,
        got: usize,
    },
}

/// The register called `name` (LeRobot's spelling).
pub fn by_name(name: &str) -> Option<Register> {
    ALL.iter().copied().find(|register| register.name == name)
}

impl Register {
    /// Little-endian bytes of `value` (sign-magnitude where the register is).
    pub fn encode(&self, value: i32) -> Result<Vec<u8>, RegisterError> {
        let out_of_range = || RegisterError::OutOfRange {
            name: self.name,
            value,
            size: self.size,
            signed: self.sign_bit.is_some(),
        };
        let raw: u32 = match self.sign_bit {
            Some(bit) => {
                let magnitude = value.unsigned_abs();
                if magnitude >= 1 << bit {
                    return Err(out_of_range());
                }
                magnitude | (u32::from(value < 0) << bit)
            }
            None => u32::try_from(value).map_err(|_| out_of_range())?,
        };
        if self.size < 4 && raw >> (8 * u32::from(self.size)) != 0 {
            return Err(out_of_range());
        }
        Ok(raw.to_le_bytes()[..usize::from(self.size)].to_vec())
    }

    /// The value stored in `bytes` (little-endian, sign-magnitude where the register is).
    pub fn decode(&self, bytes: &[u8]) -> Result<i32, RegisterError> {
        if bytes.len() != usize::from(self.size) {
            return Err(RegisterError::WrongSize {
                name: self.name,
                expected: self.size,
                got: bytes.len(),
            });
        }
        let raw = bytes
            .iter()
            .rev()
            .fold(0u32, |value, byte| (value << 8) | u32::from(*byte));
        Ok(match self.sign_bit {
            Some(bit) => {
                let magnitude = (raw & ((1 << bit) - 1)) as i32;
                if raw >> bit & 1 == 1 {
                    -magnitude
                } else {
                    magnitude
                }
            }
            None => raw as i32,
        })
    }

    pub fn is_eprom(&self) -> bool {
        self.address < EPROM_END
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sign_magnitude_matches_the_servo_convention() {
        assert_eq!(
            HOMING_OFFSET.encode(-447).unwrap(),
            (447u16 | 1 << 11).to_le_bytes()
        );
        assert_eq!(
            HOMING_OFFSET
                .decode(&(447u16 | 1 << 11).to_le_bytes())
                .unwrap(),
            -447
        );
        assert_eq!(
            PRESENT_LOAD
                .decode(&(100u16 | 1 << 10).to_le_bytes())
                .unwrap(),
            -100
        );
        assert_eq!(GOAL_POSITION.encode(2048).unwrap(), [0x00, 0x08]);
        assert_eq!(PRESENT_POSITION.decode(&[70, 0x80]).unwrap(), -70);
        assert_eq!(PRESENT_CURRENT.decode(&[53, 0x80]).unwrap(), -53);
        // The magnitude limit LeRobot users meet on wrist_roll.
        assert!(HOMING_OFFSET.encode(2048).is_err());
        assert!(HOMING_OFFSET.encode(2047).is_ok());
    }

    #[test]
    fn unsigned_registers_refuse_negative_and_too_wide_values() {
        assert!(TORQUE_ENABLE.encode(-1).is_err());
        assert!(TORQUE_ENABLE.encode(256).is_err());
        assert_eq!(MODEL_NUMBER.decode(&777u16.to_le_bytes()).unwrap(), 777);
        assert!(MODEL_NUMBER.decode(&[1]).is_err());
    }

    #[test]
    fn names_resolve_and_the_table_is_consistent() {
        assert_eq!(by_name("Present_Position"), Some(PRESENT_POSITION));
        assert_eq!(by_name("Nope"), None);
        for window in ALL.windows(2) {
            assert!(
                window[0].address + window[0].size <= window[1].address,
                "{window:?}"
            );
        }
        assert!(HOMING_OFFSET.is_eprom() && !TORQUE_ENABLE.is_eprom());
    }

    #[test]
    fn baud_indices_follow_the_servo_table() {
        assert_eq!(baud_index(1_000_000), Some(0));
        assert_eq!(baud_index(115_200), Some(4));
        assert_eq!(baud_index(9600), None);
    }
}
