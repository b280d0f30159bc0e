//! End-effector actions: a target gripper pose in the arm's base frame (the five coordinates the
//! 5-DoF arm reaches: the grasp point's x, y, z in m, the approach pitch and the jaws' roll in rad,
//! as [`kinematics::TaskPose`] defines them) plus the gripper's joint target (rad), turned into
//! joint targets by the shared IK each control period. A target the arm cannot reach becomes the
//! nearest pose it reaches (the IK's own degradation), and the step says so. Pure: no I/O.

use nalgebra::Vector3;

use crate::{
    kinematics::{self, ArmPositions, IkOptions, TaskPose, ARM_JOINTS},
    robot::{JointPositions, JOINT_COUNT, JOINT_LIMITS},
};

/// The coordinates of an end-effector action or state, in order (units: m, m, m, rad, rad, rad).
pub const EE_NAMES: [&str; JOINT_COUNT] = ["x", "y", "z", "pitch", "roll", "gripper"];

/// One end-effector action or state, in [`EE_NAMES`] order.
pub type EePose = [f64; JOINT_COUNT];

/// What one end-effector action commands.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EeStep {
    /// Joint targets (rad) for the period, inside the joint limits.
    pub targets: JointPositions,
    /// The target was out of reach (or past a limit): `targets` reach the nearest pose instead.
    pub clamped: bool,
    /// How far the reached pose is from the target: m, and the larger angle error in rad.
    pub position_error: f64,
    pub angle_error: f64,
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EeError {
    #[error("an end-effector action is 6 finite numbers (x y z m, pitch roll rad, gripper rad), not {0:?}")]
    NotFinite(Vec<f64>),
}

/// The end-effector state of a joint configuration: forward kinematics of the arm, and the
/// gripper's joint as it is. The roll is continuous over wrist_roll's whole range (it runs from
/// about -1.2 to 4.4 rad), not wrapped at +-pi: the jaws' roll is a fixed offset minus wrist_roll, so a
/// dataset's roll never jumps by a turn where the wrist crosses the wrap.
pub fn ee_pose(joints: &JointPositions) -> EePose {
    let arm: ArmPositions = std::array::from_fn(|joint| joints[joint]);
    let pose = kinematics::task_pose(&arm);
    let wrist_roll = joints[ARM_JOINTS - 1];
    let roll = kinematics::wrap_angle(pose.roll + wrist_roll) - wrist_roll;
    [
        pose.position.x,
        pose.position.y,
        pose.position.z,
        pose.pitch,
        roll,
        joints[JOINT_COUNT - 1],
    ]
}

/// Joint targets reaching `action`, the IK starting from `current` (the targets in force: the
/// solution stays on their branch and moves least).
pub fn joint_targets(action: &EePose, current: &JointPositions) -> Result<EeStep, EeError> {
    if !action.iter().all(|value| value.is_finite()) {
        return Err(EeError::NotFinite(action.to_vec()));
    }
    let target = TaskPose {
        position: Vector3::new(action[0], action[1], action[2]),
        pitch: action[3],
        roll: action[4],
    };
    let seed: ArmPositions = std::array::from_fn(|joint| current[joint]);
    let solution = kinematics::solve(
        &target,
        &seed,
        &kinematics::arm_limits(),
        &IkOptions::default(),
    );
    let targets = std::array::from_fn(|joint| {
        if joint < ARM_JOINTS {
            solution.joints[joint]
        } else {
            JOINT_LIMITS[joint].clamp(action[joint])
        }
    });
    Ok(EeStep {
        targets,
        clamped: !solution.reached,
        position_error: solution.position_error,
        angle_error: solution.angle_error,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    #[test]
    fn a_reachable_pose_round_trips_through_ik_and_forward_kinematics() {
        let joints = [0.3, -0.4, 0.5, 1.0, -0.2, 0.6];
        let pose = ee_pose(&joints);
        let step = joint_targets(&pose, &[0.0; 6]).unwrap();
        assert!(!step.clamped, "{step:?}");
        let back = ee_pose(&step.targets);
        for (coordinate, (a, b)) in pose.iter().zip(back).enumerate() {
            assert!((a - b).abs() < 2e-3, "{}: {a} vs {b}", EE_NAMES[coordinate]);
        }
        assert_eq!(step.targets[5], 0.6);
    }

    #[test]
    fn the_roll_is_continuous_over_the_wrist_rolls_range() {
        let range = JOINT_LIMITS[ARM_JOINTS - 1];
        let rolls: Vec<f64> = (0..=200)
            .map(|k| {
                let wrist = range.min + (range.max - range.min) * k as f64 / 200.0;
                ee_pose(&[0.2, -0.5, 0.8, 1.2, wrist, 0.0])[4]
            })
            .collect();
        for pair in rolls.windows(2) {
            let step = pair[1] - pair[0];
            assert!(step < 0.0 && step > -0.05, "{pair:?}");
        }
        // And the IK reaches a roll past pi (the wrist near its lower limit).
        let joints = [0.2, -0.5, 0.8, 1.2, range.min + 0.1, 0.0];
        let pose = ee_pose(&joints);
        assert!(pose[4] > PI, "{pose:?}");
        let step = joint_targets(&pose, &[0.0; 6]).unwrap();
        assert!(
            !step.clamped && (step.targets[4] - joints[4]).abs() < 2e-3,
            "{step:?}"
        );
    }

    #[test]
    fn an_unreachable_target_is_clamped_to_the_nearest_reachable_pose() {
        let far = [1.5, 0.0, 0.1, 1.0, 0.0, 0.0];
        let step = joint_targets(&far, &[0.0; 6]).unwrap();
        assert!(step.clamped && step.position_error > 0.5, "{step:?}");
        for (joint, value) in step.targets.iter().enumerate() {
            assert!(JOINT_LIMITS[joint].contains(*value));
        }
        // Nearest: the arm stretches towards it, further out than at home.
        let reached = ee_pose(&step.targets);
        assert!(reached[0] > ee_pose(&[0.0; 6])[0]);
    }

    #[test]
    fn the_gripper_is_kept_inside_its_limits_and_bad_numbers_are_refused() {
        let mut pose = ee_pose(&[0.0; 6]);
        pose[5] = 9.0;
        assert_eq!(
            joint_targets(&pose, &[0.0; 6]).unwrap().targets[5],
            JOINT_LIMITS[5].max
        );
        pose[2] = f64::NAN;
        assert!(joint_targets(&pose, &[0.0; 6]).is_err());
    }
}
