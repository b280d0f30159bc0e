//! Command-line options of so101_camera_node.

use std::path::PathBuf;

use so101_core::ros::NodeArgs;

use crate::{controls::ControlRequest, request::CameraRequest};

/// Real cameras as ROS image topics: each `--camera NAME=DEVICE` publishes the camera's own JPEG
/// frames unchanged on camera/NAME/image_raw/compressed (sensor_msgs/CompressedImage), its
/// CameraInfo on camera/NAME/camera_info and rgb8 frames on camera/NAME/image_raw while it has a
/// subscriber (always with --raw),
/// each stamped with the instant the frame was captured. DEVICE `fake:SETTINGS` is the
/// in-process test camera (docs/real_arm.md).
#[derive(Debug, clap::Parser)]
#[command(version, about, long_about = None)]
pub struct Args {
    /// A camera: NAME=DEVICE[:WIDTHxHEIGHT][@FPS], DEVICE a /dev/videoN or /dev/v4l/by-id/...
    /// path, an index, or fake:SETTINGS (repeatable).
    #[arg(long = "camera", required_unless_present = "list")]
    pub cameras: Vec<CameraRequest>,
    /// An image control set at start: CAMERA.KEY=VALUE, KEY exposure (100 µs units), gain,
    /// white_balance (K) or focus, VALUE a number or auto (repeatable); each is also the
    /// parameter CAMERA.KEY.
    #[arg(long = "control")]
    pub controls: Vec<ControlRequest>,
    /// A camera's calibration: NAME=FILE, the YAML file ROS's camera_calibration writes; its
    /// matrices go out in camera_info (repeatable).
    #[arg(long = "calibration", value_parser = parse_calibration)]
    pub calibrations: Vec<(String, PathBuf)>,
    /// Wait for a camera that is not plugged in yet instead of refusing to start.
    #[arg(long)]
    pub wait: bool,
    /// Decode every frame and publish it as rgb8 on camera/NAME/image_raw, subscribed or not
    /// (without it: only while image_raw has a subscriber).
    #[arg(long)]
    pub raw: bool,
    /// JPEG quality of the frames of YUYV-only cameras, 1-100.
    #[arg(long, default_value_t = 90, value_parser = clap::value_parser!(u8).range(1..=100))]
    pub jpeg_quality: u8,
    /// Print the modes (formats, sizes, rates) of each --camera, or of every camera of this
    /// machine with their stable names, and exit.
    #[arg(long)]
    pub list: bool,
    /// Save one still of each --camera as DIR/NAME/<seconds since 1970>.jpg, taken after 1.5 s
    /// of streaming (automatic exposure settles) in the node's mode and controls, and exit: the
    /// empty workspace the sim shows behind the arm (randomization `backgrounds = DIR`).
    #[arg(long, value_name = "DIR")]
    pub snapshot: Option<PathBuf>,
    /// Exit cleanly after this many seconds.
    #[arg(long)]
    pub duration: Option<f64>,
    #[command(flatten)]
    pub node: NodeArgs,
}

fn parse_calibration(text: &str) -> Result<(String, PathBuf), String> {
    let (name, file) = text
        .split_once('=')
        .filter(|(name, file)| !name.is_empty() && !file.is_empty())
        .ok_or_else(|| format!("--calibration {text:?}: expected NAME=FILE"))?;
    Ok((name.to_owned(), PathBuf::from(file)))
}
