//! Joint trajectories, as trajectory_msgs/JointTrajectory and control_msgs' FollowJointTrajectory
//! carry them: validated whole on arrival, then sampled at the control rate, with the tolerances
//! of the action. Pure: the nodes feed it times and positions.
//!
//! Between two points the positions are interpolated linearly, or by a cubic through the two
//! points' velocities when both give them (joint_trajectory_controller's spline). The first segment
//! starts from where the arm was told to be when the trajectory started, at rest. Joints the
//! trajectory does not name keep their targets.

use crate::{
    command::PartialTargets,
    robot::{joint_index, JointLimit, JointPositions, JOINT_COUNT, JOINT_NAMES},
};

/// Why a trajectory was refused (nothing of it is executed).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TrajectoryError {
    #[error("the trajectory names no joints")]
    NoJoints,
    #[error("the trajectory has no points")]
    NoPoints,
    #[error("unknown joint name {0:?} (expected some of {JOINT_NAMES:?})")]
    UnknownJoint(String),
    #[error("joint {0:?} is named twice")]
    DuplicateJoint(String),
    #[error("point {point} has {got} positions for {expected} joints")]
    PositionCount {
        point: usize,
        expected: usize,
        got: usize,
    },
    #[error(
        "point {point} has {got} velocities for {expected} joints (give none or one per joint)"
    )]
    VelocityCount {
        point: usize,
        expected: usize,
        got: usize,
    },
    #[error("point {point}: a value of {joint} is not finite")]
    NotFinite { point: usize, joint: &'static str },
    #[error("point {point}: time_from_start {time} s is not after the previous point's")]
    TimeNotIncreasing { point: usize, time: f64 },
    #[error("point {point}: {joint} at {value} rad is outside its range {min} to {max}")]
    OutOfRange {
        point: usize,
        joint: &'static str,
        value: f64,
        min: f64,
        max: f64,
    },
}

/// One point as it arrives: seconds from the start, one position per named joint, and either no
/// velocities or one per named joint.
#[derive(Debug, Clone, PartialEq)]
pub struct PointInput {
    pub time_from_start: f64,
    pub positions: Vec<f64>,
    pub velocities: Vec<f64>,
}

#[derive(Debug, Clone, PartialEq)]
struct Point {
    time: f64,
    positions: Vec<f64>,
    velocities: Option<Vec<f64>>,
}

/// A validated trajectory.
#[derive(Debug, Clone, PartialEq)]
pub struct Trajectory {
    /// Joint indices, in the order of the points' values.
    joints: Vec<usize>,
    points: Vec<Point>,
}

impl Trajectory {
    /// Validates a trajectory for joints `names` against `limits`.
    pub fn new(
        names: &[String],
        points: &[PointInput],
        limits: &[JointLimit; JOINT_COUNT],
    ) -> Result<Self, TrajectoryError> {
        if names.is_empty() {
            return Err(TrajectoryError::NoJoints);
        }
        if points.is_empty() {
            return Err(TrajectoryError::NoPoints);
        }
        let mut joints = Vec::with_capacity(names.len());
        for name in names {
            let joint =
                joint_index(name).ok_or_else(|| TrajectoryError::UnknownJoint(name.clone()))?;
            if joints.contains(&joint) {
                return Err(TrajectoryError::DuplicateJoint(name.clone()));
            }
            joints.push(joint);
        }
        let mut previous_time = None;
        let mut validated = Vec::with_capacity(points.len());
        for (index, point) in points.iter().enumerate() {
            if point.positions.len() != joints.len() {
                return Err(TrajectoryError::PositionCount {
                    point: index,
                    expected: joints.len(),
                    got: point.positions.len(),
                });
            }
            if !point.velocities.is_empty() && point.velocities.len() != joints.len() {
                return Err(TrajectoryError::VelocityCount {
                    point: index,
                    expected: joints.len(),
                    got: point.velocities.len(),
                });
            }
            let time = point.time_from_start;
            if !time.is_finite() || time < 0.0 || previous_time.is_some_and(|before| time <= before)
            {
                return Err(TrajectoryError::TimeNotIncreasing { point: index, time });
            }
            previous_time = Some(time);
            for (slot, &joint) in joints.iter().enumerate() {
                let finite = point.positions[slot].is_finite()
                    && point.velocities.get(slot).is_none_or(|v| v.is_finite());
                if !finite {
                    return Err(TrajectoryError::NotFinite {
                        point: index,
                        joint: JOINT_NAMES[joint],
                    });
                }
                let value = point.positions[slot];
                let limit = limits[joint];
                if value < limit.min || value > limit.max {
                    return Err(TrajectoryError::OutOfRange {
                        point: index,
                        joint: JOINT_NAMES[joint],
                        value,
                        min: limit.min,
                        max: limit.max,
                    });
                }
            }
            validated.push(Point {
                time,
                positions: point.positions.clone(),
                velocities: (!point.velocities.is_empty()).then(|| point.velocities.clone()),
            });
        }
        Ok(Self {
            joints,
            points: validated,
        })
    }

    /// The named joints' indices, in the trajectory's order.
    pub fn joints(&self) -> &[usize] {
        &self.joints
    }

    /// Seconds from the start to the last point.
    pub fn duration(&self) -> f64 {
        self.points.last().map_or(0.0, |point| point.time)
    }

    /// The last point's positions, in the trajectory's joint order.
    pub fn final_positions(&self) -> &[f64] {
        self.points.last().map_or(&[], |point| &point.positions)
    }

    /// The last point as targets (joints not named: none).
    pub fn final_targets(&self) -> PartialTargets {
        let mut targets = [None; JOINT_COUNT];
        for (&joint, &position) in self.joints.iter().zip(self.final_positions()) {
            targets[joint] = Some(position);
        }
        PartialTargets::from_validated(targets)
    }

    /// Positions and velocities (trajectory's joint order) `t` s after the start, having started
    /// from `start` (every joint, at rest).
    pub fn sample(&self, start: &JointPositions, t: f64) -> (Vec<f64>, Vec<f64>) {
        let later = self.points.partition_point(|point| point.time <= t);
        if later == self.points.len() {
            let last = &self.points[later - 1];
            return (last.positions.clone(), vec![0.0; self.joints.len()]);
        }
        let to = &self.points[later];
        let origin;
        let from = if later == 0 {
            origin = Point {
                time: 0.0,
                positions: self.joints.iter().map(|&joint| start[joint]).collect(),
                velocities: Some(vec![0.0; self.joints.len()]),
            };
            &origin
        } else {
            &self.points[later - 1]
        };
        let span = to.time - from.time;
        let s = ((t - from.time) / span).clamp(0.0, 1.0);
        let mut positions = Vec::with_capacity(self.joints.len());
        let mut velocities = Vec::with_capacity(self.joints.len());
        for slot in 0..self.joints.len() {
            let (p0, p1) = (from.positions[slot], to.positions[slot]);
            match (&from.velocities, &to.velocities) {
                (Some(v0), Some(v1)) => {
                    let (m0, m1) = (v0[slot] * span, v1[slot] * span);
                    let (s2, s3) = (s * s, s * s * s);
                    positions.push(
                        (2.0 * s3 - 3.0 * s2 + 1.0) * p0
                            + (s3 - 2.0 * s2 + s) * m0
                            + (-2.0 * s3 + 3.0 * s2) * p1
                            + (s3 - s2) * m1,
                    );
                    velocities.push(
                        ((6.0 * s2 - 6.0 * s) * p0
                            + (3.0 * s2 - 4.0 * s + 1.0) * m0
                            + (-6.0 * s2 + 6.0 * s) * p1
                            + (3.0 * s2 - 2.0 * s) * m1)
                            / span,
                    );
                }
                _ => {
                    positions.push(p0 + s * (p1 - p0));
                    velocities.push((p1 - p0) / span);
                }
            }
        }
        (positions, velocities)
    }

    /// The targets `t` s after the start.
    pub fn targets(&self, start: &JointPositions, t: f64) -> PartialTargets {
        let (positions, _) = self.sample(start, t);
        let mut targets = [None; JOINT_COUNT];
        for (&joint, position) in self.joints.iter().zip(positions) {
            targets[joint] = Some(position);
        }
        PartialTargets::from_validated(targets)
    }
}

/// FollowJointTrajectory's tolerances for one goal (rad): a joint without one is not checked.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Tolerances {
    /// Largest |actual - desired| while the trajectory runs.
    pub path: [Option<f64>; JOINT_COUNT],
    /// Largest |actual - final| once it has ended.
    pub goal: [Option<f64>; JOINT_COUNT],
    /// Seconds after the end the arm has to come within the goal tolerance.
    pub goal_time: f64,
}

/// Seconds after the end to reach the goal tolerance when the goal says 0.
pub const DEFAULT_GOAL_TIME_TOLERANCE: f64 = 0.5;

impl Tolerances {
    /// From control_msgs/JointTolerance entries (name, position): a position above 0 is a
    /// tolerance, 0 or -1 none; unknown names are an error.
    pub fn new(
        path: &[(String, f64)],
        goal: &[(String, f64)],
        goal_time: f64,
    ) -> Result<Self, TrajectoryError> {
        let table = |entries: &[(String, f64)]| {
            let mut table = [None; JOINT_COUNT];
            for (name, position) in entries {
                let joint =
                    joint_index(name).ok_or_else(|| TrajectoryError::UnknownJoint(name.clone()))?;
                table[joint] = (*position > 0.0 && position.is_finite()).then_some(*position);
            }
            Ok(table)
        };
        Ok(Self {
            path: table(path)?,
            goal: table(goal)?,
            goal_time: if goal_time > 0.0 && goal_time.is_finite() {
                goal_time
            } else {
                DEFAULT_GOAL_TIME_TOLERANCE
            },
        })
    }
}

/// Where a followed trajectory stands.
#[derive(Debug, Clone, PartialEq)]
pub enum Progress {
    Running,
    Succeeded,
    PathToleranceViolated(String),
    GoalToleranceViolated(String),
}

/// A trajectory being followed: when it started, from where, with what tolerances.
#[derive(Debug, Clone, PartialEq)]
pub struct Follower {
    trajectory: Trajectory,
    started: f64,
    start: JointPositions,
    tolerances: Tolerances,
}

impl Follower {
    /// Starts `trajectory` at time `started` (the node's clock, s) from the positions `start`.
    pub fn new(
        trajectory: Trajectory,
        started: f64,
        start: JointPositions,
        tolerances: Tolerances,
    ) -> Self {
        Self {
            trajectory,
            started,
            start,
            tolerances,
        }
    }

    pub fn trajectory(&self) -> &Trajectory {
        &self.trajectory
    }

    /// The targets at `now`; none before the start time.
    pub fn targets(&self, now: f64) -> Option<PartialTargets> {
        (now >= self.started).then(|| self.trajectory.targets(&self.start, now - self.started))
    }

    /// Desired positions and velocities at `now` (trajectory's joint order).
    pub fn desired(&self, now: f64) -> (Vec<f64>, Vec<f64>) {
        self.trajectory
            .sample(&self.start, (now - self.started).max(0.0))
    }

    /// Where the trajectory stands at `now`, the arm at `actual`.
    pub fn progress(&self, now: f64, actual: &JointPositions) -> Progress {
        let elapsed = now - self.started;
        if elapsed < self.trajectory.duration() {
            let (desired, _) = self.desired(now);
            return match self.violation(&self.tolerances.path, &desired, actual) {
                Some(message) => Progress::PathToleranceViolated(message),
                None => Progress::Running,
            };
        }
        let last = self.trajectory.final_positions();
        match self.violation(&self.tolerances.goal, last, actual) {
            None => Progress::Succeeded,
            Some(_) if elapsed < self.trajectory.duration() + self.tolerances.goal_time => {
                Progress::Running
            }
            Some(message) => Progress::GoalToleranceViolated(message),
        }
    }

    fn violation(
        &self,
        tolerances: &[Option<f64>; JOINT_COUNT],
        wanted: &[f64],
        actual: &JointPositions,
    ) -> Option<String> {
        self.trajectory
            .joints
            .iter()
            .zip(wanted)
            .find_map(|(&joint, &wanted)| {
                let tolerance = tolerances[joint]?;
                let error = (actual[joint] - wanted).abs();
                (error > tolerance).then(|| {
                    format!(
                        "{} is {error:.4} rad from {wanted:.4} (tolerance {tolerance})",
                        JOINT_NAMES[joint]
                    )
                })
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robot::JOINT_LIMITS;

    fn names(names: &[&str]) -> Vec<String> {
        names.iter().map(|name| name.to_string()).collect()
    }

    fn point(time: f64, positions: &[f64], velocities: &[f64]) -> PointInput {
        PointInput {
            time_from_start: time,
            positions: positions.to_vec(),
            velocities: velocities.to_vec(),
        }
    }

    fn pan_lift() -> Trajectory {
        Trajectory::new(
            &names(&["shoulder_pan", "shoulder_lift"]),
            &[point(1.0, &[0.5, -0.2], &[]), point(3.0, &[-0.5, 0.2], &[])],
            &JOINT_LIMITS,
        )
        .unwrap()
    }

    #[test]
    fn linear_segments_start_from_the_arm_and_hold_the_last_point() {
        let trajectory = pan_lift();
        let start = [0.1; JOINT_COUNT];
        let (positions, _) = trajectory.sample(&start, 0.5);
        assert!((positions[0] - 0.3).abs() < 1e-12 && (positions[1] + 0.05).abs() < 1e-12);
        let (positions, velocities) = trajectory.sample(&start, 2.0);
        assert!(positions[0].abs() < 1e-12 && (velocities[0] + 0.5).abs() < 1e-12);
        assert_eq!(trajectory.sample(&start, 9.0).0, vec![-0.5, 0.2]);
        let targets = trajectory.targets(&start, 1.0);
        assert_eq!(targets.get(0), Some(0.5));
        assert_eq!(targets.get(2), None, "joints not named keep their targets");
    }

    #[test]
    fn velocities_give_a_cubic_through_both_points() {
        let trajectory = Trajectory::new(
            &names(&["elbow_flex"]),
            &[point(1.0, &[0.0], &[1.0]), point(2.0, &[1.0], &[0.0])],
            &JOINT_LIMITS,
        )
        .unwrap();
        let start = [0.0; JOINT_COUNT];
        let at = |t: f64| trajectory.sample(&start, t);
        assert!((at(1.0).0[0]).abs() < 1e-12 && (at(1.0).1[0] - 1.0).abs() < 1e-12);
        assert!((at(2.0).0[0] - 1.0).abs() < 1e-12);
        assert!((at(1.999_999).1[0]).abs() < 1e-4, "arrives at rest");
    }

    #[test]
    fn malformed_or_out_of_range_trajectories_are_refused_whole() {
        let limits = &JOINT_LIMITS;
        let one = names(&["gripper"]);
        let cases: Vec<(Vec<String>, Vec<PointInput>, &str)> = vec![
            (vec![], vec![point(1.0, &[], &[])], "no joints"),
            (one.clone(), vec![], "no points"),
            (
                names(&["elbow"]),
                vec![point(1.0, &[0.0], &[])],
                "unknown joint",
            ),
            (
                names(&["gripper", "gripper"]),
                vec![point(1.0, &[0.0, 0.0], &[])],
                "twice",
            ),
            (
                one.clone(),
                vec![point(1.0, &[0.0, 0.1], &[])],
                "2 positions for 1",
            ),
            (
                one.clone(),
                vec![point(1.0, &[0.0], &[0.0, 0.0])],
                "velocities",
            ),
            (
                one.clone(),
                vec![point(1.0, &[f64::NAN], &[])],
                "not finite",
            ),
            (
                one.clone(),
                vec![point(1.0, &[0.0], &[]), point(1.0, &[0.1], &[])],
                "not after",
            ),
            (one.clone(), vec![point(-1.0, &[0.0], &[])], "not after"),
            (one, vec![point(1.0, &[9.0], &[])], "outside its range"),
        ];
        for (names, points, expected) in cases {
            let error = Trajectory::new(&names, &points, limits)
                .unwrap_err()
                .to_string();
            assert!(error.contains(expected), "{error:?} lacks {expected:?}");
        }
    }

    #[test]
    fn the_follower_checks_path_and_goal_tolerances() {
        let tolerances = Tolerances::new(
            &[("shoulder_pan".into(), 0.1)],
            &[
                ("shoulder_pan".into(), 0.02),
                ("shoulder_lift".into(), -1.0),
            ],
            0.0,
        )
        .unwrap();
        assert_eq!(tolerances.goal_time, DEFAULT_GOAL_TIME_TOLERANCE);
        assert_eq!(tolerances.goal[1], None);
        let follower = Follower::new(pan_lift(), 10.0, [0.0; JOINT_COUNT], tolerances);
        assert_eq!(follower.targets(9.0), None, "nothing before the start");
        let mut actual = [0.0; JOINT_COUNT];
        actual[0] = 0.25; // desired 0.25 at 10.5 s
        assert_eq!(follower.progress(10.5, &actual), Progress::Running);
        actual[0] = 0.0;
        assert!(matches!(
            follower.progress(10.5, &actual),
            Progress::PathToleranceViolated(message) if message.contains("shoulder_pan")
        ));
        actual[0] = -0.45;
        assert_eq!(
            follower.progress(13.1, &actual),
            Progress::Running,
            "settling"
        );
        assert!(matches!(
            follower.progress(13.6, &actual),
            Progress::GoalToleranceViolated(_)
        ));
        actual[0] = -0.49;
        assert_eq!(follower.progress(13.6, &actual), Progress::Succeeded);
        assert!(Tolerances::new(&[("nope".into(), 0.1)], &[], 0.0).is_err());
    }
}
