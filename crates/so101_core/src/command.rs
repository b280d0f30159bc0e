//! Validation of position commands from the topic contract, shared by the simulation and the driver.
//!
//! A command is rejected whole when any part of it is malformed (non-finite values, unknown joint
//! names, length mismatches): applying half of a malformed message could move the arm somewhere
//! nobody asked for. Well-formed targets outside the joint limits are clamped, not rejected, which is
//! what a position controller with limits does.

use crate::robot::{joint_index, JointLimit, JointPositions, JOINT_COUNT, JOINT_NAMES};

/// Why a command was rejected.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CommandError {
    #[error("command names {names} joints but carries {positions} positions")]
    LengthMismatch { names: usize, positions: usize },
    #[error("command carries no positions")]
    Empty,
    #[error("unknown joint name {0:?} (expected one of {JOINT_NAMES:?})")]
    UnknownJoint(String),
    #[error("joint {0:?} is named twice")]
    DuplicateJoint(String),
    #[error("position of {joint} is not finite ({value})")]
    NotFinite { joint: &'static str, value: f64 },
    #[error("array command has {0} values, expected {JOINT_COUNT} (one per joint in order {JOINT_NAMES:?})")]
    WrongArrayLength(usize),
}

/// Target positions for a subset of the joints, validated but not yet clamped.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PartialTargets {
    targets: [Option<f64>; JOINT_COUNT],
}

impl PartialTargets {
    /// Targets already checked elsewhere (a validated trajectory's samples).
    pub fn from_validated(targets: [Option<f64>; JOINT_COUNT]) -> Self {
        Self { targets }
    }

    pub fn get(&self, joint: usize) -> Option<f64> {
        self.targets[joint]
    }

    /// Applies these targets onto `current`, clamping each one to its joint limit; joints not named
    /// keep their current target.
    pub fn apply_clamped(&self, current: &mut JointPositions, limits: &[JointLimit; JOINT_COUNT]) {
        for (joint, target) in self.targets.iter().enumerate() {
            if let Some(value) = target {
                current[joint] = limits[joint].clamp(*value);
            }
        }
    }
}

/// Validates a sensor_msgs/JointState command: positions by name, any non-empty subset of joints.
/// Velocity and effort fields are ignored (this is a position interface).
pub fn targets_from_joint_state(
    names: &[String],
    positions: &[f64],
) -> Result<PartialTargets, CommandError> {
    if names.len() != positions.len() {
        return Err(CommandError::LengthMismatch {
            names: names.len(),
            positions: positions.len(),
        });
    }
    if names.is_empty() {
        return Err(CommandError::Empty);
    }
    let mut result = PartialTargets::default();
    for (name, &value) in names.iter().zip(positions) {
        let joint = joint_index(name).ok_or_else(|| CommandError::UnknownJoint(name.clone()))?;
        if result.targets[joint].is_some() {
            return Err(CommandError::DuplicateJoint(name.clone()));
        }
        result.targets[joint] = Some(finite(joint, value)?);
    }
    Ok(result)
}

fn finite(joint: usize, value: f64) -> Result<f64, CommandError> {
    if value.is_finite() {
        Ok(value)
    } else {
        Err(CommandError::NotFinite {
            joint: JOINT_NAMES[joint],
            value,
        })
    }
}

/// Validates a std_msgs/Float64MultiArray command: exactly one position per joint, in joint order.
pub fn targets_from_array(values: &[f64]) -> Result<PartialTargets, CommandError> {
    if values.len() != JOINT_COUNT {
        return Err(CommandError::WrongArrayLength(values.len()));
    }
    let mut result = PartialTargets::default();
    for (joint, &value) in values.iter().enumerate() {
        result.targets[joint] = Some(finite(joint, value)?);
    }
    Ok(result)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robot::JOINT_LIMITS;

    fn names(list: &[&str]) -> Vec<String> {
        list.iter().map(|name| name.to_string()).collect()
    }

    #[test]
    fn partial_command_moves_only_named_joints() {
        let targets =
            targets_from_joint_state(&names(&["elbow_flex", "gripper"]), &[0.5, 1.0]).unwrap();
        let mut current = [0.1; JOINT_COUNT];
        targets.apply_clamped(&mut current, &JOINT_LIMITS);
        assert_eq!(current, [0.1, 0.1, 0.5, 0.1, 0.1, 1.0]);
    }

    #[test]
    fn out_of_range_targets_are_clamped_to_the_limits() {
        let targets =
            targets_from_joint_state(&names(&["shoulder_pan", "gripper"]), &[1e9, -1e9]).unwrap();
        let mut current = [0.0; JOINT_COUNT];
        targets.apply_clamped(&mut current, &JOINT_LIMITS);
        assert_eq!(current[0], JOINT_LIMITS[0].max);
        assert_eq!(current[5], JOINT_LIMITS[5].min);
    }

    #[test]
    fn malformed_joint_state_commands_are_rejected_whole() {
        let cases: Vec<(Vec<String>, Vec<f64>, CommandError)> = vec![
            (
                names(&["gripper"]),
                vec![],
                CommandError::LengthMismatch {
                    names: 1,
                    positions: 0,
                },
            ),
            (names(&[]), vec![], CommandError::Empty),
            (
                names(&["gripper", "nose"]),
                vec![0.0, 0.0],
                CommandError::UnknownJoint("nose".into()),
            ),
            (
                names(&["gripper", "gripper"]),
                vec![0.0, 0.1],
                CommandError::DuplicateJoint("gripper".into()),
            ),
        ];
        for (names, positions, expected) in cases {
            assert_eq!(targets_from_joint_state(&names, &positions), Err(expected));
        }
        for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            let result =
                targets_from_joint_state(&names(&["shoulder_pan", "wrist_roll"]), &[0.2, bad]);
            assert!(
                matches!(
                    result,
                    Err(CommandError::NotFinite {
                        joint: "wrist_roll",
                        ..
                    })
                ),
                "{result:?}"
            );
        }
    }

    #[test]
    fn array_commands_need_six_finite_values() {
        assert_eq!(
            targets_from_array(&[0.0; 5]),
            Err(CommandError::WrongArrayLength(5))
        );
        assert_eq!(
            targets_from_array(&[0.0; 7]),
            Err(CommandError::WrongArrayLength(7))
        );
        let mut values = [0.0; JOINT_COUNT];
        values[3] = f64::NAN;
        assert!(matches!(
            targets_from_array(&values),
            Err(CommandError::NotFinite {
                joint: "wrist_flex",
                ..
            })
        ));
        let targets = targets_from_array(&[0.1, 0.2, 0.3, 0.4, 0.5, 0.6]).unwrap();
        assert_eq!(targets.get(5), Some(0.6));
    }
}
