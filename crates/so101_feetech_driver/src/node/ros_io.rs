//! The driver's ROS side: a publisher thread (so a slow DDS write never delays the bus cycle) and
//! the torque_enable service.

use so101_core::contract::{services, topics};
use std::{
    sync::mpsc::{sync_channel, Receiver, SyncSender, TrySendError},
    thread::JoinHandle,
    time::{Duration, Instant},
};

use ros2_client::{Publisher, RmwRequestId, Server};
use so101_core::ros::{
    node::{spawn_publisher_thread, NodeError},
    qos,
    rate_limit::RateLimiter,
    RosNode,
};
use so101_msgs::{
    diagnostic_msgs::DiagnosticArray,
    sensor_msgs::JointState,
    std_srvs::{SetBool, SetBoolRequest, TriggerResponse},
};

/// Messages queued ahead of the publisher thread; beyond that they are dropped and counted (the
/// bus cycle never waits for DDS).
const QUEUE: usize = 256;

pub enum Output {
    Joints(JointState),
    Diagnostics(DiagnosticArray),
}

pub struct Outputs {
    sender: Option<SyncSender<Output>>,
    thread: Option<JoinHandle<()>>,
    pub dropped: u64,
}

impl Outputs {
    /// Publishes joint states on `joint_topic` (joint_states, or leader/joint_states) and
    /// /diagnostics.
    pub fn start(node: &mut RosNode, joint_topic: &str) -> Result<Self, NodeError> {
        let joints: Publisher<JointState> = node.publisher(joint_topic, qos::default_topic())?;
        let diagnostics: Publisher<DiagnosticArray> =
            node.publisher(topics::DIAGNOSTICS, qos::default_topic())?;
        let (sender, receiver) = sync_channel(QUEUE);
        let thread = spawn_publisher_thread(move || publish(&joints, &diagnostics, &receiver))?;
        Ok(Self {
            sender: Some(sender),
            thread: Some(thread),
            dropped: 0,
        })
    }

    pub fn send(&mut self, output: Output) {
        if let Some(sender) = &self.sender {
            if let Err(TrySendError::Full(_)) = sender.try_send(output) {
                self.dropped += 1;
            }
        }
    }
}

impl Drop for Outputs {
    fn drop(&mut self) {
        self.sender.take();
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

fn publish(
    joints: &Publisher<JointState>,
    diagnostics: &Publisher<DiagnosticArray>,
    outputs: &Receiver<Output>,
) {
    let mut failures = RateLimiter::new(Duration::from_secs(5));
    for output in outputs {
        let error = match output {
            Output::Joints(message) => joints.publish(message).err().map(|e| format!("{e:?}")),
            Output::Diagnostics(message) => {
                diagnostics.publish(message).err().map(|e| format!("{e:?}"))
            }
        };
        if let Some(error) = error {
            if let Some(suppressed) = failures.check(Instant::now()) {
                tracing::warn!(suppressed, %error, "publishing failed");
            }
        }
    }
}

/// torque_enable (std_srvs/SetBool).
pub struct TorqueService {
    server: Server<SetBoolRequest, TriggerResponse>,
}

impl TorqueService {
    pub fn serve(node: &mut RosNode) -> Result<Self, NodeError> {
        Ok(Self {
            server: node.server::<SetBool>(services::TORQUE_ENABLE)?,
        })
    }

    /// The next request: its id and whether it asks for torque on.
    pub fn next(&self) -> Option<(RmwRequestId, bool)> {
        match self.server.receive_request() {
            Ok(Some((id, request))) => Some((id, request.data)),
            Ok(None) => None,
            Err(error) => {
                tracing::warn!(?error, "bad torque_enable request");
                None
            }
        }
    }

    pub fn answer(&self, id: RmwRequestId, success: bool, message: String) {
        if let Err(error) = self
            .server
            .send_response(id, TriggerResponse { success, message })
        {
            tracing::warn!(?error, "cannot answer torque_enable");
        }
    }
}
