//! Command-line options of so101_sim_node.

use std::{path::PathBuf, str::FromStr};

use so101_core::{
    contract::CAMERA_NAMES,
    ros::NodeArgs,
    servo::{ServoModelSpec, DEFAULT_SERVO_MODEL},
    task::CONTROL_RATE_HZ,
};

use so101_sim::{
    cameras::{
        placement::CameraPlacements,
        spec::{self, CameraList, CameraSpec, FrameSize},
    },
    offscreen::RendererChoice,
    randomization::{spec as randomization, RandomizationSpec},
    task::TaskKind,
};

use crate::pacing::{self, TimeMode};

/// Physics periods per second of sim time unless --rate says otherwise: the targets are held for
/// one period, then /joint_states, /clock and the task topics are published. Not the policy's
/// control rate (so101_core::task::CONTROL_RATE_HZ), a client's choice of --rate.
pub const DEFAULT_PERIOD_RATE_HZ: f64 = 100.0;

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
    /// The goal tasks (all but the touch tasks): their dense shaping instead of a sparse reward.
    #[arg(long)]
    pub dense_reward: bool,
    /// Seed of the cube placement on /sim/reset: the same seed gives the same sequence of episodes.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Control rate of the simulated arm in Hz (physics periods per second of sim time; not the
    /// policy's rate): the commanded targets are held for one period, and /joint_states, /clock
    /// and the task topics are published once per period.
    #[arg(long, default_value_t = DEFAULT_PERIOD_RATE_HZ, value_parser = parse_rate)]
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
    /// --speed modes the physics waits for them. Default: the policy's control rate (the tasks' and
    /// datasets').
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
    #[arg(long, default_value = DEFAULT_SERVO_MODEL, value_parser = ServoModelSpec::from_str)]
    pub servo_params: ServoModelSpec,
    /// Domain randomization at every /sim/reset: "off" (or "false"), "default" (or "true":
    /// assets/randomization.toml), "heldout" (the held-out shift set for evaluation:
    /// assets/randomization_heldout.toml) or a file of ranges (.toml). Each episode's draw is
    /// published on /sim/episode.
    #[arg(long, default_value = randomization::OFF, value_parser = RandomizationSpec::from_str)]
    pub randomize: RandomizationSpec,
    /// Where your real cameras stand: a file from `so101-camera-align estimate` (.toml) placing
    /// cameras fixed in the world (pose in the arm's base frame, field of view, frame size).
    /// Randomization jitters around these places; a placed camera renders at the file's size
    /// unless --cameras names one.
    #[arg(long, value_parser = parse_camera_placements)]
    pub camera_poses: Option<CameraPlacements>,
    /// Exit cleanly after this many seconds of wall time.
    #[arg(long, value_parser = parse_duration)]
    pub duration: Option<f64>,
    #[command(flatten)]
    pub node: NodeArgs,
}

impl Args {
    /// The cameras to render: a camera the placements file places takes its size from there
    /// unless --cameras names one.
    pub fn camera_specs(&self) -> Vec<CameraSpec> {
        let placed = |name: &str| {
            self.camera_poses
                .as_ref()
                .and_then(|placements| placements.size(name))
        };
        self.cameras.resolve(
            |name| placed(name).unwrap_or(self.camera_size),
            self.camera_rate,
        )
    }
}

fn parse_camera_placements(text: &str) -> Result<CameraPlacements, String> {
    CameraPlacements::load(std::path::Path::new(text)).map_err(|error| error.to_string())
}

pub fn default_scene() -> &'static str {
    so101_core::robot::DEFAULT_SCENE
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

#[cfg(test)]
mod tests {
    use super::*;
    use clap::{error::ErrorKind, Parser};
    use so101_core::servo::ServoModelChoice;

    #[test]
    fn the_servo_model_and_the_randomization_arrive_parsed() {
        let args = Args::parse_from(["so101_sim_node"]);
        assert_eq!(args.servo_params.name(), DEFAULT_SERVO_MODEL);
        assert_eq!(args.servo_params.choice(), &ServoModelChoice::default());
        assert_eq!(
            (args.randomize.name(), args.randomize.config()),
            ("off", None)
        );
        let args = Args::parse_from([
            "so101_sim_node",
            "--servo-params",
            "gain80",
            "--randomize",
            "true",
        ]);
        assert_eq!(args.servo_params.choice(), &ServoModelChoice::Gain80);
        assert_eq!(args.randomize, RandomizationSpec::default_ranges());
    }

    #[test]
    fn a_bad_model_or_randomization_is_a_usage_error_naming_it() {
        for (option, value, says) in [
            (
                "--servo-params",
                "sts9999",
                "\"sts9999\" is not a servo model",
            ),
            (
                "--servo-params",
                "/nonexistent/fit.json",
                "/nonexistent/fit.json",
            ),
            ("--randomize", "on", "\"on\" is not a randomization"),
            (
                "--randomize",
                "/nonexistent/ranges.toml",
                "/nonexistent/ranges.toml",
            ),
            (
                "--camera-poses",
                "/nonexistent/camera_poses.toml",
                "/nonexistent/camera_poses.toml",
            ),
        ] {
            let error = Args::try_parse_from(["so101_sim_node", option, value]).unwrap_err();
            assert_eq!(error.kind(), ErrorKind::ValueValidation, "{error}");
            assert!(error.to_string().contains(says), "{error}");
        }
    }

    #[test]
    fn a_placed_camera_renders_at_the_file_size_unless_cameras_names_one() {
        let file =
            std::env::temp_dir().join(format!("so101_cli_poses_{}.toml", std::process::id()));
        std::fs::write(
            &file,
            "[front]\nposition = [0.6, 0.0, 0.3]\nquaternion = [1.0, 0.0, 0.0, 0.0]\nfovy = 50.0\nwidth = 1280\nheight = 720\n",
        )
        .unwrap();
        let path = file.to_str().unwrap();
        let args = Args::parse_from([
            "so101_sim_node",
            "--camera-poses",
            path,
            "--cameras",
            "top,front,wrist:64x48",
        ]);
        std::fs::remove_file(&file).unwrap();
        let sizes: Vec<String> = args
            .camera_specs()
            .iter()
            .map(|camera| format!("{}:{}", camera.name, camera.size))
            .collect();
        assert_eq!(sizes, ["top:640x480", "front:1280x720", "wrist:64x48"]);
        assert_eq!(args.camera_poses.unwrap().source, path);
    }
}
