//! Calibration in LeRobot's format and place, and the conversion between servo ticks and the
//! radians of the topic contract.
//!
//! A LeRobot calibration file maps each motor name to `{id, drive_mode, homing_offset, range_min,
//! range_max}`. The servo subtracts Homing_Offset itself, so the ticks read back are already
//! centred; range_min/range_max bound every goal.
//!
//! Radians: arm joints use LeRobot's DEGREES mapping, `deg = (ticks - mid) * 360 / 4095` with
//! `mid` the middle of the calibrated range, so `rad.to_degrees()` is exactly what LeRobot records.
//! The gripper (LeRobot's RANGE_0_100) is the angle from the closed end of its range, offset to the
//! model's closed limit, so sim and real share the gripper's radian range.

use std::{
    collections::BTreeMap,
    f64::consts::PI,
    path::{Path, PathBuf},
};

use serde::{Deserialize, Serialize};
use so101_core::{
    robot::{JOINT_COUNT, JOINT_LIMITS, JOINT_NAMES},
    servo::TICKS_PER_REVOLUTION,
};

use crate::protocol::MAX_ID;

/// LeRobot divides by the model's resolution minus one (4095), not by 4096.
const RADIANS_PER_TICK: f64 = 2.0 * PI / MAX_TICKS as f64;
/// Index of the gripper in joint order.
const GRIPPER: usize = 5;
/// Highest tick value of a 12-bit position.
pub const MAX_TICKS: i32 = TICKS_PER_REVOLUTION as i32 - 1;
/// Largest Homing_Offset the register holds (sign-magnitude, 11 bits).
pub const MAX_HOMING_OFFSET: i32 = 2047;

/// One motor's entry in a LeRobot calibration file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct MotorCalibration {
    pub id: u8,
    pub drive_mode: u8,
    pub homing_offset: i32,
    pub range_min: i32,
    pub range_max: i32,
}

impl MotorCalibration {
    fn mid(&self) -> f64 {
        f64::from(self.range_min + self.range_max) / 2.0
    }

    fn inverted(&self) -> bool {
        self.drive_mode != 0
    }

    /// Clamps ticks into the calibrated range.
    pub fn clamp_ticks(&self, ticks: i32) -> i32 {
        ticks.clamp(self.range_min, self.range_max)
    }
}

/// Which side of a teleoperation pair an arm is; decides where LeRobot keeps its file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ArmRole {
    Follower,
    Leader,
}

#[derive(Debug, thiserror::Error)]
pub enum CalibrationError {
    #[error("no calibration file at {path}: calibrate first (`so101_feetech_driver calibrate --robot-id ID`, or LeRobot's lerobot-calibrate)")]
    Missing { path: PathBuf },
    #[error("cannot read calibration {path}: {source}")]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("calibration {path} is not valid LeRobot calibration JSON: {source}")]
    Parse {
        path: PathBuf,
        source: serde_json::Error,
    },
    #[error("calibration {path}: {problem}")]
    Invalid { path: PathBuf, problem: String },
    #[error("cannot write calibration {path}: {source}")]
    Write {
        path: PathBuf,
        source: std::io::Error,
    },
}

/// The calibration of all six motors, in joint order.
#[derive(Debug, Clone, PartialEq)]
pub struct ArmCalibration {
    pub motors: [MotorCalibration; JOINT_COUNT],
}

impl ArmCalibration {
    /// Parses LeRobot's JSON and checks every value against what the servos can hold.
    pub fn from_json(text: &str, path: &Path) -> Result<Self, CalibrationError> {
        let map: BTreeMap<String, MotorCalibration> =
            serde_json::from_str(text).map_err(|source| CalibrationError::Parse {
                path: path.to_owned(),
                source,
            })?;
        let invalid = |problem: String| CalibrationError::Invalid {
            path: path.to_owned(),
            problem,
        };
        if let Some(extra) = map
            .keys()
            .find(|name| !JOINT_NAMES.contains(&name.as_str()))
        {
            return Err(invalid(format!(
                "unknown motor {extra:?} (expected {JOINT_NAMES:?})"
            )));
        }
        let mut motors = Vec::with_capacity(JOINT_COUNT);
        for name in JOINT_NAMES {
            let motor = map
                .get(name)
                .ok_or_else(|| invalid(format!("motor {name:?} is missing")))?;
            validate_motor(name, motor).map_err(invalid)?;
            motors.push(*motor);
        }
        let mut ids: Vec<u8> = motors.iter().map(|motor| motor.id).collect();
        ids.sort_unstable();
        ids.dedup();
        if ids.len() != JOINT_COUNT {
            return Err(invalid("two motors share an id".into()));
        }
        let motors = motors
            .try_into()
            .map_err(|_| invalid("wrong motor count".into()))?;
        Ok(Self { motors })
    }

    /// LeRobot's JSON (motor names in joint order, 4-space indent like LeRobot writes it).
    pub fn to_json(&self) -> String {
        let mut out = String::from("{\n");
        for (index, (name, motor)) in JOINT_NAMES.iter().zip(&self.motors).enumerate() {
            let comma = if index + 1 < JOINT_COUNT { "," } else { "" };
            out.push_str(&format!(
                "    \"{name}\": {{\n        \"id\": {},\n        \"drive_mode\": {},\n        \"homing_offset\": {},\n        \"range_min\": {},\n        \"range_max\": {}\n    }}{comma}\n",
                motor.id, motor.drive_mode, motor.homing_offset, motor.range_min, motor.range_max
            ));
        }
        out.push('}');
        out
    }

    pub fn load(path: &Path) -> Result<Self, CalibrationError> {
        let text = std::fs::read_to_string(path).map_err(|source| {
            if source.kind() == std::io::ErrorKind::NotFound {
                CalibrationError::Missing {
                    path: path.to_owned(),
                }
            } else {
                CalibrationError::Read {
                    path: path.to_owned(),
                    source,
                }
            }
        })?;
        Self::from_json(&text, path)
    }

    /// Writes the file atomically (a crash never leaves half a calibration).
    pub fn save(&self, path: &Path) -> Result<(), CalibrationError> {
        let write_error = |source| CalibrationError::Write {
            path: path.to_owned(),
            source,
        };
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent).map_err(write_error)?;
        }
        let temporary = path.with_extension("json.tmp");
        std::fs::write(&temporary, self.to_json()).map_err(write_error)?;
        std::fs::rename(&temporary, path).map_err(write_error)
    }

    pub fn ids(&self) -> [u8; JOINT_COUNT] {
        self.motors.map(|motor| motor.id)
    }

    /// Joint position in rad from the ticks the servo reports.
    pub fn radians_from_ticks(&self, joint: usize, ticks: i32) -> f64 {
        let motor = &self.motors[joint];
        if joint == GRIPPER {
            let from_closed = if motor.inverted() {
                motor.range_max - ticks
            } else {
                ticks - motor.range_min
            };
            JOINT_LIMITS[GRIPPER].min + f64::from(from_closed) * RADIANS_PER_TICK
        } else {
            (f64::from(ticks) - motor.mid()) * RADIANS_PER_TICK
        }
    }

    /// Ticks for a joint position in rad, clamped into the calibrated range.
    pub fn ticks_from_radians(&self, joint: usize, radians: f64) -> i32 {
        let motor = &self.motors[joint];
        let ticks = if joint == GRIPPER {
            let from_closed = (radians - JOINT_LIMITS[GRIPPER].min) / RADIANS_PER_TICK;
            if motor.inverted() {
                f64::from(motor.range_max) - from_closed
            } else {
                f64::from(motor.range_min) + from_closed
            }
        } else {
            radians / RADIANS_PER_TICK + motor.mid()
        };
        // The clamp to the range also bounds the f64 -> i32 conversion.
        motor.clamp_ticks(ticks.round().clamp(0.0, f64::from(MAX_TICKS)) as i32)
    }

    /// Every joint's position in rad from the ticks its servo reports.
    pub fn positions_from_ticks(&self, ticks: &[i32; JOINT_COUNT]) -> [f64; JOINT_COUNT] {
        std::array::from_fn(|joint| self.radians_from_ticks(joint, ticks[joint]))
    }

    /// Every joint's goal in ticks for positions in rad, clamped into the calibrated ranges.
    pub fn ticks_from_positions(&self, positions: &[f64; JOINT_COUNT]) -> [i32; JOINT_COUNT] {
        std::array::from_fn(|joint| self.ticks_from_radians(joint, positions[joint]))
    }

    /// Joint velocity in rad/s from Present_Velocity (ticks/s).
    pub fn radians_per_second(&self, joint: usize, ticks_per_second: i32) -> f64 {
        let sign = if joint == GRIPPER && self.motors[joint].inverted() {
            -1.0
        } else {
            1.0
        };
        sign * f64::from(ticks_per_second) * RADIANS_PER_TICK
    }

    /// Every joint's calibrated range in rad (ordered low..high).
    pub fn limits_in_radians(&self) -> [(f64, f64); JOINT_COUNT] {
        std::array::from_fn(|joint| {
            let motor = &self.motors[joint];
            let a = self.radians_from_ticks(joint, motor.range_min);
            let b = self.radians_from_ticks(joint, motor.range_max);
            (a.min(b), a.max(b))
        })
    }
}

/// Checks one motor's entry against what the servos can hold.
pub fn validate_motor(name: &str, motor: &MotorCalibration) -> Result<(), String> {
    if motor.id == 0 || motor.id > MAX_ID {
        return Err(format!("{name}: id {} is not 1..={MAX_ID}", motor.id));
    }
    if motor.drive_mode > 1 {
        return Err(format!(
            "{name}: drive_mode {} is not 0 or 1",
            motor.drive_mode
        ));
    }
    if motor.homing_offset.abs() > MAX_HOMING_OFFSET {
        return Err(format!(
            "{name}: homing_offset {} exceeds +-{MAX_HOMING_OFFSET} (the register's sign-magnitude limit)",
            motor.homing_offset
        ));
    }
    if !(0..=MAX_TICKS).contains(&motor.range_min)
        || !(0..=MAX_TICKS).contains(&motor.range_max)
        || motor.range_min >= motor.range_max
    {
        return Err(format!(
            "{name}: range {}..{} is not an increasing range within 0..{MAX_TICKS}",
            motor.range_min, motor.range_max
        ));
    }
    Ok(())
}

/// LeRobot's calibration directory: $HF_LEROBOT_CALIBRATION, else $HF_LEROBOT_HOME/calibration,
/// else $HF_HOME/lerobot/calibration, else ~/.cache/huggingface/lerobot/calibration.
pub fn lerobot_calibration_dir(env: impl Fn(&str) -> Option<String>) -> PathBuf {
    let set = |name: &str| {
        env(name)
            .filter(|value| !value.is_empty())
            .map(PathBuf::from)
    };
    if let Some(dir) = set("HF_LEROBOT_CALIBRATION") {
        return dir;
    }
    if let Some(home) = set("HF_LEROBOT_HOME") {
        return home.join("calibration");
    }
    let hf_home = set("HF_HOME").unwrap_or_else(|| {
        set("XDG_CACHE_HOME")
            .or_else(|| set("HOME").map(|home| home.join(".cache")))
            .unwrap_or_else(|| PathBuf::from(".cache"))
            .join("huggingface")
    });
    hf_home.join("lerobot").join("calibration")
}

/// Where LeRobot keeps the calibration of arm `robot_id` in `role`.
pub fn lerobot_calibration_path(base: &Path, role: ArmRole, robot_id: &str) -> PathBuf {
    let folder = match role {
        ArmRole::Follower => Path::new("robots").join("so_follower"),
        ArmRole::Leader => Path::new("teleoperators").join("so_leader"),
    };
    base.join(folder).join(format!("{robot_id}.json"))
}

#[cfg(test)]
mod tests {
    use super::*;

    const LEROBOT_FILE: &str = r#"{
        "shoulder_pan": {"id": 1, "drive_mode": 0, "homing_offset": -447, "range_min": 760, "range_max": 3300},
        "shoulder_lift": {"id": 2, "drive_mode": 0, "homing_offset": 1200, "range_min": 800, "range_max": 3200},
        "elbow_flex": {"id": 3, "drive_mode": 0, "homing_offset": 0, "range_min": 900, "range_max": 3100},
        "wrist_flex": {"id": 4, "drive_mode": 0, "homing_offset": 12, "range_min": 850, "range_max": 3250},
        "wrist_roll": {"id": 5, "drive_mode": 0, "homing_offset": 0, "range_min": 0, "range_max": 4095},
        "gripper": {"id": 6, "drive_mode": 0, "homing_offset": -900, "range_min": 2000, "range_max": 3300}
    }"#;

    fn calibration() -> ArmCalibration {
        ArmCalibration::from_json(LEROBOT_FILE, Path::new("test.json")).unwrap()
    }

    #[test]
    fn lerobot_files_round_trip() {
        let calibration = calibration();
        assert_eq!(calibration.ids(), [1, 2, 3, 4, 5, 6]);
        assert_eq!(calibration.motors[0].homing_offset, -447);
        let again = ArmCalibration::from_json(&calibration.to_json(), Path::new("x")).unwrap();
        assert_eq!(again, calibration);
        let value: serde_json::Value = serde_json::from_str(&calibration.to_json()).unwrap();
        assert_eq!(value["gripper"]["range_max"], 3300);
    }

    #[test]
    fn radians_match_lerobot_degrees() {
        let calibration = calibration();
        // shoulder_pan mid = 2030; 2030 + 4095/4 ticks is 90 degrees in LeRobot's units.
        let quarter: f64 = 2030.0 + 4095.0 / 4.0;
        let radians = calibration.radians_from_ticks(0, quarter as i32);
        assert!((radians.to_degrees() - (quarter.floor() - 2030.0) * 360.0 / 4095.0).abs() < 1e-9);
        for ticks in [760, 1000, 2030, 3300] {
            let back = calibration.ticks_from_radians(0, calibration.radians_from_ticks(0, ticks));
            assert_eq!(back, ticks);
        }
    }

    #[test]
    fn goals_are_clamped_to_the_calibrated_range() {
        let calibration = calibration();
        assert_eq!(calibration.ticks_from_radians(0, 100.0), 3300);
        assert_eq!(calibration.ticks_from_radians(0, -100.0), 760);
        assert_eq!(calibration.ticks_from_radians(5, -5.0), 2000);
        let (low, high) = calibration.limits_in_radians()[5];
        assert!((low - JOINT_LIMITS[5].min).abs() < 1e-12 && high > low);
    }

    #[test]
    fn the_gripper_counts_from_its_closed_end_and_honours_drive_mode() {
        let mut calibration = calibration();
        assert!((calibration.radians_from_ticks(5, 2000) - JOINT_LIMITS[5].min).abs() < 1e-12);
        calibration.motors[5].drive_mode = 1;
        assert!((calibration.radians_from_ticks(5, 3300) - JOINT_LIMITS[5].min).abs() < 1e-12);
        let ticks = calibration.ticks_from_radians(5, 0.5);
        assert!((calibration.radians_from_ticks(5, ticks) - 0.5).abs() < RADIANS_PER_TICK);
        assert!(calibration.radians_per_second(5, 100) < 0.0);
    }

    #[test]
    fn invalid_files_are_refused_with_the_reason() {
        let bad = LEROBOT_FILE.replace("\"homing_offset\": -447", "\"homing_offset\": -3000");
        let error = ArmCalibration::from_json(&bad, Path::new("c.json")).unwrap_err();
        assert!(error.to_string().contains("exceeds"), "{error}");
        let bad = LEROBOT_FILE.replace("\"id\": 6", "\"id\": 5");
        assert!(ArmCalibration::from_json(&bad, Path::new("c.json")).is_err());
        let bad = LEROBOT_FILE.replace("\"range_min\": 900", "\"range_min\": 3900");
        assert!(ArmCalibration::from_json(&bad, Path::new("c.json")).is_err());
        assert!(matches!(
            ArmCalibration::from_json("{", Path::new("c.json")),
            Err(CalibrationError::Parse { .. })
        ));
    }

    #[test]
    fn lerobot_locations() {
        let env = |vars: &'static [(&'static str, &'static str)]| {
            move |name: &str| {
                vars.iter()
                    .find(|(key, _)| *key == name)
                    .map(|(_, value)| value.to_string())
            }
        };
        assert_eq!(
            lerobot_calibration_dir(env(&[("HOME", "/home/u")])),
            Path::new("/home/u/.cache/huggingface/lerobot/calibration")
        );
        assert_eq!(
            lerobot_calibration_dir(env(&[("HOME", "/h"), ("HF_HOME", "/hf")])),
            Path::new("/hf/lerobot/calibration")
        );
        assert_eq!(
            lerobot_calibration_dir(env(&[("HF_LEROBOT_CALIBRATION", "/c")])),
            Path::new("/c")
        );
        assert_eq!(
            lerobot_calibration_path(Path::new("/c"), ArmRole::Leader, "arm"),
            Path::new("/c/teleoperators/so_leader/arm.json")
        );
    }
}
