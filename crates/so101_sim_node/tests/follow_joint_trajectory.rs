//! control_msgs/action/FollowJointTrajectory end to end from a Rust action client (ros2-client)
//! against the sim node's binary: a goal accepted, feedback while it runs, a SUCCESSFUL result,
//! the arm where the goal ends; a goal naming an unknown joint aborted with INVALID_JOINTS and the
//! reason. Opens DDS participants: runs only inside scripts/isolated (scripts/test.sh does that).

use std::{
    process::{Child, Command, Stdio},
    time::{Duration, Instant},
};

use ros2_client::{
    action::{ActionClient, ActionClientQosPolicies},
    action_msgs::{CancelGoalResponseEnum, GoalStatusEnum},
    ServiceMapping,
};
use so101_core::{
    contract::{actions, topics},
    ros::{context::only_loopback, qos, NodeArgs, RosNode},
};
use so101_msgs::{
    builtin_interfaces::Duration as RosDuration,
    control_msgs::{
        FollowJointTrajectory, FollowJointTrajectoryFeedback as Feedback,
        FollowJointTrajectoryGoal as Goal, FollowJointTrajectoryResult as Outcome, JointTolerance,
    },
    sensor_msgs::JointState,
    trajectory_msgs::{JointTrajectory, JointTrajectoryPoint},
};

type Client = ActionClient<Goal, Outcome, Feedback>;

/// The sim node, stopped with SIGINT when dropped.
struct Sim(Child);

impl Sim {
    fn start(namespace: &str) -> Self {
        let log = std::fs::File::create(std::env::temp_dir().join(format!("{namespace}.log")))
            .expect("a log file");
        let child = Command::new(env!("CARGO_BIN_EXE_so101_sim_node"))
            .args([
                "--lite",
                "--cameras",
                "none",
                "--speed",
                "4",
                "--namespace",
                namespace,
            ])
            .stdout(Stdio::null())
            .stderr(log)
            .spawn()
            .expect("the sim node starts");
        Self(child)
    }
}

impl Drop for Sim {
    fn drop(&mut self) {
        let _ = Command::new("kill")
            .args(["-INT", &self.0.id().to_string()])
            .status();
        let _ = self.0.wait();
    }
}

/// A sim node under `namespace` and a client node beside it (inside scripts/isolated only).
fn connect(namespace: &str) -> (Sim, RosNode) {
    assert!(only_loopback(), "run inside scripts/isolated");
    let sim = Sim::start(namespace);
    let node = RosNode::start(
        "fjt_client",
        &NodeArgs {
            namespace: Some(namespace.into()),
        },
    )
    .expect("a node");
    (sim, node)
}

fn client(node: &mut RosNode) -> Client {
    let name = node
        .names()
        .name(actions::FOLLOW_JOINT_TRAJECTORY)
        .expect("a valid name");
    node.node_mut()
        .create_action_client(
            ServiceMapping::Enhanced,
            &name,
            &FollowJointTrajectory::action_type_name(),
            ActionClientQosPolicies {
                goal_service: qos::service(),
                result_service: qos::service(),
                cancel_service: qos::service(),
                feedback_subscription: qos::reliable(100),
                status_subscription: qos::latched(),
            },
        )
        .expect("an action client")
}

fn wait_for<T>(what: &str, timeout: Duration, mut poll: impl FnMut() -> Option<T>) -> T {
    let deadline = Instant::now() + timeout;
    loop {
        if let Some(value) = poll() {
            return value;
        }
        assert!(Instant::now() < deadline, "timeout waiting for {what}");
        std::thread::sleep(Duration::from_millis(5));
    }
}

fn goal(names: &[&str], positions: &[f64], seconds: f64) -> Goal {
    Goal {
        trajectory: JointTrajectory {
            joint_names: names.iter().map(|name| name.to_string()).collect(),
            points: vec![JointTrajectoryPoint {
                positions: positions.to_vec(),
                time_from_start: RosDuration::from_secs_f64(seconds),
                ..JointTrajectoryPoint::default()
            }],
            ..JointTrajectory::default()
        },
        ..Goal::default()
    }
}

/// Sends `goal` until it is accepted (a request sent before discovery matched the server is
/// lost: it is sent again, as a new goal, every second); returns the accepted goal's id.
fn send(client: &Client, goal: Goal) -> ros2_client::action::GoalId {
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        assert!(
            Instant::now() < deadline,
            "the action server never answered"
        );
        let (request, goal_id) = client.send_goal(goal.clone()).expect("the goal is sent");
        let answered = Instant::now() + Duration::from_secs(1);
        while Instant::now() < answered {
            match client.receive_goal_response(request) {
                Ok(Some(response)) => {
                    assert!(response.accepted, "the goal was not accepted");
                    return goal_id;
                }
                Ok(None) => std::thread::sleep(Duration::from_millis(5)),
                Err(error) => panic!("bad goal response: {error:?}"),
            }
        }
    }
}

fn result(
    client: &Client,
    goal_id: ros2_client::action::GoalId,
    feedback: &mut Vec<Feedback>,
) -> (GoalStatusEnum, Outcome) {
    let request = client
        .request_result(goal_id)
        .expect("the result is asked for");
    wait_for("the result", Duration::from_secs(20), || {
        while let Ok(Some(message)) = client.receive_feedback(goal_id) {
            feedback.push(message);
        }
        client.receive_result(request).ok().flatten()
    })
}

#[test]
fn a_goal_runs_to_success_with_feedback() {
    let (_sim, mut node) = connect("fjt_success");
    let states = node
        .subscription::<JointState>(topics::JOINT_STATES, qos::reliable(100))
        .expect("a subscription");
    let client = client(&mut node);
    let target = [0.4, -0.3, 0.5];
    let mut wanted = goal(
        &["shoulder_pan", "shoulder_lift", "elbow_flex"],
        &target,
        1.5,
    );
    wanted.goal_tolerance = ["shoulder_pan", "shoulder_lift", "elbow_flex"]
        .iter()
        .map(|name| JointTolerance {
            name: name.to_string(),
            position: 0.05,
            ..JointTolerance::default()
        })
        .collect();
    let goal_id = send(&client, wanted);
    let mut feedback = Vec::new();
    let (status, outcome) = result(&client, goal_id, &mut feedback);
    assert_eq!(status, GoalStatusEnum::Succeeded, "{outcome:?}");
    assert_eq!(outcome.error_code, Outcome::SUCCESSFUL);
    assert!(feedback.len() >= 5, "{} feedback messages", feedback.len());
    let last = feedback.last().expect("feedback");
    assert_eq!(
        last.joint_names,
        ["shoulder_pan", "shoulder_lift", "elbow_flex"]
    );
    assert_eq!(last.desired.positions.len(), 3);
    assert_eq!(last.actual.positions.len(), 3);
    let mut latest = None;
    while let Ok(Some((message, _))) = states.take() {
        latest = Some(message);
    }
    let latest = latest.expect("joint states arrived");
    for (index, name) in ["shoulder_pan", "shoulder_lift", "elbow_flex"]
        .iter()
        .enumerate()
    {
        let at = latest.name.iter().position(|n| n == name).expect("joint");
        assert!(
            (latest.position[at] - target[index]).abs() < 0.05,
            "{name} at {} for {}",
            latest.position[at],
            target[index]
        );
    }
}

#[test]
fn a_goal_naming_an_unknown_joint_is_aborted_with_the_reason() {
    let (_sim, mut node) = connect("fjt_invalid");
    let client = client(&mut node);
    let goal_id = send(&client, goal(&["elbow"], &[0.1], 1.0));
    let (status, outcome) = result(&client, goal_id, &mut Vec::new());
    assert_eq!(status, GoalStatusEnum::Aborted);
    assert_eq!(outcome.error_code, Outcome::INVALID_JOINTS);
    assert!(
        outcome
            .error_string
            .contains("unknown joint name \"elbow\""),
        "{outcome:?}"
    );
}

#[test]
fn a_newer_goal_preempts_and_a_cancel_stops_the_running_one() {
    let (_sim, mut node) = connect("fjt_preempt");
    let client = client(&mut node);
    let first = send(&client, goal(&["shoulder_pan"], &[0.8], 20.0));
    let second = send(&client, goal(&["shoulder_pan"], &[-0.8], 20.0));
    let (status, outcome) = result(&client, first, &mut Vec::new());
    assert_eq!(status, GoalStatusEnum::Aborted);
    assert!(
        outcome.error_string.contains("newer trajectory"),
        "{outcome:?}"
    );
    // Canceling the ended goal leaves the running one alone.
    let request = client.cancel_goal(first).expect("the cancel is sent");
    let response = wait_for("the cancel response", Duration::from_secs(10), || {
        client.receive_cancel_response(request).ok().flatten()
    });
    assert_eq!(response.return_code, CancelGoalResponseEnum::GoalTerminated);
    assert!(response.goals_canceling.is_empty());
    let request = client.cancel_goal(second).expect("the cancel is sent");
    let response = wait_for("the cancel response", Duration::from_secs(10), || {
        client.receive_cancel_response(request).ok().flatten()
    });
    assert_eq!(response.goals_canceling.len(), 1);
    let (status, _) = result(&client, second, &mut Vec::new());
    assert_eq!(status, GoalStatusEnum::Canceled);
}
