//! The command-line options of the two binaries, apart from what they run, so their ROS
//! parameters (crate::parameters) and their programs (crate::app, crate::state_publisher) both
//! read them without importing each other.

use std::path::PathBuf;

use clap::{Args as ClapArgs, Parser, Subcommand};
use so101_core::robot::DEFAULT_SCENE;
use so101_core::ros::NodeArgs;

use crate::urdf::MeshUri;

/// Shows the SO-101 stack in Rerun: joint positions and commands, camera images, the arm in 3D
/// (from the shared kinematic model, with the scene's meshes when installed), cube, bin, reward and
/// success. Live from the topics (`live`), or from recorder_node's episode bags (`bag`).
#[derive(Debug, Parser)]
#[command(version)]
pub struct RerunArgs {
    #[command(subcommand)]
    pub command: Command,
    #[command(flatten)]
    pub scene: SceneArgs,
}

#[derive(Debug, ClapArgs)]
pub struct SceneArgs {
    /// MJCF scene the shapes are read from.
    #[arg(long, global = true, default_value = DEFAULT_SCENE)]
    pub scene: PathBuf,
    /// Draw the arm with boxes even where the scene's meshes are installed.
    #[arg(long, global = true)]
    pub no_meshes: bool,
    /// Where the arm's base sits in the world, "x,y,z" in m (default: where the scene mounts it).
    #[arg(long, global = true, value_parser = so101_core::cli_values::parse_point)]
    pub base_xyz: Option<[f64; 3]>,
    /// Camera images logged per second of sim time, per camera (0: every image). Full-rate
    /// 640x480 images make large recordings.
    #[arg(long, global = true, default_value_t = 5.0, value_parser = parse_image_rate)]
    pub image_rate: f64,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Subscribe to the stack's topics and log them as they come.
    Live(LiveArgs),
    /// Turn episode bags into .rrd recordings, one per episode.
    Bag(BagArgs),
}

#[derive(Debug, ClapArgs)]
pub struct LiveArgs {
    /// Write the recording to this .rrd file.
    #[arg(long, group = "sink")]
    pub save: Option<PathBuf>,
    /// Stream to a running viewer (`rerun`), e.g. rerun+http://127.0.0.1:9876/proxy.
    #[arg(long, group = "sink", num_args = 0..=1, default_missing_value = "rerun+http://127.0.0.1:9876/proxy")]
    pub connect: Option<String>,
    /// Start a viewer (the `rerun` executable on PATH, e.g. .venv/bin/rerun) and stream to it.
    #[arg(long, group = "sink")]
    pub spawn: bool,
    /// Cameras to show, comma-separated ("none" for none).
    #[arg(long, default_value = so101_core::contract::CAMERA_NAMES.join(","), value_delimiter = ',')]
    pub cameras: Vec<String>,
    /// Stop after this many seconds.
    #[arg(long)]
    pub duration: Option<f64>,
    #[command(flatten)]
    pub node: NodeArgs,
}

#[derive(Debug, ClapArgs)]
pub struct BagArgs {
    /// Episode bag directories, or directories holding episode_* directories.
    #[arg(required = true)]
    pub bags: Vec<PathBuf>,
    /// Directory for the recordings (EPISODE.rrd).
    #[arg(long, default_value = "rrd")]
    pub output: PathBuf,
}

/// Publishes the SO-101's robot description (URDF) and its tf tree from /joint_states, so RViz and
/// other ROS tools show the arm (sim or real).
#[derive(Debug, Parser)]
#[command(version)]
pub struct StatePublisherArgs {
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

/// Highest --image-rate, images per second of sim time.
pub const MAX_IMAGE_RATE: f64 = 1000.0;

fn parse_image_rate(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(rate) if (0.0..=MAX_IMAGE_RATE).contains(&rate) => Ok(rate),
        _ => Err(format!(
            "{text:?} is not an image rate from 0 to {MAX_IMAGE_RATE} per second"
        )),
    }
}
