//! Command-line options of so101_sim_node.

use std::path::PathBuf;

use so101_core::{
    contract::CAMERA_NAMES, ros::NodeArgs, servo::ServoModelChoice, task::CONTROL_RATE_HZ,
};

use so101_sim::{
    cameras::spec::{self, CameraList, FrameSize},
    offscreen::RendererChoice,
    randomization::RandomizationConfig,
    task::TaskKind,
};

use crate::pacing::{self, TimeMode};

/// MuJoCo simulation of the SO-101 arm with a cube-to-bin task, publishing /joint_states and
/// obeying /joint_commands like the physical arm's driver.
#[derive(Debug, clap::Parser)]
#[command(version, about, long_about = None)]
pub struct Args {
    /// MJCF scene to load.
    #[arg(long, default_value = default_scene())]
    pub scene: PathBuf,
    /// Mesh-free visual variant: loads without the third-party meshes fetched at set-up.
    #[arg(long)]
    pub lite: bool,
    /// Task that defines /task/reward and /task/success.
    #[arg(long, value_enum, default_value = "cube_to_bin")]
    pub task: TaskKind,
    /// cube_to_bin only: dense shaping for approach, grasp, lift and place instead of a sparse reward.
    #[arg(long)]
    pub dense_reward: bool,
    /// Seed of the cube placement on /sim/reset: the same seed gives the same sequence of episodes.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Control rate in Hz: /joint_states, /clock and the task topics are published once per period.
    #[arg(long, default_value_t = 100.0, value_parser = parse_rate)]
    pub rate: f64,
    /// Sim time relative to wall time: a factor (1 = real time, 2 = twice as fast) or "max".
    #[arg(long, default_value = "1", value_parser = pacing::parse_speed, conflicts_with = "lockstep")]
    pub speed: TimeMode,
    /// Advance one control period per /sim/step call and never by itself (deterministic evaluation, RL).
    #[arg(long)]
    pub lockstep: bool,
    /// With --lockstep: every valid /joint_commands message also advances one control period,
    /// and the state it leads to is published before the next command is taken (one message,
    /// one step, in order; no /sim/step call needed; a rejected command advances nothing).
    #[arg(long, requires = "lockstep")]
    pub step_on_command: bool,
    /// Play the built-in pick-and-place demo until the first external command arrives.
    #[arg(long)]
    pub demo: bool,
    /// Cameras to render, comma-separated: NAME[:WIDTHxHEIGHT][@RATE] (e.g.
    /// "top,front:320x240,wrist@15"), or "none". Each publishes /camera/NAME/image_raw (rgb8) and
    /// /camera/NAME/camera_info, stamped with sim time.
    #[arg(long, default_value = CAMERA_NAMES.join(","), value_parser = spec::parse_camera_list)]
    pub cameras: CameraList,
    /// Frame size of the cameras that do not name one.
    #[arg(long, default_value = "640x480", value_parser = spec::parse_size)]
    pub camera_size: FrameSize,
    /// Frames per second of sim time of the cameras that do not name a rate. In real time, frames
    /// the renderer cannot keep up with are skipped (and counted in /diagnostics); in lockstep and
    /// --speed modes the physics waits for them. Default: the control rate of the tasks and datasets.
    #[arg(long, default_value_t = CONTROL_RATE_HZ, value_parser = spec::parse_rate)]
    pub camera_rate: f64,
    /// Also publish JPEG (sensor_msgs/CompressedImage) on /camera/NAME/image_raw/compressed.
    #[arg(long)]
    pub jpeg: bool,
    /// JPEG quality, 1-100.
    #[arg(long, default_value_t = 90, value_parser = clap::value_parser!(u8).range(1..=100))]
    pub jpeg_quality: u8,
    /// Headless OpenGL platform: EGL (GPU driver or Mesa without a display), OSMesa, or EGL with
    /// OSMesa as the fallback.
    #[arg(long, value_enum, default_value = "auto")]
    pub renderer: RendererChoice,
    /// Render shadows (costly on a CPU rasteriser).
    #[arg(long)]
    pub camera_shadows: bool,
    /// The servos' model: "sts3215" (the STS3215 as LeRobot configures it, published mechanics),
    /// "gain80" (the scene's first position servos, for comparison) or a parameter file (.json)
    /// from `so101-sysid fit`.
    #[arg(long, default_value = "sts3215", value_parser = parse_servo_params)]
    pub servo_params: String,
    /// Domain randomization at every /sim/reset: "off", "default" (assets/randomization.toml) or
    /// a file of ranges (.toml). Each episode's draw is published on /sim/episode.
    #[arg(long, default_value = "off", value_parser = parse_randomize)]
    pub randomize: String,
    /// Exit cleanly after this many seconds of wall time.
    #[arg(long, value_parser = parse_duration)]
    pub duration: Option<f64>,
    #[command(flatten)]
    pub node: NodeArgs,
}

pub fn default_scene() -> &'static str {
    so101_core::robot::DEFAULT_SCENE
}

/// Checks the preset or file now (a usage error rather than a failure at start).
fn parse_servo_params(text: &str) -> Result<String, String> {
    ServoModelChoice::parse(text).map_err(|error| error.to_string())?;
    Ok(text.to_owned())
}

/// Checks the file now, so a bad one is a usage error rather than a failure at start.
fn parse_randomize(text: &str) -> Result<String, String> {
    if text != "off" {
        RandomizationConfig::parse(text).map_err(|error| error.to_string())?;
    }
    Ok(text.to_owned())
}

/// The randomization `--randomize` asks for.
pub fn randomization(text: &str) -> anyhow::Result<Option<RandomizationConfig>> {
    if text == "off" {
        return Ok(None);
    }
    Ok(Some(RandomizationConfig::parse(text)?))
}

fn parse_rate(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(rate) if rate.is_finite() && rate > 0.0 && rate <= 10_000.0 => Ok(rate),
        _ => Err(format!(
            "{text:?} is not a rate above 0 and at most 10000 Hz (the scene allows up to one period per physics step)"
        )),
    }
}

fn parse_duration(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(seconds) if (0.0..=1e9).contains(&seconds) => Ok(seconds),
        _ => Err(format!("{text:?} is not a number of seconds from 0 to 1e9")),
    }
}
