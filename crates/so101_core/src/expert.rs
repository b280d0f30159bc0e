//! The scripted expert for cube_to_bin: from the cube's pose, a grasp from above with the jaws
//! across two faces of the cube, a lift, a move over the bin and a release, as timed task-space
//! waypoints that the shared IK turns into joint targets every control period. Noise on the
//! waypoints and on the joint targets (as in the ALOHA scripted policies) makes the
//! demonstrations varied. Pure: no I/O.

use std::f64::consts::FRAC_PI_2;

use crate::{
    kinematics::{self, ArmPositions, IkOptions, TaskPose, ARM_JOINTS},
    robot::{JointPositions, JOINT_COUNT, JOINT_LIMITS},
};
use nalgebra::Vector3;
use rand::Rng;
use rand_distr_free::normal;

/// Where things are and how the expert moves (base frame, m and s).
#[derive(Debug, Clone, PartialEq)]
pub struct ExpertConfig {
    /// Where a released cube should drop: above the bin's centre.
    pub bin: Vector3<f64>,
    /// Height of the table top.
    pub table_z: f64,
    /// Gripper targets (rad).
    pub gripper_open: f64,
    pub gripper_closed: f64,
    /// Standard deviation of the noise on each waypoint position (m).
    pub waypoint_noise: f64,
    /// Standard deviation of the noise on each joint target, every period (rad).
    pub action_noise: f64,
    /// Scales every move's duration (1 = the tuned timing).
    pub slowness: f64,
}

/// Where the sim scene's bin centre is (world frame, m): the expert drops the cube above it.
pub const SIM_BIN_IN_WORLD: [f64; 3] = [0.10, -0.22, 0.77];
/// Height of the sim scene's table top (world frame, m).
pub const SIM_TABLE_Z: f64 = 0.75;
/// Gripper targets of the expert's open and closed jaws (rad).
pub const GRIPPER_OPEN: f64 = 0.9;
pub const GRIPPER_CLOSED: f64 = -0.17;

impl ExpertConfig {
    /// The expert in the sim scene, its base at `base_in_world`, dropping the cube above
    /// `bin_in_world`, with the given noise (the teleop node's defaults and the in-process
    /// expert's).
    pub fn for_scene(
        base_in_world: Vector3<f64>,
        bin_in_world: Vector3<f64>,
        waypoint_noise: f64,
        action_noise: f64,
    ) -> Self {
        Self {
            bin: bin_in_world - base_in_world,
            table_z: SIM_TABLE_Z - base_in_world.z,
            gripper_open: GRIPPER_OPEN,
            gripper_closed: GRIPPER_CLOSED,
            waypoint_noise,
            action_noise,
            slowness: 1.0,
        }
    }
}

/// One waypoint: where the grasp point is and how open the gripper is when the segment ends.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Waypoint {
    pose: TaskPose,
    gripper: f64,
    /// Seconds to get here from the previous waypoint.
    duration: f64,
}

/// A planned episode: task-space waypoints from the arm's pose when it starts.
#[derive(Debug, Clone)]
pub struct Plan {
    start: Waypoint,
    waypoints: Vec<Waypoint>,
    /// The IK's last solution, the seed of the next (the solution stays on one branch).
    seed: ArmPositions,
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlanError {
    #[error("no straight-down or tilted grasp reaches the cube at {0:?} (base frame)")]
    Unreachable([f64; 3]),
}

/// Heights above the table of the grasp point in each phase.
const GRASP_ABOVE_TABLE: f64 = 0.017;
const APPROACH_ABOVE_CUBE: f64 = 0.06;
const CARRY_ABOVE_TABLE: f64 = 0.13;
const RELEASE_ABOVE_TABLE: f64 = 0.095;
/// Sideways room between the fixed jaw's pad and the cube on the way down, m.
const JAW_CLEARANCE: f64 = 0.007;
/// Grasp pitches tried in order: straight down first, then tilted (far or near the base).
const GRASP_PITCHES: [f64; 5] = [FRAC_PI_2, 1.35, 1.15, 0.95, 0.75];

/// Yaw of a cube lying flat, from its orientation (w, x, y, z).
pub fn cube_yaw(orientation: [f64; 4]) -> f64 {
    let [w, x, y, z] = orientation;
    (2.0 * (w * z + x * y)).atan2(1.0 - 2.0 * (y * y + z * z))
}

/// The roll that puts the jaws across two faces of a cube of yaw `yaw`, for an arm facing
/// `heading`, when the gripper points straight down: of the four equivalent faces the one needing
/// the least roll.
pub fn grasp_roll(heading: f64, yaw: f64) -> f64 {
    // Pointing down, the jaw axis lies at heading + pi/2 - roll in the world's horizontal plane.
    (0..4)
        .map(|quarter| {
            kinematics::wrap_angle(heading + FRAC_PI_2 - yaw - f64::from(quarter) * FRAC_PI_2)
        })
        .min_by(|a, b| a.abs().total_cmp(&b.abs()))
        .unwrap_or(0.0)
}

impl Plan {
    /// Plans one pick-and-place from `joints` (the arm now) for a cube at `cube` (base frame) with
    /// yaw `yaw`.
    pub fn new(
        joints: &JointPositions,
        cube: Vector3<f64>,
        yaw: f64,
        config: &ExpertConfig,
        rng: &mut impl Rng,
    ) -> Result<Self, PlanError> {
        let arm: ArmPositions = std::array::from_fn(|joint| joints[joint]);
        let limits = kinematics::arm_limits();
        let options = IkOptions::default();
        let noisy = |point: Vector3<f64>, rng: &mut dyn rand::RngCore| {
            point
                + Vector3::new(
                    normal(rng) * config.waypoint_noise,
                    normal(rng) * config.waypoint_noise,
                    0.0,
                )
        };
        let grasp_at = noisy(
            Vector3::new(cube.x, cube.y, config.table_z + GRASP_ABOVE_TABLE),
            rng,
        );
        let mut grasp = reachable_pose(grasp_at, yaw)
            .ok_or(PlanError::Unreachable([cube.x, cube.y, cube.z]))?;
        // The fixed jaw's pad touches the cube's face when the grasp point is on the cube's centre:
        // come down shifted away from the fixed jaw (the jaw axis points from it to the moving
        // jaw), which then pushes the cube onto the pad as it closes.
        let solution = kinematics::solve(&grasp, &[0.0; ARM_JOINTS], &limits, &options);
        let jaw_axis = kinematics::grasp_frame(&solution.joints).rotation * Vector3::x();
        let shifted = grasp.position - Vector3::new(jaw_axis.x, jaw_axis.y, 0.0) * JAW_CLEARANCE;
        // The arm's heading changes a little with the shift: align the jaws for the new one.
        grasp = reachable_pose(shifted, yaw).unwrap_or(TaskPose {
            position: shifted,
            ..grasp
        });
        let above = |position: Vector3<f64>, height: f64| {
            Vector3::new(position.x, position.y, config.table_z + height)
        };
        // Carrying, only the position matters: the steepest pitch the arm reaches there.
        let carry_pose = |position: Vector3<f64>| {
            reachable_pose(position, 0.0).unwrap_or(TaskPose {
                position,
                pitch: GRASP_PITCHES[GRASP_PITCHES.len() - 1],
                roll: 0.0,
            })
        };
        let bin = noisy(config.bin, rng);
        let s = config.slowness;
        let waypoint = |pose: TaskPose, gripper: f64, duration: f64| Waypoint {
            pose,
            gripper,
            duration: duration * s,
        };
        let (open, closed) = (config.gripper_open, config.gripper_closed);
        let approach = TaskPose {
            position: grasp.position + Vector3::new(0.0, 0.0, APPROACH_ABOVE_CUBE),
            ..grasp
        };
        let lifted = carry_pose(above(grasp.position, CARRY_ABOVE_TABLE));
        let waypoints = vec![
            waypoint(approach, open, 1.6),
            waypoint(grasp, open, 1.0),
            waypoint(grasp, open, 0.2),
            waypoint(grasp, closed, 0.6),
            waypoint(lifted, closed, 1.0),
            waypoint(carry_pose(above(bin, CARRY_ABOVE_TABLE)), closed, 1.5),
            waypoint(carry_pose(above(bin, RELEASE_ABOVE_TABLE)), closed, 0.5),
            waypoint(carry_pose(above(bin, RELEASE_ABOVE_TABLE)), open, 0.5),
            waypoint(carry_pose(above(bin, CARRY_ABOVE_TABLE + 0.03)), open, 0.7),
        ];
        Ok(Self {
            start: Waypoint {
                pose: kinematics::task_pose(&arm),
                gripper: joints[JOINT_COUNT - 1],
                duration: 0.0,
            },
            waypoints,
            seed: arm,
        })
    }

    /// Seconds from start to the last waypoint.
    pub fn duration(&self) -> f64 {
        self.waypoints
            .iter()
            .map(|waypoint| waypoint.duration)
            .sum()
    }

    /// Where the grasp point and gripper should be `t` seconds into the plan (smooth in and out of
    /// every waypoint).
    fn sample(&self, t: f64) -> (TaskPose, f64) {
        let mut from = self.start;
        let mut elapsed = t.max(0.0);
        for to in &self.waypoints {
            if elapsed < to.duration {
                let s = smoothstep(elapsed / to.duration);
                let pose = TaskPose {
                    position: from.pose.position.lerp(&to.pose.position, s),
                    pitch: from.pose.pitch + s * (to.pose.pitch - from.pose.pitch),
                    roll: from.pose.roll
                        + s * kinematics::wrap_angle(to.pose.roll - from.pose.roll),
                };
                return (pose, from.gripper + s * (to.gripper - from.gripper));
            }
            elapsed -= to.duration;
            from = *to;
        }
        (from.pose, from.gripper)
    }

    /// Joint targets `t` seconds into the plan, with the action noise added (inside the limits).
    pub fn targets_at(
        &mut self,
        t: f64,
        config: &ExpertConfig,
        rng: &mut impl Rng,
    ) -> JointPositions {
        let (pose, gripper) = self.sample(t);
        let solution = kinematics::solve(
            &pose,
            &self.seed,
            &kinematics::arm_limits(),
            &IkOptions::default(),
        );
        self.seed = solution.joints;
        std::array::from_fn(|joint| {
            let value = if joint < ARM_JOINTS {
                solution.joints[joint]
            } else {
                gripper
            };
            JOINT_LIMITS[joint].clamp(value + normal(rng) * config.action_noise)
        })
    }
}

/// The grasp point at `position` pointing as steeply down as the arm reaches there (straight down
/// if it can), with the jaws across the faces of a cube of yaw `yaw`; `None` when no pitch of
/// [`GRASP_PITCHES`] reaches it.
fn reachable_pose(position: Vector3<f64>, yaw: f64) -> Option<TaskPose> {
    let limits = kinematics::arm_limits();
    let options = IkOptions::default();
    GRASP_PITCHES.iter().find_map(|&pitch| {
        let mut pose = TaskPose {
            position,
            pitch,
            roll: grasp_roll(kinematics::azimuth(&position), yaw),
        };
        let first = kinematics::solve(&pose, &[0.0; ARM_JOINTS], &limits, &options);
        // The arm's plane is off the point's azimuth by the links' sideways offsets: recompute
        // the roll for the heading the arm really takes.
        pose.roll = grasp_roll(kinematics::heading(&first.joints), yaw);
        kinematics::solve(&pose, &first.joints, &limits, &options)
            .reached
            .then_some(pose)
    })
}

fn smoothstep(x: f64) -> f64 {
    let x = x.clamp(0.0, 1.0);
    x * x * (3.0 - 2.0 * x)
}

/// A standard normal sample without another dependency (Box-Muller).
mod rand_distr_free {
    pub fn normal(rng: &mut (impl rand::Rng + ?Sized)) -> f64 {
        let u1: f64 = rng.gen_range(f64::EPSILON..1.0);
        let u2: f64 = rng.gen();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    pub fn sim_config() -> ExpertConfig {
        ExpertConfig {
            bin: Vector3::new(0.10, -0.22, 0.02),
            table_z: 0.0,
            gripper_open: 0.9,
            gripper_closed: -0.17,
            waypoint_noise: 0.0,
            action_noise: 0.0,
            slowness: 1.0,
        }
    }

    #[test]
    fn the_jaws_close_across_two_faces_of_the_cube() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        for (x, y, yaw) in [(0.23, -0.05, 0.0), (0.19, 0.07, 0.6), (0.27, -0.07, -0.4)] {
            let cube = Vector3::new(x, y, 0.015);
            let mut plan = Plan::new(&[0.0; 6], cube, yaw, &sim_config(), &mut rng).unwrap();
            // At the grasp (after approach and descent), the grasp point is on the cube ...
            let t = 1.6 + 1.0 + 0.1;
            let targets = plan.targets_at(t, &sim_config(), &mut rng);
            let arm: ArmPositions = std::array::from_fn(|j| targets[j]);
            let frame = kinematics::grasp_frame(&arm);
            let at = frame.translation.vector;
            let off = at - Vector3::new(x, y, GRASP_ABOVE_TABLE);
            assert!((off.norm() - JAW_CLEARANCE).abs() < 1e-3, "{at:?}");
            // ... pointing down, with the jaw axis along a face normal of the cube.
            let approach = frame.rotation * -Vector3::z();
            assert!(approach.z < -0.99, "{approach:?}");
            let jaw = frame.rotation * Vector3::x();
            let misalignment = kinematics::wrap_angle(4.0 * (jaw.y.atan2(jaw.x) - yaw)) / 4.0;
            assert!(
                misalignment.abs() < 0.03,
                "jaw off the faces by {misalignment} rad"
            );
            assert_eq!(targets[5], 0.9);
        }
    }

    #[test]
    fn the_plan_ends_open_over_the_bin_inside_the_limits() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(2);
        let config = ExpertConfig {
            waypoint_noise: 0.005,
            action_noise: 0.01,
            ..sim_config()
        };
        let mut plan = Plan::new(
            &[0.0; 6],
            Vector3::new(0.21, 0.03, 0.015),
            0.3,
            &config,
            &mut rng,
        )
        .unwrap();
        let mut t = 0.0;
        while t <= plan.duration() {
            let targets = plan.targets_at(t, &config, &mut rng);
            for (joint, value) in targets.iter().enumerate() {
                assert!(
                    JOINT_LIMITS[joint].contains(*value),
                    "t={t}: {joint}={value}"
                );
            }
            t += 0.02;
        }
        let quiet = sim_config();
        let end = plan.targets_at(plan.duration() + 1.0, &quiet, &mut rng);
        let arm: ArmPositions = std::array::from_fn(|j| end[j]);
        let over = kinematics::task_pose(&arm).position;
        assert!(
            (over.xy() - Vector3::new(0.10, -0.22, 0.0).xy()).norm() < 0.02,
            "{over:?}"
        );
        assert!(end[5] > 0.8);
    }

    #[test]
    fn cube_yaw_reads_a_flat_cubes_turn() {
        let half = 0.3_f64 / 2.0;
        assert!((cube_yaw([half.cos(), 0.0, 0.0, half.sin()]) - 0.3).abs() < 1e-12);
        assert_eq!(cube_yaw([1.0, 0.0, 0.0, 0.0]), 0.0);
    }

    #[test]
    fn grasp_roll_picks_the_face_pair_needing_the_least_roll() {
        for heading in [-0.5, 0.0, 0.4] {
            for yaw in [-1.0, 0.0, 0.7, 2.5] {
                let roll = grasp_roll(heading, yaw);
                assert!(roll.abs() <= FRAC_PI_2 / 2.0 + 1e-12, "{roll}");
            }
        }
    }
}
