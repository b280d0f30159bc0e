//! The arm's trajectory interface, as ros2_control's joint_trajectory_controller named
//! `arm_controller` offers it: trajectory_msgs/JointTrajectory on `arm_controller/joint_trajectory`
//! and the action control_msgs/action/FollowJointTrajectory on
//! `arm_controller/follow_joint_trajectory` (what MoveIt's controller manager sends), shared by
//! the simulation and the driver. The node polls it once per control period, in its own clock
//! (sim time, or monotonic wall time; header stamps are read in it):
//! [`ArmController::take_new`], [`ArmController::targets`], then [`ArmController::after_period`].
//!
//! One trajectory runs at a time: a newer one (topic or goal) or any direct command preempts it.
//! After a successful end its last point stays the target until the arm is there, for at most
//! [`HOLD_SECONDS`] (the driver's watchdog would otherwise stop the arm short of it, and a stalled
//! arm must not be pushed for ever). A goal that cannot run is accepted and aborted at once with
//! the reason in its result's error_string, so the client learns why.

mod goals;

use std::time::{Duration, Instant};

use ros2_client::{
    action::{ActionServer, ActionServerQosPolicies, GoalInfo, SendGoalResponse},
    action_msgs::GoalStatusEnum,
    ServiceMapping, Subscription,
};
use so101_msgs::{
    builtin_interfaces::Time,
    control_msgs::{
        FollowJointTrajectory, FollowJointTrajectoryFeedback as Feedback,
        FollowJointTrajectoryGoal as Goal, FollowJointTrajectoryResult as Outcome,
    },
    std_msgs::Header,
    trajectory_msgs::{JointTrajectory, JointTrajectoryPoint},
};

use crate::{
    command::PartialTargets,
    contract::{actions, topics},
    robot::{JointLimit, JointPositions, JOINT_COUNT, JOINT_NAMES},
    ros::{node::NodeError, qos, rate_limit::RateLimiter, RosNode},
    trajectory::{Follower, PointInput, Progress, Tolerances, Trajectory, TrajectoryError},
};
use goals::{GoalBook, GoalRecord};

type Server = ActionServer<Goal, Outcome, Feedback>;
type AcceptedAt = ros2_client::builtin_interfaces::Time;

/// Seconds of the node's clock between two feedback messages of a goal.
const FEEDBACK_PERIOD: f64 = 0.05;
/// Longest the last point of a finished trajectory is held as the target.
pub const HOLD_SECONDS: f64 = 2.0;
/// Distance (rad) at which a held joint counts as arrived.
const ARRIVED: f64 = 0.005;
/// Latest start accepted for a stamped trajectory (s from now): a stamp in another clock (wall
/// time sent to the sim) would otherwise wait for ever.
const START_HORIZON: f64 = 60.0;

struct Active {
    follower: Follower,
    goal: Option<GoalRecord>,
    next_feedback: f64,
}

/// The last point of a finished trajectory, held until the arm is there or `until`.
struct Hold {
    targets: PartialTargets,
    until: f64,
}

/// The topic, the action server and the trajectory being followed.
pub struct ArmController {
    topic: Subscription<JointTrajectory>,
    action: Server,
    active: Option<Active>,
    hold: Option<Hold>,
    goals: GoalBook<ros2_client::RmwRequestId>,
    warnings: RateLimiter,
    /// Trajectories started, and refused, since the node started (for /diagnostics).
    pub accepted: u64,
    pub rejected: u64,
}

impl ArmController {
    pub fn serve(node: &mut RosNode) -> Result<Self, NodeError> {
        let topic =
            node.subscription::<JointTrajectory>(topics::JOINT_TRAJECTORY, qos::reliable(10))?;
        let name = node.names().name(actions::FOLLOW_JOINT_TRAJECTORY)?;
        let action = node
            .node_mut()
            .create_action_server::<Goal, Outcome, Feedback>(
                ServiceMapping::Enhanced,
                &name,
                &FollowJointTrajectory::action_type_name(),
                ActionServerQosPolicies {
                    goal_service: qos::service(),
                    result_service: qos::service(),
                    cancel_service: qos::service(),
                    feedback_publisher: qos::reliable(10),
                    // rcl's action status: the latest list for late joiners.
                    status_publisher: qos::latched(),
                },
            )
            .map_err(|error| NodeError::Create {
                what: format!("action {}", actions::FOLLOW_JOINT_TRAJECTORY),
                reason: format!("{error:?}"),
            })?;
        Ok(Self {
            topic,
            action,
            active: None,
            hold: None,
            goals: GoalBook::default(),
            warnings: RateLimiter::new(Duration::from_secs(1)),
            accepted: 0,
            rejected: 0,
        })
    }

    /// Whether a trajectory runs or its last point is held.
    pub fn is_busy(&self) -> bool {
        self.active.is_some() || self.hold.is_some()
    }

    /// Takes the trajectories and goals that arrived: each valid one replaces the running one;
    /// with `refusal` (e.g. torque is off) every one is refused with that reason. `now`: the
    /// node's clock (s); `actual`: where the arm is (the start of the first segment), read only
    /// when a trajectory arrives (this runs on the control loop's hot path).
    pub fn take_new(
        &mut self,
        now: f64,
        actual: &dyn Fn() -> JointPositions,
        limits: &[JointLimit; JOINT_COUNT],
        refusal: Option<&str>,
    ) {
        loop {
            match self.topic.take() {
                Ok(Some((message, _))) => {
                    let started = match refusal {
                        Some(reason) => Err(invalid_goal(reason)),
                        None => start(&message, &[], &[], 0.0, now, &actual(), limits),
                    };
                    match started {
                        Ok(follower) => self.begin(follower, None, now, "topic"),
                        Err(refused) => self.refuse(&refused.error_string),
                    }
                }
                Ok(None) => break,
                Err(error) => self.refuse(&format!("undecodable trajectory: {error:?}")),
            }
        }
        self.take_goals(now, actual, limits, refusal);
        self.serve_cancels();
        self.serve_result_requests();
    }

    /// A direct command (/joint_commands or the array topic), a reset, a torque change or a
    /// fault ends the trajectory (a goal is aborted with `why`), and the hold of the last one.
    pub fn preempt(&mut self, why: &str) {
        self.hold = None;
        if let Some(active) = self.active.take() {
            tracing::info!("trajectory preempted: {why}");
            if let Some(goal) = active.goal {
                self.end(goal, GoalStatusEnum::Aborted, Outcome::INVALID_GOAL, why);
            }
        }
    }

    /// The targets of the running trajectory at `now`, or the held last point of the one before.
    pub fn targets(&self, now: f64) -> Option<PartialTargets> {
        match (&self.active, &self.hold) {
            (Some(active), _) => active.follower.targets(now),
            (None, Some(hold)) => Some(hold.targets),
            (None, None) => None,
        }
    }

    /// After a control period: the goal's feedback, its tolerances, and its end; the end of a hold.
    pub fn after_period(&mut self, now: f64, actual: &JointPositions, velocities: &[f64]) {
        if let Some(hold) = &self.hold {
            let arrived = (0..JOINT_COUNT).all(|joint| {
                hold.targets
                    .get(joint)
                    .is_none_or(|target| (actual[joint] - target).abs() < ARRIVED)
            });
            if arrived || now >= hold.until {
                self.hold = None;
            }
        }
        let Some(active) = self.active.as_mut() else {
            return;
        };
        let progress = active.follower.progress(now, actual);
        if let Some(goal) = active.goal {
            if now >= active.next_feedback {
                active.next_feedback = now + FEEDBACK_PERIOD;
                let feedback = feedback(&active.follower, now, actual, velocities);
                if let Err(error) = self.action.send_feedback(goal.id, feedback) {
                    tracing::debug!(?error, "cannot send trajectory feedback");
                }
            }
        }
        let (status, code, message) = match progress {
            Progress::Running => return,
            Progress::Succeeded => (
                GoalStatusEnum::Succeeded,
                Outcome::SUCCESSFUL,
                String::new(),
            ),
            Progress::PathToleranceViolated(message) => (
                GoalStatusEnum::Aborted,
                Outcome::PATH_TOLERANCE_VIOLATED,
                message,
            ),
            Progress::GoalToleranceViolated(message) => (
                GoalStatusEnum::Aborted,
                Outcome::GOAL_TOLERANCE_VIOLATED,
                message,
            ),
        };
        let Some(ended) = self.active.take() else {
            return;
        };
        if status == GoalStatusEnum::Succeeded {
            tracing::debug!("trajectory done");
            self.hold = Some(Hold {
                targets: ended.follower.trajectory().final_targets(),
                until: now + HOLD_SECONDS,
            });
        } else {
            tracing::warn!("trajectory aborted: {message}");
        }
        if let Some(goal) = ended.goal {
            self.end(goal, status, code, &message);
        }
    }

    fn take_goals(
        &mut self,
        now: f64,
        actual: &dyn Fn() -> JointPositions,
        limits: &[JointLimit; JOINT_COUNT],
        refusal: Option<&str>,
    ) {
        loop {
            let (request, goal_request) = match self.action.receive_goal() {
                Ok(Some(received)) => received,
                Ok(None) => break,
                Err(error) => {
                    self.refuse(&format!("undecodable goal: {error:?}"));
                    continue;
                }
            };
            let record = GoalRecord {
                id: goal_request.goal_id,
                accepted: AcceptedAt::now(),
            };
            let response = SendGoalResponse {
                accepted: true,
                stamp: record.accepted,
            };
            if let Err(error) = self.action.send_goal_response(request, response) {
                tracing::warn!(?error, "cannot answer a trajectory goal");
                continue;
            }
            let goal = goal_request.goal;
            let started = if let Some(reason) = refusal {
                Err(invalid_goal(reason))
            } else if !goal.multi_dof_trajectory.joint_names.is_empty() {
                Err(Outcome {
                    error_code: Outcome::INVALID_JOINTS,
                    error_string: "this arm has no multi-DOF joints".to_owned(),
                })
            } else {
                let positions = |entries: &[so101_msgs::control_msgs::JointTolerance]| {
                    entries
                        .iter()
                        .map(|entry| (entry.name.clone(), entry.position))
                        .collect::<Vec<_>>()
                };
                start(
                    &goal.trajectory,
                    &positions(&goal.path_tolerance),
                    &positions(&goal.goal_tolerance),
                    goal.goal_time_tolerance.as_secs_f64(),
                    now,
                    &actual(),
                    limits,
                )
            };
            match started {
                Ok(follower) => self.begin(follower, Some(record), now, "goal"),
                Err(refused) => {
                    self.refuse(&refused.error_string);
                    self.end(
                        record,
                        GoalStatusEnum::Aborted,
                        refused.error_code,
                        &refused.error_string,
                    );
                }
            }
        }
    }

    fn begin(&mut self, follower: Follower, goal: Option<GoalRecord>, now: f64, from: &str) {
        self.preempt(&format!("a newer trajectory arrived ({from})"));
        self.accepted += 1;
        tracing::info!(
            from,
            joints = follower.trajectory().joints().len(),
            seconds = follower.trajectory().duration(),
            "trajectory started"
        );
        if let Some(goal) = goal {
            self.goals.start(goal);
        }
        self.active = Some(Active {
            follower,
            goal,
            next_feedback: now,
        });
        self.publish_statuses();
    }

    fn refuse(&mut self, reason: &str) {
        self.rejected += 1;
        if let Some(suppressed) = self.warnings.check(Instant::now()) {
            tracing::warn!(suppressed, "trajectory refused: {reason}");
        }
    }

    /// Ends a goal: its status, its result (to waiting and later result requests).
    fn end(&mut self, goal: GoalRecord, status: GoalStatusEnum, code: i32, message: &str) {
        self.goals.end(goal, status, code, message);
        self.publish_statuses();
        self.serve_result_requests();
    }

    fn serve_cancels(&mut self) {
        while let Ok(Some((request, cancel))) = self.action.receive_cancel_request() {
            let Some(goal_info) = cancel_goal_info(&cancel) else {
                tracing::warn!("cannot read a cancel request");
                continue;
            };
            let (response, cancel_running) = self.goals.cancel(&goal_info);
            if cancel_running {
                if let Some(goal) = self.active.take().and_then(|active| active.goal) {
                    tracing::info!("trajectory goal canceled");
                    self.end(
                        goal,
                        GoalStatusEnum::Canceled,
                        Outcome::SUCCESSFUL,
                        "canceled",
                    );
                }
            }
            if let Err(error) = self.action.send_cancel_response(request, response) {
                tracing::warn!(?error, "cannot answer a cancel request");
            }
        }
    }

    /// Takes the result requests and answers those whose goal has ended (or is unknown).
    fn serve_result_requests(&mut self) {
        while let Ok(Some((request, asked))) = self.action.receive_result_request() {
            self.goals.ask_result(request, asked.goal_id);
        }
        for (request, response) in self.goals.answerable() {
            if let Err(error) = self.action.send_result(request, response) {
                tracing::warn!(?error, "cannot answer a result request");
            }
        }
    }

    fn publish_statuses(&mut self) {
        if let Err(error) = self.action.send_goal_statuses(self.goals.statuses()) {
            tracing::debug!(?error, "cannot publish the goal statuses");
        }
    }
}

/// The goal a cancel request names: ros2-client keeps the field private, so it is read back
/// through its serde form.
fn cancel_goal_info(request: &ros2_client::action::CancelGoalRequest) -> Option<GoalInfo> {
    #[derive(serde::Deserialize)]
    struct Named {
        goal_info: GoalInfo,
    }
    let value = serde_json::to_value(request).ok()?;
    serde_json::from_value::<Named>(value)
        .ok()
        .map(|named| named.goal_info)
}

fn invalid_goal(reason: &str) -> Outcome {
    Outcome {
        error_code: Outcome::INVALID_GOAL,
        error_string: reason.to_owned(),
    }
}

/// A follower for `message`, or the result that refuses it. A zero stamp starts it now, a later
/// one then (at most [`START_HORIZON`] ahead); one whose end lies in the past is refused.
fn start(
    message: &JointTrajectory,
    path_tolerance: &[(String, f64)],
    goal_tolerance: &[(String, f64)],
    goal_time_tolerance: f64,
    now: f64,
    actual: &JointPositions,
    limits: &[JointLimit; JOINT_COUNT],
) -> Result<Follower, Outcome> {
    let invalid = |error: TrajectoryError| Outcome {
        error_code: match error {
            TrajectoryError::UnknownJoint(_)
            | TrajectoryError::DuplicateJoint(_)
            | TrajectoryError::NoJoints => Outcome::INVALID_JOINTS,
            _ => Outcome::INVALID_GOAL,
        },
        error_string: error.to_string(),
    };
    let points: Vec<PointInput> = message
        .points
        .iter()
        .map(|point| PointInput {
            time_from_start: point.time_from_start.as_secs_f64(),
            positions: point.positions.clone(),
            velocities: point.velocities.clone(),
        })
        .collect();
    let trajectory = Trajectory::new(&message.joint_names, &points, limits).map_err(invalid)?;
    let tolerances =
        Tolerances::new(path_tolerance, goal_tolerance, goal_time_tolerance).map_err(invalid)?;
    let stamp = message.header.stamp;
    let started = if stamp == Time::default() {
        now
    } else {
        stamp.as_secs_f64()
    };
    if started + trajectory.duration() < now {
        return Err(Outcome {
            error_code: Outcome::OLD_HEADER_TIMESTAMP,
            error_string: format!(
                "the trajectory starts at {started:.3} s and ends before now ({now:.3} s)"
            ),
        });
    }
    if started > now + START_HORIZON {
        return Err(invalid_goal(&format!(
            "header.stamp {started:.3} s is more than {START_HORIZON} s after now ({now:.3} s; \
             the node's clock: sim time for the sim, wall time for the driver)"
        )));
    }
    Ok(Follower::new(trajectory, started, *actual, tolerances))
}

fn feedback(
    follower: &Follower,
    now: f64,
    actual: &JointPositions,
    velocities: &[f64],
) -> Feedback {
    let joints = follower.trajectory().joints();
    let (desired, desired_velocities) = follower.desired(now);
    let actual_positions: Vec<f64> = joints.iter().map(|&joint| actual[joint]).collect();
    let actual_velocities: Vec<f64> = joints
        .iter()
        .map(|&joint| velocities.get(joint).copied().unwrap_or(0.0))
        .collect();
    let point = |positions: Vec<f64>, velocities: Vec<f64>| JointTrajectoryPoint {
        positions,
        velocities,
        ..JointTrajectoryPoint::default()
    };
    let difference = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(a, b)| a - b).collect();
    Feedback {
        header: Header {
            stamp: Time::from_secs_f64(now),
            frame_id: String::new(),
        },
        joint_names: joints
            .iter()
            .map(|&joint| JOINT_NAMES[joint].to_owned())
            .collect(),
        error: point(
            difference(&desired, &actual_positions),
            difference(&desired_velocities, &actual_velocities),
        ),
        desired: point(desired, desired_velocities),
        actual: point(actual_positions, actual_velocities),
        ..Feedback::default()
    }
}
