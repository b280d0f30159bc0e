//! The two command topics of the contract (/joint_commands and
//! /forward_position_controller/commands), validated on intake and counted, shared by every node
//! that moves an arm (simulation and driver).

use crate::contract::topics;
use std::time::{Duration, Instant};

use ros2_client::Subscription;
use so101_msgs::{sensor_msgs::JointState, std_msgs::Float64MultiArray};

use crate::{
    command::{targets_from_array, targets_from_joint_state, CommandError, PartialTargets},
    ros::{node::NodeError, qos, rate_limit::RateLimiter, RosNode},
};

/// The command subscriptions and the rules for accepting what arrives on them.
pub struct CommandInbox {
    joint_commands: Subscription<JointState>,
    array_commands: Subscription<Float64MultiArray>,
    pub tally: CommandTally,
}

/// Counts of accepted and rejected commands, and the limiter of rejection warnings.
pub struct CommandTally {
    warnings: RateLimiter,
    pub accepted: u64,
    pub rejected: u64,
}

impl CommandInbox {
    pub fn subscribe(node: &mut RosNode) -> Result<Self, NodeError> {
        Ok(Self {
            joint_commands: node
                .subscription(topics::JOINT_COMMANDS, qos::command_subscription())?,
            array_commands: node.subscription(
                topics::FORWARD_POSITION_COMMANDS,
                qos::command_subscription(),
            )?,
            tally: CommandTally {
                warnings: RateLimiter::new(Duration::from_secs(1)),
                accepted: 0,
                rejected: 0,
            },
        })
    }

    /// Every valid command that arrived since the last call: /joint_commands in arrival order, then
    /// the array commands in arrival order.
    pub fn drain(&mut self) -> Vec<PartialTargets> {
        let mut accepted = Vec::new();
        self.tally.drain(
            &self.joint_commands,
            "/joint_commands",
            &mut accepted,
            |message| targets_from_joint_state(&message.name, &message.position),
        );
        self.tally.drain(
            &self.array_commands,
            "/forward_position_controller/commands",
            &mut accepted,
            |message| targets_from_array(&message.data),
        );
        accepted
    }
}

impl CommandTally {
    /// Takes every message waiting on `subscription`, validates it and keeps the valid targets.
    fn drain<M: 'static + serde::de::DeserializeOwned>(
        &mut self,
        subscription: &Subscription<M>,
        topic: &str,
        accepted: &mut Vec<PartialTargets>,
        validate: impl Fn(&M) -> Result<PartialTargets, CommandError>,
    ) {
        loop {
            match subscription.take() {
                Ok(Some((message, _))) => match validate(&message) {
                    Ok(targets) => {
                        self.accepted += 1;
                        accepted.push(targets);
                    }
                    Err(error) => self.reject(topic, &error.to_string()),
                },
                Ok(None) => break,
                Err(error) => self.reject(topic, &format!("undecodable message: {error:?}")),
            }
        }
    }

    fn reject(&mut self, topic: &str, reason: &str) {
        self.rejected += 1;
        if let Some(suppressed) = self.warnings.check(Instant::now()) {
            tracing::warn!(
                topic,
                rejected_total = self.rejected,
                suppressed,
                "command rejected: {reason}"
            );
        }
    }
}
