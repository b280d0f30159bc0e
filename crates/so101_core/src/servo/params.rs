//! What one STS3215 model is made of: the register values the driver writes to the servo, and
//! the physical numbers (motor, gearbox, latency) that registers do not tell. Presets, and the
//! parameter file `so101-sysid fit` writes and `--servo-params` loads.

use std::{fmt, path::Path, str::FromStr};

use serde::{Deserialize, Serialize};

use crate::robot::{JOINT_COUNT, JOINT_NAMES};

/// Encoder ticks per revolution of the STS3215's magnetic encoder (positions read 0..=4095).
pub const TICKS_PER_REVOLUTION: u32 = 4096;
/// Radians per encoder tick.
pub const RAD_PER_TICK: f64 = std::f64::consts::TAU / TICKS_PER_REVOLUTION as f64;

/// The preset name of the STS3215 model with its published parameters.
pub const STS3215: &str = "sts3215";
/// The preset name of the scene's own position actuator (see [`ServoModelChoice::Gain80`]).
pub const GAIN80: &str = "gain80";
/// The servo model every door (sim node, in-process worlds, Gymnasium, LeRobot) starts with.
pub const DEFAULT_SERVO_MODEL: &str = STS3215;
/// The servo models known by name (any other is a parameter file).
pub const SERVO_MODELS: [&str; 2] = [STS3215, GAIN80];

/// The registers that shape the motion, in the servo's own units (see
/// ../shared/notes/feetech-sts3215.md for the control table).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ServoRegisters {
    /// P_Coefficient (21).
    pub p_coefficient: f64,
    /// D_Coefficient (22).
    pub d_coefficient: f64,
    /// I_Coefficient (23).
    pub i_coefficient: f64,
    /// Acceleration (41), 100 ticks/s² per unit; 0 = no ramp.
    pub acceleration: f64,
    /// Goal_Velocity (46), ticks/s; 0 = as fast as the motor goes.
    pub goal_velocity: f64,
    /// Torque_Limit (48), 0.1 % of the stall torque.
    pub torque_limit: f64,
    /// CW_Dead_Zone (26) and CCW_Dead_Zone (27), ticks: no drive while the error is inside.
    pub cw_dead_zone: f64,
    pub ccw_dead_zone: f64,
    /// Overload_Torque (36), % of the stall torque, held for Protection_Time (35, 10 ms units),
    /// limits the output to Protective_Torque (34, %) until the demand falls back.
    pub overload_torque: f64,
    pub protection_time: f64,
    pub protective_torque: f64,
}

impl ServoRegisters {
    /// What LeRobot's so101_follower (and this project's driver) writes to an arm joint:
    /// P 16, I 0, D 32, Acceleration 254, full torque; the rest factory.
    pub const LEROBOT_ARM: Self = Self {
        p_coefficient: 16.0,
        d_coefficient: 32.0,
        i_coefficient: 0.0,
        acceleration: 254.0,
        goal_velocity: 0.0,
        torque_limit: 1000.0,
        cw_dead_zone: 1.0,
        ccw_dead_zone: 1.0,
        overload_torque: 80.0,
        protection_time: 200.0,
        protective_torque: 20.0,
    };

    /// The gripper: as an arm joint, with LeRobot's Max_Torque_Limit 500 and Overload_Torque 25.
    pub const LEROBOT_GRIPPER: Self = Self {
        torque_limit: 500.0,
        overload_torque: 25.0,
        ..Self::LEROBOT_ARM
    };
}

impl Default for ServoRegisters {
    fn default() -> Self {
        Self::LEROBOT_ARM
    }
}

/// What the registers do not say: the motor, the gearbox and the joint it drives.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ServoMechanics {
    /// Output torque per rad of error per unit of P_Coefficient, N m/rad.
    pub gain_per_p: f64,
    /// Damping torque per rad/s per unit of D_Coefficient, N m s/rad.
    pub damping_per_d: f64,
    /// Torque per rad s of integrated error per unit of I_Coefficient, N m/(rad s).
    pub integral_per_i: f64,
    /// Stall torque at full Torque_Limit, N m.
    pub stall_torque: f64,
    /// No-load speed, rad/s: the motor's torque falls linearly to zero at it.
    pub no_load_speed: f64,
    /// Reflected rotor inertia, kg m².
    pub armature: f64,
    /// Viscous friction of the gearbox, N m s/rad.
    pub damping: f64,
    /// Dry friction of the gearbox, N m.
    pub friction: f64,
    /// Lost motion in the gears, rad (whole width).
    pub backlash: f64,
    /// From a goal leaving the host to the servo acting on it, s.
    pub latency: f64,
}

impl ServoMechanics {
    /// TheRobotStudio's STS3215 class (SO-ARM100 Simulation/SO101/so101_new_calib.xml): kp 998.22
    /// and kv 2.731 at P 16 and D 32, forcerange 3.35 N m, armature 0.028, damping 0.60,
    /// frictionloss 0.052; no-load speed 62 rpm (Feetech's STS3215 listing, 12 V).
    pub const STS3215: Self = Self {
        gain_per_p: 998.22 / 16.0,
        damping_per_d: 2.731 / 32.0,
        integral_per_i: 0.0,
        stall_torque: 3.35,
        no_load_speed: 62.0 * std::f64::consts::TAU / 60.0,
        armature: 0.028,
        damping: 0.60,
        friction: 0.052,
        backlash: 0.0,
        latency: 0.0,
    };
}

impl Default for ServoMechanics {
    fn default() -> Self {
        Self::STS3215
    }
}

/// One joint's servo: registers and mechanics.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ServoParams {
    pub registers: ServoRegisters,
    pub mechanics: ServoMechanics,
}

impl ServoParams {
    /// Error gain, N m/rad.
    pub fn kp(&self) -> f64 {
        self.mechanics.gain_per_p * self.registers.p_coefficient
    }

    /// Damping gain, N m s/rad.
    pub fn kd(&self) -> f64 {
        self.mechanics.damping_per_d * self.registers.d_coefficient
    }

    /// Integral gain, N m/(rad s).
    pub fn ki(&self) -> f64 {
        self.mechanics.integral_per_i * self.registers.i_coefficient
    }

    /// The most torque the servo may give, N m (Torque_Limit of the stall torque).
    pub fn torque_ceiling(&self) -> f64 {
        self.mechanics.stall_torque * (self.registers.torque_limit / 1000.0).clamp(0.0, 1.0)
    }

    /// The reference's speed limit, rad/s: Goal_Velocity, or the no-load speed when 0.
    pub fn speed_limit(&self) -> f64 {
        let goal = self.registers.goal_velocity * RAD_PER_TICK;
        if goal > 0.0 {
            goal.min(self.mechanics.no_load_speed)
        } else {
            self.mechanics.no_load_speed
        }
    }

    /// The reference's acceleration limit, rad/s² (infinite with Acceleration 0).
    pub fn acceleration_limit(&self) -> f64 {
        let ticks = self.registers.acceleration * 100.0;
        if ticks > 0.0 {
            ticks * RAD_PER_TICK
        } else {
            f64::INFINITY
        }
    }

    /// Dead zone bounds, rad: (below, above) zero error.
    pub fn dead_zone(&self) -> (f64, f64) {
        (
            self.registers.ccw_dead_zone * RAD_PER_TICK,
            self.registers.cw_dead_zone * RAD_PER_TICK,
        )
    }

    fn check(&self, joint: &str) -> Result<(), ServoParamsError> {
        let r = &self.registers;
        let m = &self.mechanics;
        let named = [
            ("registers.p_coefficient", r.p_coefficient),
            ("registers.d_coefficient", r.d_coefficient),
            ("registers.i_coefficient", r.i_coefficient),
            ("registers.acceleration", r.acceleration),
            ("registers.goal_velocity", r.goal_velocity),
            ("registers.torque_limit", r.torque_limit),
            ("registers.cw_dead_zone", r.cw_dead_zone),
            ("registers.ccw_dead_zone", r.ccw_dead_zone),
            ("registers.overload_torque", r.overload_torque),
            ("registers.protection_time", r.protection_time),
            ("registers.protective_torque", r.protective_torque),
            ("mechanics.gain_per_p", m.gain_per_p),
            ("mechanics.damping_per_d", m.damping_per_d),
            ("mechanics.integral_per_i", m.integral_per_i),
            ("mechanics.armature", m.armature),
            ("mechanics.damping", m.damping),
            ("mechanics.friction", m.friction),
            ("mechanics.backlash", m.backlash),
            ("mechanics.latency", m.latency),
        ];
        for (name, value) in named {
            if !(value.is_finite() && value >= 0.0) {
                return Err(ServoParamsError::Value {
                    joint: joint.to_owned(),
                    name,
                    value,
                });
            }
        }
        for (name, value) in [
            ("mechanics.stall_torque", m.stall_torque),
            ("mechanics.no_load_speed", m.no_load_speed),
        ] {
            if !(value.is_finite() && value > 0.0) {
                return Err(ServoParamsError::Value {
                    joint: joint.to_owned(),
                    name,
                    value,
                });
            }
        }
        if m.latency > MAX_LATENCY {
            return Err(ServoParamsError::Value {
                joint: joint.to_owned(),
                name: "mechanics.latency (at most 0.5 s)",
                value: m.latency,
            });
        }
        Ok(())
    }
}

/// The longest command latency a parameter file may ask for, s.
pub const MAX_LATENCY: f64 = 0.5;

#[derive(Debug, thiserror::Error)]
pub enum ServoParamsError {
    #[error("cannot read the servo parameter file {path}: {source}")]
    Read {
        path: String,
        source: std::io::Error,
    },
    #[error("the servo parameter file {path} is not valid: {source}")]
    Parse {
        path: String,
        source: serde_json::Error,
    },
    #[error("servo parameters of {joint}: {name} = {value} is not allowed (finite, not negative)")]
    Value {
        joint: String,
        name: &'static str,
        value: f64,
    },
    #[error("{0:?} is not a servo model: use {GAIN80}, {STS3215} or a parameter file (.json)")]
    Model(String),
    #[error("{GAIN80} is the scene's position actuator, with no servo parameters: use {STS3215} or a parameter file (.json)")]
    NoParameters,
}

/// Every joint's servo, in contract order: what a parameter file holds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ArmServoParams(pub [ServoParams; JOINT_COUNT]);

impl ArmServoParams {
    /// The STS3215 as LeRobot configures it, with TheRobotStudio's published mechanics.
    pub fn sts3215() -> Self {
        let mut joints = [ServoParams::default(); JOINT_COUNT];
        joints[JOINT_COUNT - 1].registers = ServoRegisters::LEROBOT_GRIPPER;
        Self(joints)
    }

    /// Reads a parameter file: `{"joints": {"shoulder_pan": {"registers": {...}, "mechanics":
    /// {...}}, ...}}`. Missing joints and fields are the [`ArmServoParams::sts3215`] values.
    pub fn load(path: &Path) -> Result<Self, ServoParamsError> {
        let text = std::fs::read_to_string(path).map_err(|source| ServoParamsError::Read {
            path: path.display().to_string(),
            source,
        })?;
        Self::from_json(&text).map_err(|error| match error {
            ServoParamsError::Parse { source, .. } => ServoParamsError::Parse {
                path: path.display().to_string(),
                source,
            },
            other => other,
        })
    }

    pub fn from_json(text: &str) -> Result<Self, ServoParamsError> {
        let file: ParamsFile =
            serde_json::from_str(text).map_err(|source| ServoParamsError::Parse {
                path: String::new(),
                source,
            })?;
        let mut params = Self::sts3215();
        for (name, joint) in file.joints {
            let index =
                crate::robot::joint_index(&name).ok_or_else(|| ServoParamsError::Parse {
                    path: String::new(),
                    source: serde::de::Error::custom(format!("{name:?} is not an SO-101 joint")),
                })?;
            let base = params.0[index];
            params.0[index] = joint.over(base).map_err(|source| ServoParamsError::Parse {
                path: String::new(),
                source,
            })?;
        }
        for (index, joint) in params.0.iter().enumerate() {
            joint.check(JOINT_NAMES[index])?;
        }
        Ok(params)
    }

    pub fn to_json(&self) -> String {
        let joints = JOINT_NAMES
            .iter()
            .zip(self.0.iter())
            .map(|(name, params)| ((*name).to_owned(), JointEntry::full(params)))
            .collect();
        serde_json::to_string_pretty(&ParamsFile { joints }).expect("plain numbers serialize")
    }
}

/// The servo model of the simulation's actuators.
#[derive(Debug, Clone, PartialEq)]
pub enum ServoModelChoice {
    /// The scene's own position actuator: gain 80 N m/rad, damping 3, ±3.35 N m; instant, no
    /// registers. The default before the STS3215 model, kept for comparison.
    Gain80,
    /// The STS3215 model with these parameters (boxed: six servos' worth of numbers).
    Sts3215(Box<ArmServoParams>),
}

impl Default for ServoModelChoice {
    /// The STS3215 model with its published parameters.
    fn default() -> Self {
        Self::Sts3215(Box::new(ArmServoParams::sts3215()))
    }
}

impl ServoModelChoice {
    pub fn name(&self) -> &'static str {
        match self {
            Self::Gain80 => GAIN80,
            Self::Sts3215(_) => STS3215,
        }
    }

    /// `gain80`, `sts3215` or the path of a parameter file.
    pub fn parse(text: &str) -> Result<Self, ServoParamsError> {
        match text {
            GAIN80 => Ok(Self::Gain80),
            STS3215 => Ok(Self::default()),
            path if path.ends_with(".json") => Self::load(Path::new(path)),
            other => Err(ServoParamsError::Model(other.to_owned())),
        }
    }

    /// The STS3215 model with a parameter file's values (any file name).
    pub fn load(path: &Path) -> Result<Self, ServoParamsError> {
        ArmServoParams::load(path).map(|params| Self::Sts3215(Box::new(params)))
    }

    /// The parameters of the STS3215 model `text` names (`sts3215` or a parameter file): what the
    /// emulator and the identification work with; `gain80` has none.
    pub fn parse_params(text: &str) -> Result<ArmServoParams, ServoParamsError> {
        match Self::parse(text)? {
            Self::Sts3215(params) => Ok(*params),
            Self::Gain80 => Err(ServoParamsError::NoParameters),
        }
    }
}

/// A servo model as the user named it (a preset's name or a parameter file's path) with the model
/// it gives: parsed, and its file read, once, where the option is taken; the name is what the
/// node's parameters and logs show.
#[derive(Debug, Clone, PartialEq)]
pub struct ServoModelSpec {
    name: String,
    choice: ServoModelChoice,
}

impl ServoModelSpec {
    /// `gain80`, `sts3215` or the path of a parameter file (.json).
    pub fn parse(text: &str) -> Result<Self, ServoParamsError> {
        Ok(Self {
            name: text.to_owned(),
            choice: ServoModelChoice::parse(text)?,
        })
    }

    /// A parameter file, whatever its name (a path handed over as a path, not as text).
    pub fn load(path: &Path) -> Result<Self, ServoParamsError> {
        Ok(Self {
            name: path.display().to_string(),
            choice: ServoModelChoice::load(path)?,
        })
    }

    /// The preset's name or the file's path, as given.
    pub fn name(&self) -> &str {
        &self.name
    }

    pub fn choice(&self) -> &ServoModelChoice {
        &self.choice
    }

    pub fn into_choice(self) -> ServoModelChoice {
        self.choice
    }
}

impl Default for ServoModelSpec {
    fn default() -> Self {
        Self {
            name: DEFAULT_SERVO_MODEL.to_owned(),
            choice: ServoModelChoice::default(),
        }
    }
}

impl fmt::Display for ServoModelSpec {
    fn fmt(&self, formatter: &mut fmt::Formatter<'_>) -> fmt::Result {
        formatter.write_str(&self.name)
    }
}

impl FromStr for ServoModelSpec {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, Self::Err> {
        Self::parse(text).map_err(|error| error.to_string())
    }
}

impl fmt::Display for ServoModelChoice {
    fn fmt(&self, formatter: &mut fmt::Formatter<'_>) -> fmt::Result {
        formatter.write_str(self.name())
    }
}

#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct ParamsFile {
    joints: std::collections::BTreeMap<String, JointEntry>,
}

/// A joint's entry: every field optional, over the preset's.
#[derive(Debug, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct JointEntry {
    #[serde(default)]
    registers: serde_json::Map<String, serde_json::Value>,
    #[serde(default)]
    mechanics: serde_json::Map<String, serde_json::Value>,
}

impl JointEntry {
    fn full(params: &ServoParams) -> Self {
        let object = |value: serde_json::Value| match value {
            serde_json::Value::Object(map) => map,
            _ => serde_json::Map::new(),
        };
        Self {
            registers: object(serde_json::to_value(params.registers).unwrap_or_default()),
            mechanics: object(serde_json::to_value(params.mechanics).unwrap_or_default()),
        }
    }

    /// The preset's values with this entry's fields over them (unknown names are an error).
    fn over(self, base: ServoParams) -> Result<ServoParams, serde_json::Error> {
        let merge = |base: serde_json::Value,
                     fields: serde_json::Map<String, serde_json::Value>| {
            let mut map = match base {
                serde_json::Value::Object(map) => map,
                _ => serde_json::Map::new(),
            };
            map.extend(fields);
            serde_json::Value::Object(map)
        };
        let registers = merge(
            serde_json::to_value(base.registers).unwrap_or_default(),
            self.registers,
        );
        let mechanics = merge(
            serde_json::to_value(base.mechanics).unwrap_or_default(),
            self.mechanics,
        );
        Ok(ServoParams {
            registers: serde_json::from_value(registers)?,
            mechanics: serde_json::from_value(mechanics)?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_spec_keeps_the_users_name_and_reads_its_file_once() {
        let default = ServoModelSpec::default();
        assert_eq!(default, ServoModelSpec::parse(DEFAULT_SERVO_MODEL).unwrap());
        assert_eq!(default.to_string(), "sts3215");
        assert_eq!(
            ServoModelSpec::parse(GAIN80).unwrap().choice(),
            &ServoModelChoice::Gain80
        );
        let path = std::env::temp_dir().join(format!("so101_servo_{}.json", std::process::id()));
        let mut params = ArmServoParams::sts3215();
        params.0[0].mechanics.latency = 0.02;
        std::fs::write(&path, params.to_json()).unwrap();
        let spec: ServoModelSpec = path.to_str().unwrap().parse().unwrap();
        std::fs::remove_file(&path).unwrap();
        assert_eq!(spec.name(), path.display().to_string());
        let ServoModelChoice::Sts3215(read) = spec.into_choice() else {
            panic!("a parameter file is the STS3215 model");
        };
        assert!((read.0[0].mechanics.latency - 0.02).abs() < 1e-12);
    }

    #[test]
    fn a_bad_name_is_refused_with_the_choices() {
        let error = "sts9999".parse::<ServoModelSpec>().unwrap_err();
        assert_eq!(
            error,
            "\"sts9999\" is not a servo model: use gain80, sts3215 or a parameter file (.json)"
        );
        assert!(matches!(
            ServoModelChoice::parse_params(GAIN80),
            Err(ServoParamsError::NoParameters)
        ));
        assert_eq!(
            ServoModelChoice::parse_params(STS3215).unwrap(),
            ArmServoParams::sts3215()
        );
    }
}
