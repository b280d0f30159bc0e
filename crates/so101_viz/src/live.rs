//! The live bridge: the stack's topics -> [`Bridge`], until a signal or --duration. A camera is
//! shown from its rgb8 frames (image_raw) where it has them, else from its JPEG frames
//! (image_raw/compressed: so101_camera_node's by default).

use so101_core::contract::topics;
use std::time::{Duration, Instant};

use anyhow::Result;
use ros2_client::Subscription;
use so101_core::ros::parameters::{ParameterServer, Parameters};
use so101_core::ros::shutdown::Shutdown;
use so101_core::ros::{qos, NodeArgs, RosNode};
use so101_msgs::geometry_msgs::PoseStamped;
use so101_msgs::sensor_msgs::{CompressedImage, Image, JointState};
use so101_msgs::std_msgs::{Bool, Float64};

use crate::bridge::Bridge;

struct Topics {
    joint_states: Subscription<JointState>,
    commands: Subscription<JointState>,
    cube: Subscription<PoseStamped>,
    reward: Subscription<Float64>,
    success: Subscription<Bool>,
    cameras: Vec<CameraTopics>,
}

struct CameraTopics {
    name: String,
    raw: Subscription<Image>,
    compressed: Subscription<CompressedImage>,
    /// Whether raw frames came: then the JPEG frames of the same instants are not logged again.
    raw_seen: bool,
}

/// Logs what the stack publishes until `shutdown` or `duration` (s).
pub fn run(
    bridge: &mut Bridge,
    node_args: &NodeArgs,
    parameters: Parameters,
    cameras: &[String],
    duration: Option<f64>,
    shutdown: &Shutdown,
) -> Result<()> {
    let mut node = RosNode::start("so101_rerun_bridge", node_args)?;
    let mut topics = Topics {
        joint_states: node.subscription(topics::JOINT_STATES, qos::reliable(100))?,
        commands: node.subscription(topics::JOINT_COMMANDS, qos::reliable(100))?,
        cube: node.subscription(topics::CUBE_POSE, qos::reliable(100))?,
        reward: node.subscription(topics::TASK_REWARD, qos::reliable(100))?,
        success: node.subscription(topics::TASK_SUCCESS, qos::reliable(100))?,
        cameras: cameras
            .iter()
            .map(|name| {
                Ok(CameraTopics {
                    name: name.clone(),
                    raw: node
                        .subscription(&topics::camera(name, topics::IMAGE_RAW), qos::reliable(4))?,
                    compressed: node.subscription(
                        &topics::camera(name, topics::IMAGE_COMPRESSED),
                        qos::reliable(4),
                    )?,
                    raw_seen: false,
                })
            })
            .collect::<Result<_>>()?,
    };
    let parameters = ParameterServer::start(&mut node, parameters)?;
    tracing::info!(cameras = ?cameras, "bridge running");
    let started = Instant::now();
    while !shutdown.is_requested() && duration.is_none_or(|s| started.elapsed().as_secs_f64() < s) {
        let mut idle = true;
        for change in parameters.changes() {
            if let ("image_rate", Some(rate)) = (change.name.as_str(), change.value.as_f64()) {
                bridge.set_image_rate(rate);
            }
        }
        // Joint states first: they carry the sim time the unstamped topics are logged at.
        while let Ok(Some((message, _))) = topics.joint_states.take() {
            bridge.joint_state(&message)?;
            idle = false;
        }
        while let Ok(Some((message, _))) = topics.commands.take() {
            bridge.command(&message)?;
            idle = false;
        }
        while let Ok(Some((message, _))) = topics.cube.take() {
            bridge.cube(&message)?;
            idle = false;
        }
        while let Ok(Some((message, _))) = topics.reward.take() {
            bridge.reward(message.data)?;
            idle = false;
        }
        while let Ok(Some((message, _))) = topics.success.take() {
            bridge.success(message.data)?;
            idle = false;
        }
        for camera in &mut topics.cameras {
            while let Ok(Some((message, _))) = camera.raw.take() {
                camera.raw_seen = true;
                bridge.image(&camera.name, &message)?;
                idle = false;
            }
            while let Ok(Some((message, _))) = camera.compressed.take() {
                if !camera.raw_seen {
                    bridge.compressed_image(&camera.name, &message)?;
                }
                idle = false;
            }
        }
        if idle {
            std::thread::sleep(Duration::from_millis(2));
        }
    }
    Ok(())
}
