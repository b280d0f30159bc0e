//! What the driver's integration tests share: the LeRobot calibration of the emulated arm (ids
//! 1..6; non-zero offsets so the servo-side Homing_Offset is at work).

use std::path::Path;

use so101_feetech_driver::calibration::ArmCalibration;

pub const CALIBRATION: &str = r#"{
    "shoulder_pan": {"id": 1, "drive_mode": 0, "homing_offset": 100, "range_min": 1000, "range_max": 3000},
    "shoulder_lift": {"id": 2, "drive_mode": 0, "homing_offset": -200, "range_min": 900, "range_max": 3100},
    "elbow_flex": {"id": 3, "drive_mode": 0, "homing_offset": 0, "range_min": 1000, "range_max": 3000},
    "wrist_flex": {"id": 4, "drive_mode": 0, "homing_offset": 0, "range_min": 1000, "range_max": 3000},
    "wrist_roll": {"id": 5, "drive_mode": 0, "homing_offset": 0, "range_min": 0, "range_max": 4095},
    "gripper": {"id": 6, "drive_mode": 0, "homing_offset": 0, "range_min": 2000, "range_max": 3000}
}"#;

pub fn calibration() -> ArmCalibration {
    // The fixture is valid JSON of six motors; a failure here is a broken test, reported loudly.
    #[allow(clippy::unwrap_used)]
    ArmCalibration::from_json(CALIBRATION, Path::new("test.json")).unwrap()
}
