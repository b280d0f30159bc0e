//! so101_state_publisher: /robot_description (latched) and /tf_static once, then /tf for every
//! joint state, stamped with the joint state's stamp (sim time with the sim).

use so101_core::contract::topics;
use std::time::{Duration, Instant};

use anyhow::{Context as _, Result};
use nalgebra::Isometry3;
use so101_core::command::targets_from_joint_state;
use so101_core::robot::{JOINT_LIMITS, JOINT_NAMES};
use so101_core::ros::parameters::ParameterServer;
use so101_core::ros::rate_limit::RateLimiter;
use so101_core::ros::shutdown::Shutdown;
use so101_core::ros::{qos, RosNode};
use so101_msgs::sensor_msgs::JointState;
use so101_msgs::std_msgs::String as RosString;
use so101_msgs::tf2_msgs::TFMessage;

use crate::cli::StatePublisherArgs;
use crate::scene_geometry::SceneGeometry;
use crate::tf::{joint_transforms, static_transforms, Frames};
use crate::urdf::robot_description;

pub fn run(args: StatePublisherArgs) -> Result<()> {
    let geometry = SceneGeometry::from_scene_file(&args.scene)?;
    let meshes = !args.no_meshes && geometry.has_meshes();
    let urdf = robot_description(&geometry, meshes.then_some(args.mesh_uri));
    if args.print_urdf {
        print!("{urdf}");
        return Ok(());
    }
    let shutdown = Shutdown::on_signals().context("cannot install the signal handlers")?;
    let mut node = RosNode::start("so101_state_publisher", &args.node)?;
    let _parameters = ParameterServer::start(
        &mut node,
        crate::parameters::state_publisher(&args, meshes, &urdf),
    )?;
    let description = node.publisher::<RosString>("robot_description", qos::latched())?;
    // Under a namespace the tree goes to /NS/tf, as in multi-robot ROS 2 set-ups (tf remapped).
    let tf = node.publisher::<TFMessage>("tf", qos::reliable(100))?;
    let tf_static = node.publisher::<TFMessage>("tf_static", qos::latched())?;
    let joint_states = node.subscription::<JointState>(topics::JOINT_STATES, qos::reliable(100))?;

    let frames = Frames::new(&args.frame_prefix);
    let base = args.base_xyz.map_or(geometry.base_pose, |[x, y, z]| {
        Isometry3::translation(x, y, z)
    });
    description
        .publish(RosString { data: urdf })
        .map_err(|error| anyhow::anyhow!("cannot publish /robot_description: {error:?}"))?;
    tf_static
        .publish(static_transforms(&frames, &args.world_frame, &base))
        .map_err(|error| anyhow::anyhow!("cannot publish /tf_static: {error:?}"))?;
    tracing::info!(meshes, scene = %args.scene.display(), "robot description and static transforms published");

    let started = std::time::Instant::now();
    let mut positions = [f64::NAN; JOINT_NAMES.len()];
    let mut published: u64 = 0;
    let mut failures = RateLimiter::new(Duration::from_secs(5));
    while !shutdown.is_requested()
        && args
            .duration
            .is_none_or(|s| started.elapsed().as_secs_f64() < s)
    {
        let mut idle = true;
        // One /tf message per joint state, stamped as it is.
        while let Ok(Some((message, _))) = joint_states.take() {
            idle = false;
            let targets = match targets_from_joint_state(&message.name, &message.position) {
                Ok(targets) => targets,
                Err(error) => {
                    tracing::debug!(%error, "joint state ignored");
                    continue;
                }
            };
            for (joint, value) in positions.iter_mut().enumerate() {
                if let Some(target) = targets.get(joint) {
                    // Drawn within the model's range; a reading past a limit is drawn at it.
                    *value = JOINT_LIMITS[joint].clamp(target);
                }
            }
            if !positions.iter().all(|v| v.is_finite()) {
                continue; // not every joint known yet
            }
            match tf.publish(joint_transforms(&frames, &positions, message.header.stamp)) {
                Ok(()) => published += 1,
                Err(error) => {
                    if let Some(held_back) = failures.check(Instant::now()) {
                        tracing::warn!(?error, held_back, "cannot publish /tf");
                    }
                }
            }
        }
        if idle {
            std::thread::sleep(Duration::from_millis(2));
        }
    }
    tracing::info!(published, "state publisher stopped");
    Ok(())
}
