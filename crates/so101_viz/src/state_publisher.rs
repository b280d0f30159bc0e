//! so101_state_publisher: /robot_description (latched) and /tf_static once, then /tf for every
//! joint state, stamped with the joint state's stamp (sim time with the sim).

use so101_core::contract::topics;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::{Context as _, Result};
use clap::Parser;
use nalgebra::Isometry3;
use so101_core::command::targets_from_joint_state;
use so101_core::robot::{DEFAULT_SCENE, JOINT_LIMITS, JOINT_NAMES};
use so101_core::ros::parameters::ParameterServer;
use so101_core::ros::rate_limit::RateLimiter;
use so101_core::ros::shutdown::Shutdown;
use so101_core::ros::{qos, NodeArgs, RosNode};
use so101_msgs::sensor_msgs::JointState;
use so101_msgs::std_msgs::String as RosString;
use so101_msgs::tf2_msgs::TFMessage;

use crate::scene_geometry::SceneGeometry;
use crate::tf::{joint_transforms, static_transforms, Frames};
use crate::urdf::{robot_description, MeshUri};

/// Publishes the SO-101's robot description (URDF) and its tf tree from /joint_states, so RViz and
/// other ROS tools show the arm (sim or real).
#[derive(Debug, Parser)]
#[command(version)]
pub struct Args {
    /// MJCF scene the arm's shapes are read from.
    #[arg(long, default_value = DEFAULT_SCENE)]
    pub scene: PathBuf,
    /// Draw the links with boxes even where the scene's meshes are installed.
    #[arg(long)]
    pub no_meshes: bool,
    /// How the URDF names the mesh files: package:// (resolves wherever the so101_description
    /// package is installed: `so101-description install`) or file:// (absolute paths, this machine
    /// only).
    #[arg(long, value_enum, default_value = "package")]
    pub mesh_uri: MeshUri,
    /// Parent frame of the arm's base.
    #[arg(long, default_value = "world")]
    pub world_frame: String,
    /// Where the base sits in the world frame, "x,y,z" in m (default: where the scene mounts it).
    #[arg(long, value_parser = so101_core::cli_values::parse_point)]
    pub base_xyz: Option<[f64; 3]>,
    /// Prefix of the arm's frame names ("left" gives left/base, left/shoulder, ...).
    #[arg(long, default_value = "")]
    pub frame_prefix: String,
    /// Print the URDF on stdout and exit.
    #[arg(long)]
    pub print_urdf: bool,
    /// Stop after this many seconds.
    #[arg(long)]
    pub duration: Option<f64>,
    #[command(flatten)]
    pub node: NodeArgs,
}

pub fn run(args: Args) -> Result<()> {
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
