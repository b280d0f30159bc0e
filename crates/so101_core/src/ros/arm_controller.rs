//! The arm's trajectory interface, as ros2_control's joint_trajectory_controller named
//! `arm_controller` offers it: trajectory_msgs/JointTrajectory on `arm_controller/joint_trajectory`
//! and the action control_msgs/action/FollowJointTrajectory on
//! `arm_controller/follow_joint_trajectory` (what MoveIt's controller manager sends), shared by
//! the simulation and the driver. The node polls it once per control period, in its own clock
//! (sim time or wall time, seconds; header stamps are read in it):
//! [`ArmController::take_new`], [`ArmController::targets`], then [`ArmController::after_period`].
//!
//! One trajectory runs at a time: a newer one (topic or goal) or any direct command preempts it.
//! Once it has ended its last point stays the target (as joint_trajectory_controller holds it),
//! until the next trajectory, a direct command or [`ArmController::preempt`].
//! A goal that cannot be executed is accepted and aborted at once with the reason in its result's
//! error_string, so the client learns why. A cancel request cancels the running goal.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use ros2_client::{
    action::{
        ActionServer, ActionServerQosPolicies, GetResultResponse, GoalId, GoalInfo,
        SendGoalResponse,
    },
    action_msgs::{
        CancelGoalResponse, CancelGoalResponseEnum, GoalStatus, GoalStatusArray, GoalStatusEnum,
    },
    RmwRequestId, ServiceMapping, Subscription,
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

type Server = ActionServer<Goal, Outcome, Feedback>;
type AcceptedAt = ros2_client::builtin_interfaces::Time;

/// Seconds of the node's clock between two feedback messages of a goal.
const FEEDBACK_PERIOD: f64 = 0.05;
/// Ended goals remembered for late result requests.
const ENDED_KEPT: usize = 16;

/// A goal and when it was accepted (wall time, in ros2-client's action types).
#[derive(Debug, Clone, Copy)]
struct GoalRecord {
    id: GoalId,
    accepted: AcceptedAt,
}

struct Active {
    follower: Follower,
    goal: Option<GoalRecord>,
    next_feedback: f64,
}

struct Ended {
    goal: GoalRecord,
    status: GoalStatusEnum,
    outcome: Outcome,
}

/// The topic, the action server and the trajectory being followed.
pub struct ArmController {
    topic: Subscription<JointTrajectory>,
    action: Server,
    active: Option<Active>,
    /// The last point of the trajectory that ended, held as the target.
    hold: Option<PartialTargets>,
    /// Result requests waiting for their goal to end.
    waiting: Vec<(RmwRequestId, GoalId)>,
    ended: VecDeque<Ended>,
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
            waiting: Vec::new(),
            ended: VecDeque::new(),
            warnings: RateLimiter::new(Duration::from_secs(1)),
            accepted: 0,
            rejected: 0,
        })
    }

    /// Whether a trajectory is being followed.
    pub fn is_active(&self) -> bool {
        self.active.is_some()
    }

    /// Takes the trajectories and goals that arrived: each valid one replaces the running one.
    /// `now`: the node's clock (s); `actual`: where the arm is (the start of the first segment).
    pub fn take_new(
        &mut self,
        now: f64,
        actual: &JointPositions,
        limits: &[JointLimit; JOINT_COUNT],
    ) {
        loop {
            match self.topic.take() {
                Ok(Some((message, _))) => {
                    match start(&message, &[], &[], 0.0, now, actual, limits) {
                        Ok(follower) => self.begin(follower, None, now, "topic"),
                        Err(refusal) => self.refuse(&refusal.error_string),
                    }
                }
                Ok(None) => break,
                Err(error) => self.refuse(&format!("undecodable trajectory: {error:?}")),
            }
        }
        self.take_goals(now, actual, limits);
        self.serve_cancels();
        self.serve_result_requests();
    }

    /// A direct command (/joint_commands or the array topic), a reset or a torque change ends the
    /// trajectory, and the hold of the last one.
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
        match &self.active {
            Some(active) => active.follower.targets(now),
            None => self.hold,
        }
    }

    /// After a control period: the goal's feedback, its tolerances, and its end.
    pub fn after_period(&mut self, now: f64, actual: &JointPositions, velocities: &[f64]) {
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
        let ended = self.active.take();
        let goal = ended.as_ref().and_then(|active| active.goal);
        if status == GoalStatusEnum::Succeeded {
            self.hold = ended.map(|active| {
                let trajectory = active.follower.trajectory();
                trajectory.targets(&[0.0; JOINT_COUNT], trajectory.duration())
            });
        }
        if status == GoalStatusEnum::Succeeded {
            tracing::debug!("trajectory done");
        } else {
            tracing::warn!("trajectory aborted: {message}");
        }
        if let Some(goal) = goal {
            self.end(goal, status, code, &message);
        }
    }

    fn take_goals(
        &mut self,
        now: f64,
        actual: &JointPositions,
        limits: &[JointLimit; JOINT_COUNT],
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
            let tolerance = |entries: &[so101_msgs::control_msgs::JointTolerance]| {
                entries
                    .iter()
                    .map(|entry| (entry.name.clone(), entry.position))
                    .collect::<Vec<_>>()
            };
            let started = if goal.multi_dof_trajectory.joint_names.is_empty() {
                start(
                    &goal.trajectory,
                    &tolerance(&goal.path_tolerance),
                    &tolerance(&goal.goal_tolerance),
                    goal.goal_time_tolerance.as_secs_f64(),
                    now,
                    actual,
                    limits,
                )
            } else {
                Err(Outcome {
                    error_code: Outcome::INVALID_JOINTS,
                    error_string: "this arm has no multi-DOF joints".to_owned(),
                })
            };
            match started {
                Ok(follower) => self.begin(follower, Some(record), now, "goal"),
                Err(refusal) => {
                    self.refuse(&refusal.error_string);
                    self.end(
                        record,
                        GoalStatusEnum::Aborted,
                        refusal.error_code,
                        &refusal.error_string,
                    );
                }
            }
        }
    }

    fn begin(&mut self, follower: Follower, goal: Option<GoalRecord>, now: f64, from: &str) {
        if self.active.is_some() {
            self.preempt(&format!("a newer trajectory arrived ({from})"));
        }
        self.accepted += 1;
        tracing::info!(
            from,
            joints = follower.trajectory().joints().len(),
            seconds = follower.trajectory().duration(),
            "trajectory started"
        );
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
        let outcome = Outcome {
            error_code: code,
            error_string: message.to_owned(),
        };
        if self.ended.len() == ENDED_KEPT {
            self.ended.pop_front();
        }
        self.ended.push_back(Ended {
            goal,
            status,
            outcome,
        });
        self.publish_statuses();
        self.serve_result_requests();
    }

    fn serve_cancels(&mut self) {
        while let Ok(Some((request, _))) = self.action.receive_cancel_request() {
            // One goal runs at a time: a cancel request cancels it, whichever goal it names.
            let goal = self.active.as_ref().and_then(|active| active.goal);
            let response = match goal {
                Some(goal) => {
                    self.active = None;
                    self.end(
                        goal,
                        GoalStatusEnum::Canceled,
                        Outcome::SUCCESSFUL,
                        "canceled",
                    );
                    CancelGoalResponse {
                        return_code: CancelGoalResponseEnum::None,
                        goals_canceling: vec![GoalInfo {
                            goal_id: goal.id,
                            stamp: goal.accepted,
                        }],
                    }
                }
                None => CancelGoalResponse {
                    return_code: CancelGoalResponseEnum::UnknownGoal,
                    goals_canceling: Vec::new(),
                },
            };
            if let Err(error) = self.action.send_cancel_response(request, response) {
                tracing::warn!(?error, "cannot answer a cancel request");
            }
        }
    }

    /// Answers the result requests whose goal has ended (at once for an unknown goal).
    fn serve_result_requests(&mut self) {
        while let Ok(Some((request, asked))) = self.action.receive_result_request() {
            self.waiting.push((request, asked.goal_id));
        }
        let running = self
            .active
            .as_ref()
            .and_then(|active| active.goal)
            .map(|goal| goal.id);
        let mut still_waiting = Vec::new();
        for (request, goal_id) in std::mem::take(&mut self.waiting) {
            let ended = self.ended.iter().find(|ended| ended.goal.id == goal_id);
            let response = match ended {
                Some(ended) => GetResultResponse {
                    status: ended.status,
                    result: ended.outcome.clone(),
                },
                None if running == Some(goal_id) => {
                    still_waiting.push((request, goal_id));
                    continue;
                }
                None => GetResultResponse {
                    status: GoalStatusEnum::Unknown,
                    result: Outcome::default(),
                },
            };
            if let Err(error) = self.action.send_result(request, response) {
                tracing::warn!(?error, "cannot answer a result request");
            }
        }
        self.waiting = still_waiting;
    }

    fn publish_statuses(&mut self) {
        let mut status_list: Vec<GoalStatus> = self
            .ended
            .iter()
            .map(|ended| status(ended.goal, ended.status))
            .collect();
        if let Some(goal) = self.active.as_ref().and_then(|active| active.goal) {
            status_list.push(status(goal, GoalStatusEnum::Executing));
        }
        if let Err(error) = self
            .action
            .send_goal_statuses(GoalStatusArray { status_list })
        {
            tracing::debug!(?error, "cannot publish the goal statuses");
        }
    }
}

fn status(goal: GoalRecord, status: GoalStatusEnum) -> GoalStatus {
    GoalStatus {
        goal_info: GoalInfo {
            goal_id: goal.id,
            stamp: goal.accepted,
        },
        status,
    }
}

/// A follower for `message`, or the result that refuses it. A zero stamp starts it now, a later
/// one then; one so old that the whole trajectory lies in the past is refused.
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
    let elapsed = so101_msgs::builtin_interfaces::Duration::default();
    let point = |positions: Vec<f64>, velocities: Vec<f64>| JointTrajectoryPoint {
        positions,
        velocities,
        time_from_start: elapsed,
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
