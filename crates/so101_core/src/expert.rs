//! The scripted expert of every task: from the cube's pose, a grasp from above with the jaws
//! across two faces of the cube, then what the task asks (cube_to_bin: a lift, a move over the bin
//! and a release; place_cube: the same down onto the pad; stack_cube: onto the green cube;
//! lift_cube: a lift, held; the touch tasks: the jaws at the cube, held) or, for push_cube, a push
//! along the table (`push`), as timed
//! task-space waypoints that the shared IK turns into joint targets every control period. Noise on the
//! waypoints and on the joint targets (as in the ALOHA scripted policies) makes the
//! demonstrations varied. Pure: no I/O.

use std::f64::consts::FRAC_PI_2;

use crate::{
    kinematics::{self, ArmPositions, IkOptions, TaskPose, ARM_JOINTS},
    robot::{JointPositions, JOINT_COUNT, JOINT_LIMITS},
    task::TaskKind,
};
use nalgebra::Vector3;
use rand::Rng;
use rand_distr_free::normal;

/// Where things are and how the expert moves (base frame, m and s).
#[derive(Debug, Clone, PartialEq)]
pub struct ExpertConfig {
    /// The task the expert plays.
    pub task: TaskKind,
    /// Where a released cube should drop: above the bin's centre.
    pub bin: Vector3<f64>,
    /// Where place_cube puts the cube down: the pad's centre.
    pub pad: Vector3<f64>,
    /// Where stack_cube's green cube stands: its centre.
    pub stack_base: Vector3<f64>,
    /// The centre of push_cube's target on the table.
    pub push_target: Vector3<f64>,
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
/// Where the sim scene's place_cube pad is (world frame, m; its `place_pad` site).
pub const SIM_PAD_IN_WORLD: [f64; 3] = [0.20, 0.18, 0.765];
/// Where stack_cube's green cube stands (world frame, m; its centre, the bottom on the table):
/// where place_cube's pad is.
pub const SIM_STACK_BASE_IN_WORLD: [f64; 3] = SIM_PAD_IN_WORLD;
/// The centre of push_cube's round target on the table (world frame, m), left of the cube's area.
pub const SIM_PUSH_TARGET_IN_WORLD: [f64; 3] = [0.26, 0.13, 0.75];
/// Radius of push_cube's target: the cube's centre inside it is on target (m).
pub const PUSH_TARGET_RADIUS: f64 = 0.03;
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
            task: TaskKind::CubeToBin,
            bin: bin_in_world - base_in_world,
            pad: Vector3::from(SIM_PAD_IN_WORLD) - base_in_world,
            stack_base: Vector3::from(SIM_STACK_BASE_IN_WORLD) - base_in_world,
            push_target: Vector3::from(SIM_PUSH_TARGET_IN_WORLD) - base_in_world,
            table_z: SIM_TABLE_Z - base_in_world.z,
            gripper_open: GRIPPER_OPEN,
            gripper_closed: GRIPPER_CLOSED,
            waypoint_noise,
            action_noise,
            slowness: 1.0,
        }
    }

    /// The same expert playing `task`.
    pub fn for_task(self, task: TaskKind) -> Self {
        Self { task, ..self }
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
    /// stack_cube: over the goal, still high, and the cube itself over the goal: else the carry
    /// moves by how far it is off and the gate waits again (the cube sits in the jaws where the
    /// grasp pushed it; corrected up there, where it touches nothing, before it goes down).
    OverGoal,
    /// A push has reached its end; when the cube did not get onto the target (it slid or turned
    /// off the pusher), another push from where it now lies.
    Pushed,
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
/// The gripper moving less than this a period for this many periods in a row has stopped, rad
/// (the action noise on its target moves it by less).
const GRIPPER_STILL: f64 = 0.01;
const GRIPPER_STILL_PERIODS: u32 = 3;
/// The longest step the plan's clock takes at once, s (a caller's stall is not followed).
const MAX_STEP_SECONDS: f64 = 0.1;
/// Seconds a gate waits at most; the plan then goes on as timed.
const GATE_TIMEOUT: f64 = 1.0;
/// An unreached grasp that got less than STALLED_PROGRESS (m) nearer in BLOCKED_AFTER seconds
/// of waiting is blocked.
const BLOCKED_AFTER: f64 = 0.3;
const STALLED_PROGRESS: f64 = 0.001;
/// A gripper closed to within this of its closed target holds nothing (holding the cube it
/// stops about 0.35 rad short), rad.
const EMPTY_GRIP: f64 = 0.15;
/// A cube farther than this from where it is set down (horizontally) moves the carry, at most
/// MAX_CORRECTIONS times, m.
const SET_DOWN_TOLERANCE: f64 = 0.004;
const MAX_CORRECTIONS: u32 = 3;
/// Regrasps an episode tries at most.
const MAX_REGRASPS: u32 = 2;

/// Where the cube goes once held: the poses of the carry (base frame), over the bin (cube_to_bin)
/// or the pad (place_cube).
#[derive(Debug, Clone, Copy)]
struct Carry {
    lifted: TaskPose,
    over_goal: TaskPose,
    release: TaskPose,
    /// The release moved away from the fixed jaw, which the cube still touches once let go.
    clear: TaskPose,
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
    /// Seconds the current gate has waited, and (when, how far) the arm was at its last look.
    waited: f64,
    progress: Option<(f64, f64)>,
    /// The gripper's position at the last step, and for how many steps it has not moved (the
    /// Gripped gate sees it stop).
    last_gripper: Option<f64>,
    gripper_still_for: u32,
    /// The noise-free grasp and the carry, for a regrasp when the cube's pose is not known.
    clean_grasp: TaskPose,
    #[cfg(test)]
    noisy_grasp: Vector3<f64>,
    carry: Carry,
    /// Where the cube goes without the waypoint noise (over the bin, the pad, the green cube),
    /// and how often the carry was moved to put the cube itself there (stack_cube: the carry
    /// goes to the noisy goal, the set-down to this one, for the stack's millimetres).
    clean_goal: Vector3<f64>,
    corrections: u32,
    /// No more action noise (from stack_cube's OverGoal gate on).
    quiet: bool,
    /// push_cube: where the pushes take the cube's centre (the target, with the waypoint noise),
    /// and the target itself.
    push_goal: Vector3<f64>,
    push_target: Vector3<f64>,
    table_z: f64,
    task: TaskKind,
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
/// The edge of stack_cube's green cube, m.
const STACK_BASE_EDGE: f64 = 0.03;
/// place_cube lets go with the cube this far above the table, m.
const PLACE_CLEARANCE: f64 = 0.006;
/// How far place_cube opens the jaws past closed to let go (holding the cube they stop about
/// 0.35 rad past it), rad.
const PLACE_OPENING: f64 = 0.6;
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
    let shifted = clear_of(grasp).position;
    // The arm's heading changes a little with the shift: align the jaws for the new one.
    Some(reachable_pose(shifted, yaw).unwrap_or(TaskPose {
        position: shifted,
        ..grasp
    }))
}

/// `release` moved horizontally away from the fixed jaw by [`JAW_CLEARANCE`] (the jaw axis points
/// from it to the moving jaw).
fn clear_of(release: TaskPose) -> TaskPose {
    TaskPose {
        position: release.position - horizontal_jaw_axis(&release) * JAW_CLEARANCE,
        ..release
    }
}

/// The horizontal part of the jaw axis (from the fixed jaw to the moving one) with the arm at
/// `pose` (the IK's solution from home).
fn horizontal_jaw_axis(pose: &TaskPose) -> Vector3<f64> {
    let limits = kinematics::arm_limits();
    let solution = kinematics::solve(pose, &[0.0; ARM_JOINTS], &limits, &IkOptions::default());
    let jaw_axis = kinematics::grasp_frame(&solution.joints).rotation * Vector3::x();
    Vector3::new(jaw_axis.x, jaw_axis.y, 0.0)
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
        let clean_grasp = grasp_pose(grasp_height, yaw).unwrap_or(grasp);
        let above = |position: Vector3<f64>, height: f64| {
            Vector3::new(position.x, position.y, config.table_z + height)
        };
        let (goal, release_height) = match config.task {
            TaskKind::PlaceCube => (config.pad, GRASP_ABOVE_TABLE + PLACE_CLEARANCE),
            TaskKind::StackCube => (
                config.stack_base,
                GRASP_ABOVE_TABLE + STACK_BASE_EDGE + PLACE_CLEARANCE,
            ),
            _ => (config.bin, RELEASE_ABOVE_TABLE),
        };
        let clean_goal = goal;
        let goal = goal + noise(rng);
        // Drawn for push_cube only: every other task's episodes keep the draws they had.
        let push_target = Vector3::new(config.push_target.x, config.push_target.y, cube.z);
        let push_goal = if config.task == TaskKind::PushCube {
            push_target + noise(rng)
        } else {
            push_target
        };
        let release = carry_pose(above(goal, release_height));
        let carry = Carry {
            lifted: carry_pose(above(grasp.position, CARRY_ABOVE_TABLE)),
            over_goal: carry_pose(above(goal, CARRY_ABOVE_TABLE)),
            release,
            clear: clear_of(release),
            leave: carry_pose(above(goal, CARRY_ABOVE_TABLE + 0.03)),
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
            progress: None,
            last_gripper: None,
            gripper_still_for: 0,
            clean_grasp,
            #[cfg(test)]
            noisy_grasp: grasp.position,
            carry,
            clean_goal,
            corrections: 0,
            quiet: false,
            push_goal,
            push_target,
            table_z: config.table_z,
            task: config.task,
            regrasps: 0,
            gripper_open: config.gripper_open,
            gripper_closed: config.gripper_closed,
            slowness: config.slowness,
        };
        plan.waypoints = if config.task == TaskKind::PushCube {
            plan.pushes(cube + noise(rng), 1.6).ok_or(unreachable)?
        } else {
            plan.pick_and_place(grasp, 1.6)
        };
        Ok(plan)
    }

    /// push_cube from wherever the arm is: above the start of a push behind the cube (at
    /// `cube`), down beside it, the push that takes it to the goal, then back and up. `None` when
    /// the arm reaches no pose of the push.
    fn pushes(&self, cube: Vector3<f64>, approach_s: f64) -> Option<Vec<Waypoint>> {
        let waypoint = |pose: TaskPose, duration: f64, gate: Gate| Waypoint {
            pose,
            gripper: push::GRIPPER,
            duration: duration * self.slowness,
            gate,
        };
        let stroke = push::Stroke::new(cube, self.push_goal, self.table_z)?;
        Some(vec![
            waypoint(stroke.above_start, approach_s, Gate::None),
            waypoint(stroke.start, 1.0, Gate::Reached),
            waypoint(stroke.end, stroke.seconds, Gate::Pushed),
            waypoint(stroke.back, 0.4, Gate::None),
            waypoint(stroke.above_back, 0.5, Gate::None),
        ])
    }

    /// From wherever the arm is: above the grasp, down to it, then the task's part: close, lift,
    /// carry, release (cube_to_bin over the bin, place_cube down on the pad, stack_cube down on
    /// the green cube); close, lift, hold (lift_cube); hold there (the touch tasks).
    fn pick_and_place(&self, grasp: TaskPose, approach_s: f64) -> Vec<Waypoint> {
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
        // On the table the jaws open only as far as letting go takes: a wide swing of the moving
        // jaw knocks the cube off where it was set down.
        let let_go = match self.task {
            TaskKind::PlaceCube | TaskKind::StackCube => closed + PLACE_OPENING,
            _ => open,
        };
        let down = [
            waypoint(approach, open, approach_s, Gate::None),
            waypoint(grasp, open, 1.0, Gate::Grasp),
            waypoint(grasp, open, 0.2, Gate::None),
        ];
        let grip_and_lift = [
            waypoint(grasp, closed, 0.6, Gate::Gripped),
            waypoint(carry.lifted, closed, 1.0, Gate::None),
        ];
        let rest: Vec<Waypoint> = match self.task {
            TaskKind::CubeToBin | TaskKind::PlaceCube | TaskKind::StackCube => {
                // stack_cube sets the cube down within millimetres: over the goal it first puts
                // the cube itself there; let go, the cube still touches the fixed jaw, so the jaws
                // move away from it before going up (straight up drags it off the green cube).
                let stack = self.task == TaskKind::StackCube;
                let over_goal = if stack { Gate::OverGoal } else { Gate::None };
                let clear = stack.then(|| waypoint(carry.clear, let_go, 0.3, Gate::None));
                grip_and_lift
                    .into_iter()
                    .chain([
                        waypoint(carry.over_goal, closed, 1.5, over_goal),
                        waypoint(carry.release, closed, 0.5, Gate::Reached),
                        waypoint(carry.release, let_go, 0.5, Gate::None),
                    ])
                    .chain(clear)
                    .chain([waypoint(carry.leave, open, 0.7, Gate::None)])
                    .collect()
            }
            TaskKind::LiftCube => grip_and_lift
                .into_iter()
                .chain([waypoint(carry.lifted, closed, 0.5, Gate::None)])
                .collect(),
            TaskKind::TouchCube | TaskKind::TouchCubeSparse | TaskKind::PushCube => {
                vec![waypoint(grasp, open, 0.5, Gate::None)]
            }
        };
        down.into_iter().chain(rest).collect()
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

    #[cfg(test)]
    fn grasp_was_noisy(&self) -> bool {
        self.noisy_grasp != self.clean_grasp.position
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
        let gripper = measured[JOINT_COUNT - 1];
        let moved = self
            .last_gripper
            .is_none_or(|last| (gripper - last).abs() >= GRIPPER_STILL);
        self.gripper_still_for = if moved { 0 } else { self.gripper_still_for + 1 };
        self.last_gripper = Some(gripper);
        self.advance(dt, measured, cube);
        self.targets_at_clock(config, rng)
    }

    fn advance(&mut self, dt: f64, measured: &JointPositions, cube: Option<(Vector3<f64>, f64)>) {
        // A stall or a jump of the caller's clock is not time the arm had to follow the plan.
        let dt = dt.clamp(0.0, MAX_STEP_SECONDS);
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
        // Only the time past the gate is waiting: before it, the arm was still being led there.
        self.waited += self.clock + dt - gate_at;
        self.clock = gate_at;
        let waypoint = self.waypoints[index];
        let arm: ArmPositions = std::array::from_fn(|joint| measured[joint]);
        // How far the measured grasp point is from the gate's pose.
        let distance = (kinematics::task_pose(&arm).position - waypoint.pose.position).norm();
        let reached = distance < REACHED_TOLERANCE;
        let gripper = measured[JOINT_COUNT - 1];
        let can_regrasp = self.regrasps < MAX_REGRASPS;
        let open = match waypoint.gate {
            Gate::None => true,
            Gate::Reached => reached,
            Gate::OverGoal => {
                // A stack is set down within a few millimetres: from here on, no noise on the
                // joint targets (0.01 rad each swings the cube by a centimetre).
                self.quiet = true;
                let off = cube
                    .filter(|_| reached)
                    .map(|(at, _)| {
                        Vector3::new(at.x - self.clean_goal.x, at.y - self.clean_goal.y, 0.0)
                    })
                    .filter(|off| off.norm() > SET_DOWN_TOLERANCE);
                if let Some(off) = off.filter(|_| self.corrections < MAX_CORRECTIONS) {
                    self.shift_goal(-off);
                    self.corrections += 1;
                    self.waited = 0.0;
                    return;
                }
                reached
            }
            Gate::Grasp => {
                if self.stalled(distance) && !reached && can_regrasp {
                    self.regrasp(measured, cube);
                    return;
                }
                reached
            }
            Gate::Gripped => {
                // Closed past where the cube would have stopped the jaws: they hold nothing.
                if gripper < self.gripper_closed + EMPTY_GRIP && can_regrasp {
                    self.regrasp(measured, cube);
                    return;
                }
                self.gripper_still_for >= GRIPPER_STILL_PERIODS
            }
            Gate::Pushed => {
                // Judged against the target itself (the goal carries the waypoint noise): a
                // cube already on it is not pushed again, whichever way the noise put the goal.
                let off_target =
                    cube.is_some_and(|(at, _)| (at - self.push_target).xy().norm() > push::ON_GOAL);
                if (reached || self.waited >= GATE_TIMEOUT) && off_target && can_regrasp {
                    if let Some((at, _)) = cube {
                        self.push_again(measured, at);
                        return;
                    }
                }
                reached
            }
        };
        if open || self.waited >= GATE_TIMEOUT {
            let sets_down = matches!(self.task, TaskKind::PlaceCube | TaskKind::StackCube);
            if waypoint.gate == Gate::Gripped && sets_down {
                if let Some((at, _)) = cube {
                    // The cube sits off the grasp point in the jaws: set the cube, not the grasp
                    // point, down on the pad.
                    let grasp_point = kinematics::task_pose(&arm).position;
                    let shift = held_offset_shift(grasp_point, at, self.carry.release.position);
                    self.shift_goal(shift);
                }
            }
            self.next_gate = index + 1;
            self.waited = 0.0;
            self.progress = None;
        }
    }

    /// Moves the carry's goal (over it, the release, the leave) by `offset`, in the carry's
    /// poses and in the waypoints still to come.
    fn shift_goal(&mut self, offset: Vector3<f64>) {
        let old = self.carry;
        let moved = |pose: TaskPose| carry_pose(pose.position + offset);
        self.carry.over_goal = moved(old.over_goal);
        self.carry.release = moved(old.release);
        self.carry.clear = clear_of(self.carry.release);
        self.carry.leave = moved(old.leave);
        for waypoint in &mut self.waypoints[self.next_gate..] {
            for (before, after) in [
                (old.over_goal, self.carry.over_goal),
                (old.release, self.carry.release),
                (old.clear, self.carry.clear),
                (old.leave, self.carry.leave),
            ] {
                if waypoint.pose == before {
                    waypoint.pose = after;
                }
            }
        }
    }

    /// Whether the grasp point, `distance` from the gate's pose, got no nearer over the last
    /// [`BLOCKED_AFTER`] seconds of waiting (a slow arm still gets nearer; a blocked one does not).
    fn stalled(&mut self, distance: f64) -> bool {
        match self.progress {
            None => {
                self.progress = Some((self.waited, distance));
                false
            }
            Some((since, then)) if self.waited - since >= BLOCKED_AFTER => {
                self.progress = Some((self.waited, distance));
                then - distance < STALLED_PROGRESS
            }
            Some(_) => false,
        }
    }

    /// Starts again from the arm where it is: straight up, over to above the cube's grasp (where
    /// `cube` says it is now, else where it was planned) without the noise, and down to it.
    fn regrasp(&mut self, measured: &JointPositions, cube: Option<(Vector3<f64>, f64)>) {
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
        // Opening on the way up.
        let again = self.pick_and_place(grasp, 0.8);
        self.start_again(measured, self.gripper_open, again);
    }

    /// Another push from the arm where it is: straight up, then the push of the cube from `cube`
    /// (where it now lies) to the goal. Counted with the regrasps.
    fn push_again(&mut self, measured: &JointPositions, cube: Vector3<f64>) {
        match self.pushes(cube, 0.8) {
            Some(again) => self.start_again(measured, push::GRIPPER, again),
            // Out of reach from here: the plan goes on as it was, and tries no more.
            None => self.regrasps = MAX_REGRASPS,
        }
    }

    /// Plays `waypoints` from the arm at `measured`, after going straight up (the gripper moving
    /// to `gripper`): a sideways move at the cube's height could knock it again. Counts a regrasp.
    fn start_again(&mut self, measured: &JointPositions, gripper: f64, waypoints: Vec<Waypoint>) {
        let arm: ArmPositions = std::array::from_fn(|joint| measured[joint]);
        let here = kinematics::task_pose(&arm);
        self.start = Waypoint {
            pose: here,
            gripper: measured[JOINT_COUNT - 1],
            duration: 0.0,
            gate: Gate::None,
        };
        let up = TaskPose {
            position: Vector3::new(
                here.position.x,
                here.position.y,
                self.table_z + GRASP_ABOVE_TABLE + APPROACH_ABOVE_CUBE,
            ),
            ..here
        };
        self.waypoints = std::iter::once(Waypoint {
            pose: up,
            gripper,
            duration: 0.5 * self.slowness,
            gate: Gate::None,
        })
        .chain(waypoints)
        .collect();
        self.seed = arm;
        self.clock = 0.0;
        self.next_gate = 0;
        self.waited = 0.0;
        self.progress = None;
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
        let noise = if self.quiet { 0.0 } else { config.action_noise };
        std::array::from_fn(|joint| {
            let value = if joint < ARM_JOINTS {
                solution.joints[joint]
            } else {
                gripper
            };
            JOINT_LIMITS[joint].clamp(value + normal(rng) * noise)
        })
    }
}

/// How far to move a goal of the grasp point so that the cube, held off it (at `cube` when the
/// grasp point was at `grasp_point`), lands on the goal instead: the offset turns with the arm's
/// heading on the way (it is fixed in the gripper, not in the base frame). Horizontal only.
fn held_offset_shift(
    grasp_point: Vector3<f64>,
    cube: Vector3<f64>,
    goal: Vector3<f64>,
) -> Vector3<f64> {
    let offset = Vector3::new(cube.x - grasp_point.x, cube.y - grasp_point.y, 0.0);
    let turned = |to: &Vector3<f64>| {
        let angle = kinematics::azimuth(to) - kinematics::azimuth(&grasp_point);
        let (sin, cos) = angle.sin_cos();
        Vector3::new(
            cos * offset.x - sin * offset.y,
            sin * offset.x + cos * offset.y,
            0.0,
        )
    };
    // Where the grasp point must go depends on the heading there: a few rounds settle it.
    let mut target = goal - offset;
    for _ in 0..3 {
        target = goal - turned(&target);
    }
    Vector3::new(target.x - goal.x, target.y - goal.y, 0.0)
}

/// The grasp point at `position` pointing as steeply down as the arm reaches there (straight down
/// if it can), with the jaws across the faces of a cube of yaw `yaw`; `None` when no pitch of
/// [`GRASP_PITCHES`] reaches it.
fn reachable_pose(position: Vector3<f64>, yaw: f64) -> Option<TaskPose> {
    reachable_pose_with(position, |heading| grasp_roll(heading, yaw))
}

/// The grasp point at `position` pointing as steeply down as the arm reaches there, with the roll
/// `roll` gives for the arm's heading; `None` when no pitch of [`GRASP_PITCHES`] reaches it.
fn reachable_pose_with(position: Vector3<f64>, roll: impl Fn(f64) -> f64) -> Option<TaskPose> {
    let limits = kinematics::arm_limits();
    let options = IkOptions::default();
    GRASP_PITCHES.iter().find_map(|&pitch| {
        let mut pose = TaskPose {
            position,
            pitch,
            roll: roll(kinematics::azimuth(&position)),
        };
        let first = kinematics::solve(&pose, &[0.0; ARM_JOINTS], &limits, &options);
        // The arm's plane is off the point's azimuth by the links' sideways offsets: recompute
        // the roll for the heading the arm really takes.
        pose.roll = roll(kinematics::heading(&first.joints));
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

mod push;
#[cfg(test)]
mod tests;
