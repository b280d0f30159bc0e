//! The node's side of the topic contract: the publishers (on their own thread, so publishing never
//! slows the physics) and the two services. Commands come in through so101_core's CommandInbox.

use so101_core::contract::{services, topics};
use std::{
    sync::mpsc::{sync_channel, Receiver, SyncSender},
    thread::JoinHandle,
    time::{Duration, Instant},
};

use ros2_client::{Publisher, Server};
use so101_core::{
    robot::JOINT_NAMES,
    ros::{
        node::{spawn_publisher_thread, NodeError},
        qos,
        rate_limit::RateLimiter,
        RosNode,
    },
};
use so101_msgs::{
    builtin_interfaces::Time,
    diagnostic_msgs::{DiagnosticArray, DiagnosticStatus, KeyValue},
    geometry_msgs::{Point, Pose, PoseStamped, Quaternion},
    rosgraph_msgs::Clock,
    sensor_msgs::JointState,
    std_msgs::{Bool, Float64, Header},
    std_srvs::{Trigger, TriggerRequest, TriggerResponse},
};

use so101_sim::{
    cameras::rig::RigDiagnostics,
    world::{ArmState, CubePose},
};

/// Everything published for one control period.
pub struct Frame {
    pub sim_time: f64,
    pub arm: ArmState,
    pub reward: f64,
    pub success: bool,
    pub cube: CubePose,
    pub diagnostics: Option<NodeDiagnostics>,
    /// Signalled once the frame is on the wire (lockstep answers /sim/step only after that).
    pub published: Option<SyncSender<()>>,
}

/// Counters reported on /diagnostics.
#[derive(Debug, Clone, Default)]
pub struct NodeDiagnostics {
    pub accepted_commands: u64,
    pub rejected_commands: u64,
    pub accepted_trajectories: u64,
    pub rejected_trajectories: u64,
    pub episode: u64,
    pub physics_divergences: u64,
    pub pacing_resyncs: u64,
    pub cameras: Option<RigDiagnostics>,
}

struct Publishers {
    joint_states: Publisher<JointState>,
    clock: Publisher<Clock>,
    reward: Publisher<Float64>,
    success: Publisher<Bool>,
    cube_pose: Publisher<PoseStamped>,
    diagnostics: Publisher<DiagnosticArray>,
}

/// Batches queued ahead of the publisher thread before the physics waits for it (lossless).
const BATCH_QUEUE: usize = 64;
/// Frames are handed over in batches: waking the publisher thread once per control period cost
/// more than 10 % of the physics speed at --speed max.
const MAX_BATCH_FRAMES: usize = 32;
/// Longest a frame waits in a batch before it is handed over.
const MAX_BATCH_DELAY: Duration = Duration::from_millis(1);

/// The publisher thread: frames go in, messages go out.
pub struct FramePublisher {
    sender: Option<SyncSender<Vec<Frame>>>,
    thread: Option<JoinHandle<()>>,
    batch: Vec<Frame>,
    batch_started: Instant,
}

impl FramePublisher {
    pub fn start(node: &mut RosNode) -> Result<Self, NodeError> {
        let topic = qos::default_topic();
        let publishers = Publishers {
            joint_states: node.publisher(topics::JOINT_STATES, topic.clone())?,
            clock: node.publisher(topics::CLOCK, topic.clone())?,
            reward: node.publisher(topics::TASK_REWARD, topic.clone())?,
            success: node.publisher(topics::TASK_SUCCESS, topic.clone())?,
            cube_pose: node.publisher(topics::CUBE_POSE, topic.clone())?,
            diagnostics: node.publisher(topics::DIAGNOSTICS, topic)?,
        };
        let (sender, receiver) = sync_channel(BATCH_QUEUE);
        let thread = spawn_publisher_thread(move || publish_frames(&publishers, &receiver))?;
        Ok(Self {
            sender: Some(sender),
            thread: Some(thread),
            batch: Vec::with_capacity(MAX_BATCH_FRAMES),
            batch_started: Instant::now(),
        })
    }

    /// Queues a frame. It goes out at the latest after [`MAX_BATCH_DELAY`] of wall time, at once
    /// when it carries a `published` signal, or at the next [`FramePublisher::flush`].
    pub fn send(&mut self, frame: Frame) {
        if self.batch.is_empty() {
            self.batch_started = Instant::now();
        }
        let urgent = frame.published.is_some();
        self.batch.push(frame);
        if urgent
            || self.batch.len() >= MAX_BATCH_FRAMES
            || self.batch_started.elapsed() >= MAX_BATCH_DELAY
        {
            self.flush();
        }
    }

    /// Hands every queued frame to the publisher thread; waits when it is a full queue behind.
    pub fn flush(&mut self) {
        if self.batch.is_empty() {
            return;
        }
        let batch = std::mem::replace(&mut self.batch, Vec::with_capacity(MAX_BATCH_FRAMES));
        if let Some(sender) = &self.sender {
            let _ = sender.send(batch);
        }
    }
}

impl Drop for FramePublisher {
    fn drop(&mut self) {
        self.flush();
        self.sender.take();
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

fn publish_frames(publishers: &Publishers, batches: &Receiver<Vec<Frame>>) {
    let names: Vec<String> = JOINT_NAMES.iter().map(|name| name.to_string()).collect();
    let mut failures = RateLimiter::new(Duration::from_secs(5));
    for frame in batches.iter().flatten() {
        let stamp = Time::from_secs_f64(frame.sim_time);
        let header = |frame_id: &str| Header {
            stamp,
            frame_id: frame_id.to_owned(),
        };
        let (position, orientation) = (frame.cube.position, frame.cube.orientation);
        let results = [
            publishers
                .joint_states
                .publish(JointState {
                    header: header(""),
                    name: names.clone(),
                    position: frame.arm.position.to_vec(),
                    velocity: frame.arm.velocity.to_vec(),
                    effort: frame.arm.effort.to_vec(),
                })
                .is_ok(),
            publishers.clock.publish(Clock { clock: stamp }).is_ok(),
            publishers
                .reward
                .publish(Float64 { data: frame.reward })
                .is_ok(),
            publishers
                .success
                .publish(Bool {
                    data: frame.success,
                })
                .is_ok(),
            publishers
                .cube_pose
                .publish(PoseStamped {
                    header: header("world"),
                    pose: Pose {
                        position: Point {
                            x: position[0],
                            y: position[1],
                            z: position[2],
                        },
                        orientation: Quaternion {
                            w: orientation[0],
                            x: orientation[1],
                            y: orientation[2],
                            z: orientation[3],
                        },
                    },
                })
                .is_ok(),
            frame.diagnostics.is_none_or(|diagnostics| {
                publishers
                    .diagnostics
                    .publish(diagnostics_message(header(""), &diagnostics))
                    .is_ok()
            }),
        ];
        if results.contains(&false) {
            if let Some(suppressed) = failures.check(Instant::now()) {
                tracing::warn!(suppressed, "publishing failed for part of a frame");
            }
        }
        if let Some(published) = frame.published {
            let _ = published.send(());
        }
    }
}

fn diagnostics_message(header: Header, diagnostics: &NodeDiagnostics) -> DiagnosticArray {
    let value = |key: &str, value: u64| KeyValue {
        key: key.to_owned(),
        value: value.to_string(),
    };
    let (level, message) = if diagnostics.physics_divergences > 0 {
        (
            DiagnosticStatus::WARN,
            "the physics diverged and an episode was restarted (see the log)",
        )
    } else {
        (DiagnosticStatus::OK, "running")
    };
    let mut status = vec![DiagnosticStatus {
        level,
        name: "so101_sim_node".to_owned(),
        message: message.to_owned(),
        hardware_id: "so101_sim".to_owned(),
        values: vec![
            value("accepted_commands", diagnostics.accepted_commands),
            value("rejected_commands", diagnostics.rejected_commands),
            value("accepted_trajectories", diagnostics.accepted_trajectories),
            value("rejected_trajectories", diagnostics.rejected_trajectories),
            value("episode", diagnostics.episode),
            value("physics_divergences", diagnostics.physics_divergences),
            value("pacing_resyncs", diagnostics.pacing_resyncs),
        ],
    }];
    status.extend(diagnostics.cameras.as_ref().map(camera_status));
    DiagnosticArray { header, status }
}

/// The cameras' status: frames rendered and skipped per camera, render time, the GL renderer.
fn camera_status(rig: &RigDiagnostics) -> DiagnosticStatus {
    let skipped: u64 = rig.cameras.iter().map(|camera| camera.skipped).sum();
    let (level, message) = if skipped > 0 {
        (
            DiagnosticStatus::WARN,
            "the renderer cannot keep up: frames skipped (lower --camera-rate or --camera-size)",
        )
    } else {
        (DiagnosticStatus::OK, "rendering every frame")
    };
    let mut values = vec![
        KeyValue {
            key: "renderer".into(),
            value: rig.renderer.clone(),
        },
        KeyValue {
            key: "mean_render_ms".into(),
            value: format!("{:.3}", rig.mean_render_ms),
        },
    ];
    for camera in &rig.cameras {
        values.push(KeyValue {
            key: format!("{}.rendered", camera.name),
            value: camera.rendered.to_string(),
        });
        values.push(KeyValue {
            key: format!("{}.skipped", camera.name),
            value: camera.skipped.to_string(),
        });
    }
    DiagnosticStatus {
        level,
        name: "so101_sim_node: cameras".to_owned(),
        message: message.to_owned(),
        hardware_id: "so101_sim".to_owned(),
        values,
    }
}

/// /sim/reset and /sim/step.
pub struct SimServices {
    reset: Server<TriggerRequest, TriggerResponse>,
    step: Server<TriggerRequest, TriggerResponse>,
}

/// A service call waiting for its answer.
pub struct PendingCall(ros2_client::RmwRequestId);

impl SimServices {
    pub fn serve(node: &mut RosNode) -> Result<Self, NodeError> {
        Ok(Self {
            reset: node.server::<Trigger>(services::SIM_RESET)?,
            step: node.server::<Trigger>(services::SIM_STEP)?,
        })
    }

    pub fn next_reset(&self) -> Option<PendingCall> {
        take_request(&self.reset, "/sim/reset")
    }

    pub fn next_step(&self) -> Option<PendingCall> {
        take_request(&self.step, "/sim/step")
    }

    pub fn answer_reset(&self, call: PendingCall, success: bool, message: String) {
        answer(&self.reset, call, success, message);
    }

    pub fn answer_step(&self, call: PendingCall, success: bool, message: String) {
        answer(&self.step, call, success, message);
    }
}

fn take_request(
    server: &Server<TriggerRequest, TriggerResponse>,
    name: &str,
) -> Option<PendingCall> {
    match server.receive_request() {
        Ok(Some((id, _))) => Some(PendingCall(id)),
        Ok(None) => None,
        Err(error) => {
            tracing::warn!(service = name, ?error, "bad service request");
            None
        }
    }
}

fn answer(
    server: &Server<TriggerRequest, TriggerResponse>,
    call: PendingCall,
    success: bool,
    message: String,
) {
    if let Err(error) = server.send_response(call.0, TriggerResponse { success, message }) {
        tracing::warn!(?error, "cannot send a service response");
    }
}
