//! What the operator asks for, and how it becomes joint targets: velocities in joint space, or of
//! the grasp point in Cartesian space (solved by the shared IK), integrated over each control
//! period and always kept inside the joint limits. Pure: no I/O.

use nalgebra::Vector3;
use so101_core::{
    kinematics::{self, ArmPositions, IkOptions, TaskPose, ARM_JOINTS},
    robot::{JointPositions, JOINT_COUNT, JOINT_LIMITS},
};

/// Joint space or Cartesian end-effector space.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Mode {
    Joint,
    Cartesian,
}

impl Mode {
    pub fn toggled(self) -> Self {
        match self {
            Self::Joint => Self::Cartesian,
            Self::Cartesian => Self::Joint,
        }
    }
}

/// A velocity request, each axis in -1..1 of its full speed.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Jog {
    /// Joint mode: the six joints in contract order. Cartesian mode: x, y, z (base frame), pitch,
    /// roll, and the gripper.
    pub axes: [f64; JOINT_COUNT],
}

impl Jog {
    pub const STILL: Self = Self {
        axes: [0.0; JOINT_COUNT],
    };

    pub fn is_still(&self) -> bool {
        self.axes.iter().all(|axis| *axis == 0.0)
    }
}

/// Full speeds of each kind of axis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Speeds {
    /// rad/s of each arm joint in joint mode.
    pub joint: f64,
    /// m/s of the grasp point in Cartesian mode.
    pub linear: f64,
    /// rad/s of pitch and roll in Cartesian mode.
    pub angular: f64,
    /// rad/s of the gripper in both modes.
    pub gripper: f64,
}

/// The last index of a [`Jog`]: the gripper in both modes.
const GRIPPER: usize = JOINT_COUNT - 1;

/// Joint targets moved by `jog` for `dt` seconds in joint space, clamped to the limits.
pub fn jog_joints(targets: &JointPositions, jog: &Jog, speeds: &Speeds, dt: f64) -> JointPositions {
    std::array::from_fn(|joint| {
        let speed = if joint == GRIPPER {
            speeds.gripper
        } else {
            speeds.joint
        };
        let axis = jog.axes[joint].clamp(-1.0, 1.0);
        JOINT_LIMITS[joint].clamp(targets[joint] + axis * speed * dt)
    })
}

/// Outcome of one Cartesian step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CartesianStep {
    pub targets: JointPositions,
    /// False when the requested pose was out of reach (or past a limit): the arm went as far as it
    /// could and the pose it reached becomes the new start.
    pub reached: bool,
}

/// Joint targets for the grasp point moved by `jog` for `dt` seconds, from the pose of `targets`.
pub fn jog_cartesian(
    targets: &JointPositions,
    jog: &Jog,
    speeds: &Speeds,
    dt: f64,
) -> CartesianStep {
    let arm: ArmPositions = std::array::from_fn(|joint| targets[joint]);
    let axis = |index: usize| jog.axes[index].clamp(-1.0, 1.0);
    let start = kinematics::task_pose(&arm);
    let goal = TaskPose {
        position: start.position + Vector3::new(axis(0), axis(1), axis(2)) * speeds.linear * dt,
        pitch: start.pitch + axis(3) * speeds.angular * dt,
        roll: start.roll + axis(4) * speeds.angular * dt,
    };
    let mut next = *targets;
    let mut reached = true;
    if !jog.axes[..GRIPPER].iter().all(|value| *value == 0.0) {
        let solution = kinematics::solve(
            &goal,
            &arm,
            &kinematics::arm_limits(),
            &IkOptions::default(),
        );
        reached = solution.reached;
        next[..ARM_JOINTS].copy_from_slice(&solution.joints);
    }
    next[GRIPPER] =
        JOINT_LIMITS[GRIPPER].clamp(targets[GRIPPER] + axis(GRIPPER) * speeds.gripper * dt);
    CartesianStep {
        targets: next,
        reached,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use so101_core::robot::follow;

    const SPEEDS: Speeds = Speeds {
        joint: 1.0,
        linear: 0.1,
        angular: 1.0,
        gripper: 2.0,
    };
    const REACH: JointPositions = [0.2, 0.4, 0.6, 0.9, 0.1, 0.5];

    #[test]
    fn joint_jog_moves_at_the_scaled_speed_and_stops_at_the_limits() {
        let mut jog = Jog::STILL;
        jog.axes[0] = 0.5;
        jog.axes[5] = -1.0;
        let next = jog_joints(&REACH, &jog, &SPEEDS, 0.02);
        assert!((next[0] - (0.2 + 0.01)).abs() < 1e-12);
        assert!((next[5] - (0.5 - 0.04)).abs() < 1e-12);
        assert_eq!(&next[1..5], &REACH[1..5]);
        // A full-speed push for a long time ends at the limit, never beyond.
        jog.axes = [1.0, -1.0, 1.0, -1.0, 1.0, 1.0];
        let far = jog_joints(&REACH, &jog, &SPEEDS, 100.0);
        for (joint, value) in far.iter().enumerate() {
            let limit = JOINT_LIMITS[joint];
            assert!(
                *value == limit.min || *value == limit.max,
                "{joint}: {value}"
            );
        }
        // Out-of-range requests count as full speed.
        jog.axes = [9.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        assert!((jog_joints(&REACH, &jog, &SPEEDS, 0.1)[0] - 0.3).abs() < 1e-12);
    }

    #[test]
    fn cartesian_jog_moves_the_grasp_point_along_the_asked_axis_only() {
        let arm =
            |targets: &JointPositions| -> ArmPositions { std::array::from_fn(|j| targets[j]) };
        for axis in 0..3 {
            let mut jog = Jog::STILL;
            jog.axes[axis] = 1.0;
            let step = jog_cartesian(&REACH, &jog, &SPEEDS, 0.05);
            assert!(step.reached);
            let before = kinematics::task_pose(&arm(&REACH));
            let after = kinematics::task_pose(&arm(&step.targets));
            let moved = after.position - before.position;
            let mut expected = Vector3::zeros();
            expected[axis] = 0.005;
            assert!(
                (moved - expected).norm() < 1e-4,
                "axis {axis}: moved {moved:?}"
            );
            assert!(
                (after.pitch - before.pitch).abs() < 2e-3
                    && (after.roll - before.roll).abs() < 2e-3
            );
            assert_eq!(step.targets[5], REACH[5]);
        }
        let mut jog = Jog::STILL;
        jog.axes[3] = 1.0;
        let step = jog_cartesian(&REACH, &jog, &SPEEDS, 0.05);
        let pitch = kinematics::task_pose(&arm(&step.targets)).pitch
            - kinematics::task_pose(&arm(&REACH)).pitch;
        assert!((pitch - 0.05).abs() < 2e-3, "{pitch}");
    }

    #[test]
    fn an_unreachable_cartesian_request_stays_inside_the_limits() {
        let mut targets = REACH;
        let mut jog = Jog::STILL;
        jog.axes[0] = 1.0; // straight out, far past the arm's reach
        let mut reached_all = true;
        for _ in 0..200 {
            let step = jog_cartesian(&targets, &jog, &SPEEDS, 0.05);
            reached_all &= step.reached;
            targets = step.targets;
            for (joint, value) in targets.iter().enumerate() {
                assert!(JOINT_LIMITS[joint].contains(*value), "{joint}: {value}");
            }
        }
        assert!(!reached_all, "1 m of travel should leave the workspace");
    }

    #[test]
    fn following_limits_each_step_and_clamps_the_request() {
        let wanted = [5.0, -5.0, 0.6, 0.9, 0.1, 0.5];
        let next = follow(&REACH, &wanted, 0.05);
        assert!((next[0] - 0.25).abs() < 1e-12 && (next[1] - 0.35).abs() < 1e-12);
        let mut settled = REACH;
        for _ in 0..1000 {
            settled = follow(&settled, &wanted, 0.05);
        }
        assert_eq!(settled[0], JOINT_LIMITS[0].max);
        assert_eq!(settled[1], JOINT_LIMITS[1].min);
    }
}
