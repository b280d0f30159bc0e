//! The built-in demo motion of the sim demo (scripts/run_sim_demo.sh, `--demo`): a scripted
//! pick-and-place of the cube from its default position in the scene into the bin, repeated. Pure: targets as a function of time.

use so101_core::robot::{JointPositions, JOINT_COUNT};

/// One pose of the script: the targets to reach and how long the move there takes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Waypoint {
    pub targets: JointPositions,
    /// Seconds to move from the previous waypoint to this one (linear, as the script was tuned).
    pub move_seconds: f64,
    /// Seconds to hold this pose before the next move starts.
    pub hold_seconds: f64,
}

const fn waypoint(targets: JointPositions, move_seconds: f64, hold_seconds: f64) -> Waypoint {
    Waypoint {
        targets,
        move_seconds,
        hold_seconds,
    }
}

/// Pick the cube at its default spawn position (0.23, -0.05) and drop it in the bin (joint order of
/// the contract; found by a scripted grasp planner in this scene, about 11 s per run).
pub const PICK_AND_PLACE: [Waypoint; 8] = [
    waypoint([0.0, 0.0, 0.0, 0.0, 0.0, 0.0], 0.0, 0.5),
    // above the cube, gripper open
    waypoint([0.287, -0.157, 0.151, 1.576, 0.336, 0.9], 1.5, 0.3),
    // down around it
    waypoint([0.287, -0.043, 0.527, 1.087, 0.336, 0.9], 1.0, 0.3),
    // close
    waypoint([0.287, -0.043, 0.527, 1.087, 0.336, -0.17], 0.5, 0.5),
    // lift
    waypoint([0.263, -0.154, -0.060, 1.650, 0.312, -0.17], 1.0, 0.3),
    // over the bin
    waypoint([1.299, 0.106, -0.329, 1.650, 0.083, -0.17], 1.5, 0.5),
    // release
    waypoint([1.299, 0.106, -0.329, 1.650, 0.083, 0.9], 0.3, 1.0),
    waypoint([0.0, 0.0, 0.0, 0.0, 0.0, 0.0], 1.5, 0.5),
];

/// Plays a list of waypoints, starting from the home pose (all zero).
#[derive(Debug, Clone)]
pub struct Script {
    waypoints: Vec<Waypoint>,
}

impl Script {
    pub fn new(waypoints: &[Waypoint]) -> Self {
        Self {
            waypoints: waypoints.to_vec(),
        }
    }

    /// Length of one run of the script, s.
    pub fn duration(&self) -> f64 {
        self.waypoints
            .iter()
            .map(|w| w.move_seconds + w.hold_seconds)
            .sum()
    }

    /// Targets `t` seconds after the start of a run (the last pose holds after the end).
    pub fn targets_at(&self, t: f64) -> JointPositions {
        let t = t.max(0.0);
        let mut from = [0.0; JOINT_COUNT];
        let mut start = 0.0;
        for waypoint in &self.waypoints {
            let move_end = start + waypoint.move_seconds;
            if t < move_end {
                // t >= start here, so t < move_end implies move_seconds > 0.
                let progress = ((t - start) / waypoint.move_seconds).clamp(0.0, 1.0);
                return std::array::from_fn(|joint| {
                    from[joint] + progress * (waypoint.targets[joint] - from[joint])
                });
            }
            start = move_end + waypoint.hold_seconds;
            if t < start {
                return waypoint.targets;
            }
            from = waypoint.targets;
        }
        from
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interpolates_moves_and_holds_poses() {
        let script = Script::new(&[
            waypoint([1.0, 0.0, 0.0, 0.0, 0.0, 0.0], 1.0, 1.0),
            waypoint([1.0, 2.0, 0.0, 0.0, 0.0, 0.0], 2.0, 0.0),
        ]);
        assert_eq!(script.duration(), 4.0);
        assert_eq!(script.targets_at(0.0)[0], 0.0);
        assert_eq!(script.targets_at(0.5)[0], 0.5);
        assert_eq!(script.targets_at(1.5), [1.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
        assert_eq!(script.targets_at(3.0)[1], 1.0);
        assert_eq!(script.targets_at(10.0), [1.0, 2.0, 0.0, 0.0, 0.0, 0.0]);
    }

    #[test]
    fn the_demo_stays_inside_the_joint_limits() {
        for waypoint in PICK_AND_PLACE {
            for (value, limit) in waypoint.targets.iter().zip(so101_core::robot::JOINT_LIMITS) {
                assert!(limit.contains(*value));
            }
        }
    }
}
