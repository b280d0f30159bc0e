//! A leader arm: the positions on /leader/joint_states (so101_feetech_driver --leader) become the
//! targets. A leader that falls silent (unplugged, driver stopped) holds the follower where it is,
//! and following resumes with its next message.

use std::time::{Duration, Instant};

use ros2_client::Subscription;
use so101_core::{
    command::targets_from_joint_state,
    robot::{JointPositions, JOINT_LIMITS},
    ros::{node::NodeError, qos, rate_limit::RateLimiter, RosNode},
};
use so101_msgs::sensor_msgs::JointState;

use super::{Reading, Request, Source, Tick};

pub struct Leader {
    subscription: Subscription<JointState>,
    positions: Option<JointPositions>,
    last_message: Option<Instant>,
    timeout: Duration,
    following: bool,
    bad_messages: RateLimiter,
}

impl Leader {
    /// Subscribes `topic` (default /leader/joint_states, in the node's namespace).
    pub fn subscribe(
        node: &mut RosNode,
        topic: &str,
        timeout: Duration,
    ) -> Result<Self, NodeError> {
        Ok(Self {
            subscription: node.subscription(topic, qos::default_topic())?,
            positions: None,
            last_message: None,
            timeout,
            following: false,
            bad_messages: RateLimiter::new(Duration::from_secs(5)),
        })
    }
}

impl Source for Leader {
    fn read(&mut self, _tick: &Tick) -> Reading {
        let now = Instant::now();
        while let Ok(Some((message, _))) = self.subscription.take() {
            match targets_from_joint_state(&message.name, &message.position) {
                Ok(targets) => {
                    // Joints a partial message does not name keep their last position.
                    let mut positions = self.positions.unwrap_or([0.0; 6]);
                    if self.positions.is_none() && (0..6).any(|joint| targets.get(joint).is_none())
                    {
                        continue; // the first message must give every joint
                    }
                    targets.apply_clamped(&mut positions, &JOINT_LIMITS);
                    self.positions = Some(positions);
                    self.last_message = Some(now);
                }
                Err(error) => {
                    if let Some(suppressed) = self.bad_messages.check(now) {
                        tracing::warn!(%error, suppressed, "ignoring a bad leader message");
                    }
                }
            }
        }
        let fresh = self
            .last_message
            .is_some_and(|last| now.duration_since(last) <= self.timeout);
        match (fresh, self.positions) {
            (true, Some(positions)) => {
                if !self.following {
                    tracing::info!("following the leader arm");
                    self.following = true;
                }
                Reading {
                    request: Request::Targets(positions),
                    controls: Vec::new(),
                }
            }
            _ => {
                if self.following {
                    tracing::warn!("the leader arm went silent: holding the arm where it is");
                    self.following = false;
                }
                Reading::lost()
            }
        }
    }
}
