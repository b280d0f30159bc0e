//! The SO-101 arm as every node sees it: joint order, names and position limits.
//!
//! Limits are the joint ranges of the SO-101 model (rad). The simulation scene uses the same
//! numbers; the physical driver narrows them further with the calibrated range of each servo.

/// Number of actuated joints (5 arm joints + gripper).
pub const JOINT_COUNT: usize = 6;

/// The project's MJCF scene (the arm, the table, the bin, the cube, the cameras) in this checkout:
/// the sim loads it, and the robot description is drawn from it.
pub const DEFAULT_SCENE: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../assets/so101_cube_to_bin.xml"
);

/// Joint names in the order of every array in the topic contract.
pub const JOINT_NAMES: [&str; JOINT_COUNT] = [
    "shoulder_pan",
    "shoulder_lift",
    "elbow_flex",
    "wrist_flex",
    "wrist_roll",
    "gripper",
];

/// Closed position interval of one joint, in rad.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointLimit {
    pub min: f64,
    pub max: f64,
}

impl JointLimit {
    pub const fn new(min: f64, max: f64) -> Self {
        Self { min, max }
    }

    /// The nearest position inside the limit. `value` must be finite.
    pub fn clamp(&self, value: f64) -> f64 {
        value.clamp(self.min, self.max)
    }

    pub fn contains(&self, value: f64) -> bool {
        (self.min..=self.max).contains(&value)
    }
}

/// Joint limits of the SO-101, in [`JOINT_NAMES`] order.
pub const JOINT_LIMITS: [JointLimit; JOINT_COUNT] = [
    JointLimit::new(-1.9199, 1.9199),
    JointLimit::new(-1.7453, 1.7453),
    JointLimit::new(-1.6900, 1.6900),
    JointLimit::new(-1.6581, 1.6581),
    JointLimit::new(-2.7438, 2.8412),
    JointLimit::new(-0.1745, 1.7453),
];

/// Index of a joint in [`JOINT_NAMES`], or `None` for a name that is not an SO-101 joint.
pub fn joint_index(name: &str) -> Option<usize> {
    JOINT_NAMES.iter().position(|candidate| *candidate == name)
}

/// Positions of all joints, in [`JOINT_NAMES`] order.
pub type JointPositions = [f64; JOINT_COUNT];

/// Targets for an absolute joint request (leader arm, expert), clamped to the limits and moved at
/// most `max_step` rad per joint from the current targets, so a jump never reaches a motor at once.
pub fn follow(targets: &JointPositions, wanted: &JointPositions, max_step: f64) -> JointPositions {
    std::array::from_fn(|joint| {
        let wanted = JOINT_LIMITS[joint].clamp(wanted[joint]);
        let step = (wanted - targets[joint]).clamp(-max_step, max_step);
        JOINT_LIMITS[joint].clamp(targets[joint] + step)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn joint_index_finds_every_name_and_rejects_others() {
        for (index, name) in JOINT_NAMES.iter().enumerate() {
            assert_eq!(joint_index(name), Some(index));
        }
        assert_eq!(joint_index("elbow"), None);
        assert_eq!(joint_index(""), None);
    }

    #[test]
    fn limits_are_ordered_and_contain_zero() {
        for limit in JOINT_LIMITS {
            assert!(limit.min < limit.max);
            assert!(limit.contains(0.0));
            assert_eq!(limit.clamp(1e9), limit.max);
            assert_eq!(limit.clamp(-1e9), limit.min);
        }
    }
}
