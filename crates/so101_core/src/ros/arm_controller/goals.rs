//! The action's goal book, after rcl_action: which goal runs, how the ended ones ended (for the
//! status list and late result requests), which result requests wait, and which goals a cancel
//! request names. No I/O: the controller sends what it decides.

use std::collections::VecDeque;

use ros2_client::{
    action::{GetResultResponse, GoalId, GoalInfo},
    action_msgs::{
        CancelGoalResponse, CancelGoalResponseEnum, GoalStatus, GoalStatusArray, GoalStatusEnum,
    },
    builtin_interfaces::Time,
};
use so101_msgs::control_msgs::FollowJointTrajectoryResult as Outcome;

/// Ended goals remembered for the status list and late result requests.
const ENDED_KEPT: usize = 16;

/// A goal and when it was accepted.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GoalRecord {
    pub id: GoalId,
    pub accepted: Time,
}

#[derive(Debug, Clone)]
struct Ended {
    goal: GoalRecord,
    status: GoalStatusEnum,
    outcome: Outcome,
}

/// The goals of one action server that runs one goal at a time. `R` identifies a result request.
#[derive(Debug)]
pub struct GoalBook<R> {
    running: Option<GoalRecord>,
    ended: VecDeque<Ended>,
    waiting: Vec<(R, GoalId)>,
}

impl<R> Default for GoalBook<R> {
    fn default() -> Self {
        Self {
            running: None,
            ended: VecDeque::new(),
            waiting: Vec::new(),
        }
    }
}

impl<R> GoalBook<R> {
    /// `goal` runs now (the caller has ended the one before).
    pub fn start(&mut self, goal: GoalRecord) {
        self.running = Some(goal);
    }

    /// `goal` ended so; it stops running if it was.
    pub fn end(&mut self, goal: GoalRecord, status: GoalStatusEnum, code: i32, message: &str) {
        if self.running.is_some_and(|running| running.id == goal.id) {
            self.running = None;
        }
        if self.ended.len() == ENDED_KEPT {
            self.ended.pop_front();
        }
        self.ended.push_back(Ended {
            goal,
            status,
            outcome: Outcome {
                error_code: code,
                error_string: message.to_owned(),
            },
        });
    }

    /// rcl's status list: the ended goals, then the running one.
    pub fn statuses(&self) -> GoalStatusArray {
        let status = |goal: GoalRecord, status| GoalStatus {
            goal_info: GoalInfo {
                goal_id: goal.id,
                stamp: goal.accepted,
            },
            status,
        };
        let mut status_list: Vec<GoalStatus> = self
            .ended
            .iter()
            .map(|ended| status(ended.goal, ended.status))
            .collect();
        status_list.extend(
            self.running
                .map(|goal| status(goal, GoalStatusEnum::Executing)),
        );
        GoalStatusArray { status_list }
    }

    /// A result request: it waits while its goal runs.
    pub fn ask_result(&mut self, request: R, goal: GoalId) {
        self.waiting.push((request, goal));
    }

    /// The result requests that can be answered now: their goal ended (its status and result)
    /// or is unknown (STATUS_UNKNOWN, as rcl answers).
    pub fn answerable(&mut self) -> Vec<(R, GetResultResponse<Outcome>)> {
        let running = self.running.map(|goal| goal.id);
        let (waiting, ready): (Vec<_>, Vec<_>) = std::mem::take(&mut self.waiting)
            .into_iter()
            .partition(|(_, goal)| running == Some(*goal));
        self.waiting = waiting;
        ready
            .into_iter()
            .map(|(request, goal)| {
                let response = match self.ended.iter().rev().find(|ended| ended.goal.id == goal) {
                    Some(ended) => GetResultResponse {
                        status: ended.status,
                        result: ended.outcome.clone(),
                    },
                    None => GetResultResponse {
                        status: GoalStatusEnum::Unknown,
                        result: Outcome::default(),
                    },
                };
                (request, response)
            })
            .collect()
    }

    /// rcl_action's cancel rules for `goal_info` (a zero id: every goal accepted at or before its
    /// stamp, all of them for a zero stamp; an id: that goal, and with a stamp also those accepted
    /// before it). Returns the answer and whether the running goal is to be canceled.
    pub fn cancel(&self, goal_info: &GoalInfo) -> (CancelGoalResponse, bool) {
        let zero_id = goal_info.goal_id == GoalId::ZERO;
        let zero_stamp = goal_info.stamp == Time::ZERO;
        let named = |goal: &GoalRecord| {
            (zero_id && zero_stamp)
                || (!zero_id && goal.id == goal_info.goal_id)
                || (!zero_stamp && goal.accepted <= goal_info.stamp)
        };
        match self.running.filter(|goal| named(goal)) {
            Some(goal) => (
                CancelGoalResponse {
                    return_code: CancelGoalResponseEnum::None,
                    goals_canceling: vec![GoalInfo {
                        goal_id: goal.id,
                        stamp: goal.accepted,
                    }],
                },
                true,
            ),
            None => {
                let ended = !zero_id && self.ended.iter().any(|e| e.goal.id == goal_info.goal_id);
                let return_code = if ended {
                    CancelGoalResponseEnum::GoalTerminated
                } else if zero_id {
                    // Nothing to cancel is not an error for "cancel all".
                    CancelGoalResponseEnum::None
                } else {
                    CancelGoalResponseEnum::UnknownGoal
                };
                (
                    CancelGoalResponse {
                        return_code,
                        goals_canceling: Vec::new(),
                    },
                    false,
                )
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn goal(accepted_s: i64) -> GoalRecord {
        GoalRecord {
            id: GoalId::new_random(),
            accepted: Time::from_nanos(accepted_s * 1_000_000_000),
        }
    }

    fn info(id: GoalId, stamp: Time) -> GoalInfo {
        GoalInfo { goal_id: id, stamp }
    }

    #[test]
    fn results_wait_for_their_goal_and_unknown_goals_get_status_unknown() {
        let mut book = GoalBook::default();
        let (first, second) = (goal(1), goal(2));
        book.start(first);
        book.ask_result(1, first.id);
        book.ask_result(2, GoalId::new_random());
        let ready = book.answerable();
        assert_eq!(ready.len(), 1);
        assert_eq!(
            (ready[0].0, ready[0].1.status),
            (2, GoalStatusEnum::Unknown)
        );
        book.end(
            first,
            GoalStatusEnum::Aborted,
            Outcome::INVALID_GOAL,
            "preempted",
        );
        book.start(second);
        let ready = book.answerable();
        assert_eq!(ready[0].0, 1);
        assert_eq!(ready[0].1.status, GoalStatusEnum::Aborted);
        assert_eq!(ready[0].1.result.error_string, "preempted");
        let statuses: Vec<_> = book
            .statuses()
            .status_list
            .iter()
            .map(|s| s.status)
            .collect();
        assert_eq!(
            statuses,
            [GoalStatusEnum::Aborted, GoalStatusEnum::Executing]
        );
    }

    #[test]
    fn a_cancel_names_goals_by_id_or_stamp_as_rcl_does() {
        let mut book: GoalBook<u32> = GoalBook::default();
        let (old, running) = (goal(1), goal(5));
        book.end(old, GoalStatusEnum::Succeeded, Outcome::SUCCESSFUL, "");
        book.start(running);
        let (answer, cancel) = book.cancel(&info(old.id, Time::ZERO));
        assert!(
            !cancel,
            "an ended goal's cancel leaves the running one alone"
        );
        assert_eq!(answer.return_code, CancelGoalResponseEnum::GoalTerminated);
        let (answer, cancel) = book.cancel(&info(GoalId::new_random(), Time::ZERO));
        assert!(!cancel);
        assert_eq!(answer.return_code, CancelGoalResponseEnum::UnknownGoal);
        let (_, cancel) = book.cancel(&info(GoalId::ZERO, Time::from_nanos(2_000_000_000)));
        assert!(!cancel, "accepted after the stamp");
        let (answer, cancel) = book.cancel(&info(GoalId::ZERO, Time::ZERO));
        assert!(cancel && answer.goals_canceling[0].goal_id == running.id);
        let (_, cancel) = book.cancel(&info(running.id, Time::ZERO));
        assert!(cancel);
    }
}
