//! push_cube's stroke: the closed jaws come down behind the cube, side by side across the push
//! (a flat face 3 cm wide, so the cube turns square to it and slides straight), and push its
//! centre onto the goal along the line from the cube to the goal. Pure geometry.

use std::f64::consts::{FRAC_PI_2, PI};

use nalgebra::Vector3;

use super::{horizontal_jaw_axis, reachable_pose_with, APPROACH_ABOVE_CUBE, GRASP_ABOVE_TABLE};
use crate::kinematics::{self, TaskPose};

/// The cube's centre within this of the target needs no other push (m): well inside the 3 cm the
/// task asks. Nearer, another push would start from a line of a few millimetres in any direction,
/// and more often push a cube that is on the target off it than onto its centre.
pub(super) const ON_GOAL: f64 = 0.018;
/// The gripper while pushing (rad): the pads about 18 mm apart, so both press on the cube's
/// face near its edges (one pad alone turns the cube off the line).
pub(super) const GRIPPER: f64 = 0.05;
/// The pads' middle then lies this far behind the grasp point along the jaw axis (m;
/// assets/so101_cube_to_bin.xml: the fixed pad's inner face at x = -0.008 of the gripper, the
/// grasp point at +0.007, the moving pad's inner face 18 mm from the fixed one's).
const FINGERS_BEHIND_GRASP_POINT: f64 = 0.006;
/// From the pads' middle to the face that pushes (half a pad's width), and from the cube's
/// centre to its face (m).
const FINGER_HALF_WIDTH: f64 = 0.0075;
const CUBE_HALF_EDGE: f64 = 0.015;
/// Room between the pushing face and the cube as the fingers come down, and how far they back
/// off after the push (m).
const START_GAP: f64 = 0.015;
const BACK_OFF: f64 = 0.02;
/// The push's mean speed (m/s): slow enough that the cube never slides on past the fingers.
const PUSH_SPEED: f64 = 0.06;
/// The shortest push (s).
const MIN_PUSH_SECONDS: f64 = 0.5;

/// The poses of one push (grasp point, base frame) and how long the push itself takes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Stroke {
    pub above_start: TaskPose,
    pub start: TaskPose,
    pub end: TaskPose,
    pub back: TaskPose,
    pub above_back: TaskPose,
    pub seconds: f64,
}

impl Stroke {
    /// The push of a cube whose centre is at `cube` to `goal` (base frame; the table's top at
    /// `table_z`). `None` when the arm reaches one of its poses with no pitch.
    pub fn new(cube: Vector3<f64>, goal: Vector3<f64>, table_z: f64) -> Option<Self> {
        let along = (goal - cube).xy();
        let distance = along.norm();
        // Pushed from the base's side when already on the goal (a push of no length).
        let direction = if distance > 1e-6 {
            Vector3::new(along.x / distance, along.y / distance, 0.0)
        } else {
            Vector3::new(cube.x, cube.y, 0.0).normalize()
        };
        let height = table_z + GRASP_ABOVE_TABLE;
        // Where the fingers' middle is when the pushing face touches a cube centred at `centre`.
        let touching = |centre: Vector3<f64>| {
            let at = centre - direction * (CUBE_HALF_EDGE + FINGER_HALF_WIDTH);
            Vector3::new(at.x, at.y, height)
        };
        let start = touching(cube) - direction * START_GAP;
        let end = touching(goal);
        let back = end - direction * BACK_OFF;
        let up = Vector3::new(0.0, 0.0, APPROACH_ABOVE_CUBE);
        Some(Self {
            above_start: fingers_pose(start + up, direction)?,
            start: fingers_pose(start, direction)?,
            end: fingers_pose(end, direction)?,
            back: fingers_pose(back, direction)?,
            above_back: fingers_pose(back + up, direction)?,
            seconds: ((distance + START_GAP) / PUSH_SPEED).max(MIN_PUSH_SECONDS),
        })
    }
}

/// The pose that puts the closed fingers' middle at `fingers`, pointing as steeply down as the
/// arm reaches, the jaws side by side across `direction` (horizontal, unit).
fn fingers_pose(fingers: Vector3<f64>, direction: Vector3<f64>) -> Option<TaskPose> {
    let push_angle = direction.y.atan2(direction.x);
    // Pointing down, the jaw axis lies at heading + pi/2 - roll in the horizontal plane: across
    // the push for roll = heading - push angle, either way round. The smaller roll first; the
    // wrist's range reaches some only the other way round.
    [0.0, PI, -PI].into_iter().find_map(|turn| {
        let roll = |heading: f64| half_turn(heading - push_angle) + turn;
        let first = reachable_pose_with(fingers, roll)?;
        let forward = horizontal_jaw_axis(&first) * FINGERS_BEHIND_GRASP_POINT;
        reachable_pose_with(fingers + forward, roll)
    })
}

/// `angle` as the same line's angle in (-pi/2, pi/2].
fn half_turn(angle: f64) -> f64 {
    let wrapped = kinematics::wrap_angle(angle);
    if wrapped > FRAC_PI_2 {
        wrapped - PI
    } else if wrapped <= -FRAC_PI_2 {
        wrapped + PI
    } else {
        wrapped
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kinematics::{IkOptions, ARM_JOINTS};

    #[test]
    fn the_fingers_push_across_the_line_to_the_goal() {
        let table_z = 0.0;
        let cube = Vector3::new(0.23, -0.05, 0.015);
        let goal = Vector3::new(0.26, 0.13, 0.015);
        let stroke = Stroke::new(cube, goal, table_z).expect("reachable");
        let direction = (goal - cube).xy().normalize();
        let limits = kinematics::arm_limits();
        for pose in [stroke.start, stroke.end] {
            let joints =
                kinematics::solve(&pose, &[0.0; ARM_JOINTS], &limits, &IkOptions::default()).joints;
            let frame = kinematics::grasp_frame(&joints);
            // The jaw axis lies across the push, horizontal.
            let jaw_axis = frame.rotation * Vector3::x();
            assert!(jaw_axis.xy().dot(&direction).abs() < 0.05, "{jaw_axis:?}");
            assert!(jaw_axis.z.abs() < 0.05, "{jaw_axis:?}");
        }
        // The start is behind the cube, the end the pushing face's distance behind the goal.
        let fingers = |pose: TaskPose| {
            let joints =
                kinematics::solve(&pose, &[0.0; ARM_JOINTS], &limits, &IkOptions::default()).joints;
            let frame = kinematics::grasp_frame(&joints);
            (pose.position - frame.rotation * Vector3::x() * FINGERS_BEHIND_GRASP_POINT).xy()
        };
        let reach = CUBE_HALF_EDGE + FINGER_HALF_WIDTH;
        let start = fingers(stroke.start);
        let end = fingers(stroke.end);
        assert!(((cube.xy() - start).dot(&direction) - reach - START_GAP).abs() < 0.003);
        assert!(((goal.xy() - end).dot(&direction) - reach).abs() < 0.003);
        assert!((stroke.start.position.z - GRASP_ABOVE_TABLE).abs() < 1e-9);
        let length = (goal - cube).xy().norm() + START_GAP;
        assert!((stroke.seconds - length / PUSH_SPEED).abs() < 1e-9);
    }

    #[test]
    fn rolls_are_the_smaller_of_the_two_across_a_line() {
        assert!((half_turn(0.75 * PI) + 0.25 * PI).abs() < 1e-12);
        assert!((half_turn(-0.75 * PI) - 0.25 * PI).abs() < 1e-12);
        assert!((half_turn(0.25 * PI) - 0.25 * PI).abs() < 1e-12);
    }
}
