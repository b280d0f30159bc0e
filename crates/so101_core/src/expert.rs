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
/// Seconds an expert episode goes on once the task succeeds (its recording ends on the success).
pub const SUCCESS_SHOWN_SECONDS: f64 = 0.5;
/// Seconds after the plan's end for the task to succeed, else the episode failed.
pub const JUDGE_SECONDS: f64 = 1.5;
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

/// What the plan waits for at the end of a segment before it goes on: the planner follows the
/// arm it commands (ramped servos lag their targets) instead of playing its timing blind.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Gate {
    None,
    /// The measured grasp point within [`REACHED_TOLERANCE`] of the waypoint's.
    Reached,
    /// The grasp is reached; when it is not (a jaw landed on the cube: waypoint noise pushed the
    /// grasp onto it), a regrasp from above.
    Grasp,
    /// The gripper has stopped closing; when it closed on nothing (the cube was knocked away), a
    /// regrasp from above.
    Gripped,
}

/// One waypoint: where the grasp point is and how open the gripper is when the segment ends.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Waypoint {
    pose: TaskPose,
    gripper: f64,
    /// Seconds to get here from the previous waypoint.
    duration: f64,
    gate: Gate,
}

/// A grasp point nearer than this to its target has reached it, m.
const REACHED_TOLERANCE: f64 = 0.004;
/// The gripper moving less than this in one period has stopped, rad.
const GRIPPER_STILL: f64 = 0.002;
/// Seconds a gate waits at most; the plan then goes on as timed.
const GATE_TIMEOUT: f64 = 1.0;
/// Seconds at the grasp gate before an unreached grasp counts as blocked.
const BLOCKED_AFTER: f64 = 0.4;
/// A gripper closed to within this of its closed target holds nothing (holding the cube it
/// stops about 0.35 rad short), rad.
const EMPTY_GRIP: f64 = 0.15;
/// Regrasps an episode tries at most.
const MAX_REGRASPS: u32 = 2;

/// Where the cube goes once held: the poses of the carry (base frame).
#[derive(Debug, Clone, Copy)]
struct Carry {
    lifted: TaskPose,
    over_bin: TaskPose,
    release: TaskPose,
    leave: TaskPose,
}

/// A planned episode: task-space waypoints from the arm's pose when it starts, played on a clock
/// that stops at a gate until the measured arm has done what the gate waits for.
#[derive(Debug, Clone)]
pub struct Plan {
    start: Waypoint,
    waypoints: Vec<Waypoint>,
    /// The IK's last solution, the seed of the next (the solution stays on one branch).
    seed: ArmPositions,
    /// Seconds into the waypoints (stopped while a gate waits).
    clock: f64,
    /// Gates before this waypoint have opened.
    next_gate: usize,
    /// Seconds the current gate has waited.
    waited: f64,
    /// The gripper's position at the last step (the Gripped gate sees it stop).
    last_gripper: Option<f64>,
    /// The noise-free grasp and the carry, for a regrasp when the cube's pose is not known.
    clean_grasp: TaskPose,
    carry: Carry,
    table_z: f64,
    regrasps: u32,
    gripper_open: f64,
    gripper_closed: f64,
    slowness: f64,
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

/// The grasp for a cube whose centre is at `at` (with the grasp height): pointing as steeply down
/// as the arm reaches, the jaws across two faces, shifted away from the fixed jaw.
fn grasp_pose(at: Vector3<f64>, yaw: f64) -> Option<TaskPose> {
    let grasp = reachable_pose(at, yaw)?;
    // The fixed jaw's pad touches the cube's face when the grasp point is on the cube's centre:
    // come down shifted away from the fixed jaw (the jaw axis points from it to the moving
    // jaw), which then pushes the cube onto the pad as it closes.
    let limits = kinematics::arm_limits();
    let solution = kinematics::solve(&grasp, &[0.0; ARM_JOINTS], &limits, &IkOptions::default());
    let jaw_axis = kinematics::grasp_frame(&solution.joints).rotation * Vector3::x();
    let shifted = grasp.position - Vector3::new(jaw_axis.x, jaw_axis.y, 0.0) * JAW_CLEARANCE;
    // The arm's heading changes a little with the shift: align the jaws for the new one.
    Some(reachable_pose(shifted, yaw).unwrap_or(TaskPose {
        position: shifted,
        ..grasp
    }))
}

/// Carrying, only the position matters: the steepest pitch the arm reaches there.
fn carry_pose(position: Vector3<f64>) -> TaskPose {
    reachable_pose(position, 0.0).unwrap_or(TaskPose {
        position,
        pitch: GRASP_PITCHES[GRASP_PITCHES.len() - 1],
        roll: 0.0,
    })
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
        let noise = |rng: &mut dyn rand::RngCore| {
            Vector3::new(
                normal(rng) * config.waypoint_noise,
                normal(rng) * config.waypoint_noise,
                0.0,
            )
        };
        let grasp_height = Vector3::new(cube.x, cube.y, config.table_z + GRASP_ABOVE_TABLE);
        let unreachable = PlanError::Unreachable([cube.x, cube.y, cube.z]);
        let grasp = grasp_pose(grasp_height + noise(rng), yaw).ok_or(unreachable.clone())?;
        let clean_grasp = grasp_pose(grasp_height, yaw).ok_or(unreachable)?;
        let above = |position: Vector3<f64>, height: f64| {
            Vector3::new(position.x, position.y, config.table_z + height)
        };
        let bin = config.bin + noise(rng);
        let carry = Carry {
            lifted: carry_pose(above(grasp.position, CARRY_ABOVE_TABLE)),
            over_bin: carry_pose(above(bin, CARRY_ABOVE_TABLE)),
            release: carry_pose(above(bin, RELEASE_ABOVE_TABLE)),
            leave: carry_pose(above(bin, CARRY_ABOVE_TABLE + 0.03)),
        };
        let mut plan = Self {
            start: Waypoint {
                pose: kinematics::task_pose(&arm),
                gripper: joints[JOINT_COUNT - 1],
                duration: 0.0,
                gate: Gate::None,
            },
            waypoints: Vec::new(),
            seed: arm,
            clock: 0.0,
            next_gate: 0,
            waited: 0.0,
            last_gripper: None,
            clean_grasp,
            carry,
            table_z: config.table_z,
            regrasps: 0,
            gripper_open: config.gripper_open,
            gripper_closed: config.gripper_closed,
            slowness: config.slowness,
        };
        plan.waypoints = plan.pick_and_place(grasp, 1.6, Gate::Grasp);
        Ok(plan)
    }

    /// From wherever the arm is: above the grasp, down to it, close, lift, carry, release.
    fn pick_and_place(&self, grasp: TaskPose, approach_s: f64, grasp_gate: Gate) -> Vec<Waypoint> {
        let (open, closed) = (self.gripper_open, self.gripper_closed);
        let waypoint = |pose: TaskPose, gripper: f64, duration: f64, gate: Gate| Waypoint {
            pose,
            gripper,
            duration: duration * self.slowness,
            gate,
        };
        let approach = TaskPose {
            position: grasp.position + Vector3::new(0.0, 0.0, APPROACH_ABOVE_CUBE),
            ..grasp
        };
        let carry = self.carry;
        vec![
            waypoint(approach, open, approach_s, Gate::None),
            waypoint(grasp, open, 1.0, grasp_gate),
            waypoint(grasp, open, 0.2, Gate::None),
            waypoint(grasp, closed, 0.6, Gate::Gripped),
            waypoint(carry.lifted, closed, 1.0, Gate::None),
            waypoint(carry.over_bin, closed, 1.5, Gate::None),
            waypoint(carry.release, closed, 0.5, Gate::Reached),
            waypoint(carry.release, open, 0.5, Gate::None),
            waypoint(carry.leave, open, 0.7, Gate::None),
        ]
    }

    /// Seconds from start to the last waypoint, as timed (gates that wait add to it).
    pub fn duration(&self) -> f64 {
        self.waypoints
            .iter()
            .map(|waypoint| waypoint.duration)
            .sum()
    }

    /// The plan has been played to its end.
    pub fn finished(&self) -> bool {
        self.clock >= self.duration()
    }

    /// How many times the plan went back up to grasp again.
    pub fn regrasps(&self) -> u32 {
        self.regrasps
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

    /// Moves the plan's clock `dt` seconds on, unless a gate holds it for the arm at `measured`,
    /// and returns the joint targets there with the action noise added (inside the limits).
    /// `cube` (base frame, and its yaw), where known, is where a regrasp goes.
    pub fn step(
        &mut self,
        dt: f64,
        measured: &JointPositions,
        cube: Option<(Vector3<f64>, f64)>,
        config: &ExpertConfig,
        rng: &mut impl Rng,
    ) -> JointPositions {
        self.advance(dt, measured, cube);
        self.last_gripper = Some(measured[JOINT_COUNT - 1]);
        self.targets_at_clock(config, rng)
    }

    fn advance(&mut self, dt: f64, measured: &JointPositions, cube: Option<(Vector3<f64>, f64)>) {
        let gate = (self.next_gate..self.waypoints.len())
            .find(|&index| self.waypoints[index].gate != Gate::None);
        let Some(index) = gate else {
            self.clock += dt;
            return;
        };
        let gate_at: f64 = self.waypoints[..=index].iter().map(|w| w.duration).sum();
        if self.clock + dt < gate_at {
            self.clock += dt;
            return;
        }
        self.clock = gate_at;
        self.waited += dt;
        let waypoint = self.waypoints[index];
        let arm: ArmPositions = std::array::from_fn(|joint| measured[joint]);
        let reached = || {
            (kinematics::task_pose(&arm).position - waypoint.pose.position).norm()
                < REACHED_TOLERANCE
        };
        let gripper = measured[JOINT_COUNT - 1];
        let can_regrasp = self.regrasps < MAX_REGRASPS;
        let open = match waypoint.gate {
            Gate::None => true,
            Gate::Reached => reached(),
            Gate::Grasp => {
                if !reached() && self.waited >= BLOCKED_AFTER && can_regrasp {
                    self.regrasp(measured, cube);
                    return;
                }
                reached()
            }
            Gate::Gripped => {
                let still = self
                    .last_gripper
                    .is_some_and(|last| (gripper - last).abs() < GRIPPER_STILL);
                if still && gripper < self.gripper_closed + EMPTY_GRIP && can_regrasp {
                    self.regrasp(measured, cube);
                    return;
                }
                still
            }
        };
        if open || self.waited >= GATE_TIMEOUT {
            self.next_gate = index + 1;
            self.waited = 0.0;
        }
    }

    /// Starts again from the arm where it is: up above the cube's grasp (where `cube` says it is
    /// now, else where it was planned), without the noise, and down to it.
    fn regrasp(&mut self, measured: &JointPositions, cube: Option<(Vector3<f64>, f64)>) {
        let arm: ArmPositions = std::array::from_fn(|joint| measured[joint]);
        let grasp = cube
            .and_then(|(at, yaw)| {
                grasp_pose(
                    Vector3::new(at.x, at.y, self.table_z + GRASP_ABOVE_TABLE),
                    yaw,
                )
            })
            .unwrap_or(self.clean_grasp);
        self.carry.lifted = carry_pose(Vector3::new(
            grasp.position.x,
            grasp.position.y,
            self.table_z + CARRY_ABOVE_TABLE,
        ));
        self.start = Waypoint {
            pose: kinematics::task_pose(&arm),
            gripper: measured[JOINT_COUNT - 1],
            duration: 0.0,
            gate: Gate::None,
        };
        self.waypoints = self.pick_and_place(grasp, 0.8, Gate::Grasp);
        self.seed = arm;
        self.clock = 0.0;
        self.next_gate = 0;
        self.waited = 0.0;
        self.regrasps += 1;
    }

    /// Joint targets at the clock's instant, with the action noise added (inside the limits).
    fn targets_at_clock(&mut self, config: &ExpertConfig, rng: &mut impl Rng) -> JointPositions {
        let (pose, gripper) = self.sample(self.clock);
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

    const PERIOD: f64 = 1.0 / 30.0;
    /// Where the gripper stops closed on the cube, rad.
    const HOLDING: f64 = 0.19;

    /// Steps the plan `seconds` with an arm that follows its targets exactly (the gripper stopped
    /// by the cube); the last targets.
    fn play(
        plan: &mut Plan,
        seconds: f64,
        config: &ExpertConfig,
        rng: &mut impl Rng,
        arm: &mut JointPositions,
    ) -> JointPositions {
        for _ in 0..(seconds / PERIOD).round() as usize {
            *arm = plan.step(PERIOD, arm, None, config, rng);
            arm[5] = arm[5].max(HOLDING);
        }
        *arm
    }

    #[test]
    fn the_jaws_close_across_two_faces_of_the_cube() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        for (x, y, yaw) in [(0.23, -0.05, 0.0), (0.19, 0.07, 0.6), (0.27, -0.07, -0.4)] {
            let cube = Vector3::new(x, y, 0.015);
            let mut plan = Plan::new(&[0.0; 6], cube, yaw, &sim_config(), &mut rng).unwrap();
            // At the grasp (after approach and descent), the grasp point is on the cube ...
            let mut arm = [0.0; 6];
            let targets = play(
                &mut plan,
                1.6 + 1.0 + 0.1,
                &sim_config(),
                &mut rng,
                &mut arm,
            );
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
        let mut arm = [0.0; 6];
        let mut t = 0.0;
        while !plan.finished() {
            arm = plan.step(PERIOD, &arm, None, &config, &mut rng);
            arm[5] = arm[5].max(HOLDING);
            for (joint, value) in arm.iter().enumerate() {
                assert!(
                    JOINT_LIMITS[joint].contains(*value),
                    "t={t}: {joint}={value}"
                );
            }
            t += PERIOD;
            assert!(
                t < plan.duration() + 3.0 * GATE_TIMEOUT,
                "the plan never ends"
            );
        }
        let quiet = sim_config();
        let end = play(&mut plan, 1.0, &quiet, &mut rng, &mut arm);
        let arm: ArmPositions = std::array::from_fn(|j| end[j]);
        let over = kinematics::task_pose(&arm).position;
        assert!(
            (over.xy() - Vector3::new(0.10, -0.22, 0.0).xy()).norm() < 0.02,
            "{over:?}"
        );
        assert!(end[5] > 0.8);
    }

    #[test]
    fn the_gripper_closes_only_once_a_lagging_arm_has_reached_the_grasp() {
        let config = sim_config();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let cube = Vector3::new(0.22, 0.02, 0.015);
        let mut plan = Plan::new(&[0.0; 6], cube, 0.2, &config, &mut rng).unwrap();
        // An arm that covers a third of the way to its targets each period (ramped servos).
        let mut arm = [0.0; 6];
        let mut closing_started_at_grasp = None;
        let mut opened = false;
        for _ in 0..600 {
            let targets = plan.step(PERIOD, &arm, None, &config, &mut rng);
            opened |= targets[5] >= GRIPPER_OPEN - 1e-9;
            if opened && targets[5] < GRIPPER_OPEN - 0.01 && closing_started_at_grasp.is_none() {
                let at: ArmPositions = std::array::from_fn(|j| arm[j]);
                let grasp = plan.clean_grasp.position;
                closing_started_at_grasp =
                    Some((kinematics::task_pose(&at).position - grasp).norm());
            }
            for joint in 0..6 {
                arm[joint] += (targets[joint] - arm[joint]) / 3.0;
            }
            arm[5] = arm[5].max(HOLDING);
            if plan.finished() {
                break;
            }
        }
        assert!(plan.finished() && plan.regrasps() == 0);
        let off = closing_started_at_grasp.expect("the gripper never closed");
        assert!(
            off < REACHED_TOLERANCE,
            "the jaws began closing {off} m from the grasp"
        );
    }

    #[test]
    fn a_grasp_blocked_by_the_cube_is_retried_from_above_without_the_noise() {
        let config = sim_config();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(4);
        let cube = Vector3::new(0.24, -0.03, 0.015);
        let mut plan = Plan::new(&[0.0; 6], cube, 0.0, &config, &mut rng).unwrap();
        let mut arm = [0.0; 6];
        // The arm follows, but a jaw sits on the cube: it stops 15 mm above the grasp.
        let floor = plan.clean_grasp.position.z + 0.015;
        let mut lowest_after_retry = f64::INFINITY;
        let mut opened = false;
        for _ in 0..400 {
            let targets = plan.step(PERIOD, &arm, None, &config, &mut rng);
            opened |= targets[5] >= GRIPPER_OPEN - 1e-9;
            let regrasped = plan.regrasps() > 0;
            assert!(
                !opened || targets[5] > 0.8 || regrasped,
                "closed on a blocked grasp"
            );
            let reached: ArmPositions = std::array::from_fn(|j| targets[j]);
            let blocked = !regrasped && kinematics::task_pose(&reached).position.z < floor;
            if !blocked {
                arm = targets;
                arm[5] = arm[5].max(HOLDING);
            }
            if regrasped {
                let at: ArmPositions = std::array::from_fn(|j| arm[j]);
                lowest_after_retry = lowest_after_retry.min(kinematics::task_pose(&at).position.z);
            }
            if plan.finished() {
                break;
            }
        }
        assert!(plan.regrasps() == 1 && plan.finished());
        assert!((lowest_after_retry - plan.clean_grasp.position.z).abs() < 1e-3);
    }

    #[test]
    fn a_grasp_that_closed_on_nothing_goes_back_for_the_cube_where_it_lies_now() {
        let config = sim_config();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let planned = Vector3::new(0.22, 0.0, 0.015);
        let moved = Vector3::new(0.25, 0.03, 0.015);
        let mut plan = Plan::new(&[0.0; 6], planned, 0.0, &config, &mut rng).unwrap();
        let mut arm = [0.0; 6];
        let mut lowest: Option<Vector3<f64>> = None;
        for _ in 0..600 {
            // The jaws close on nothing (the cube was knocked to `moved`), once.
            arm = plan.step(PERIOD, &arm, Some((moved, 0.0)), &config, &mut rng);
            if plan.regrasps() > 0 {
                let at: ArmPositions = std::array::from_fn(|j| arm[j]);
                let point = kinematics::task_pose(&at).position;
                if lowest.is_none_or(|low| point.z < low.z) {
                    lowest = Some(point);
                }
                // Holding the cube this time: the jaws stop short of closed.
                arm[5] = arm[5].max(HOLDING);
            }
            if plan.finished() {
                break;
            }
        }
        assert_eq!(plan.regrasps(), 1);
        assert!(plan.finished());
        let lowest = lowest.unwrap();
        let off = (lowest.xy() - moved.xy()).norm();
        assert!(
            off < JAW_CLEARANCE + 2e-3,
            "regrasped {off} m from the cube"
        );
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
