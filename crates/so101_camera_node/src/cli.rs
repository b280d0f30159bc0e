//! Command-line options of so101_camera_node.

use so101_core::ros::NodeArgs;

use crate::request::CameraRequest;

/// Real cameras as ROS image topics: each `--camera NAME=DEVICE` publishes the camera's own JPEG
/// frames unchanged on camera/NAME/image_raw/compressed (sensor_msgs/CompressedImage), its
/// CameraInfo on camera/NAME/camera_info and, with --raw, rgb8 frames on camera/NAME/image_raw,
/// each stamped with the instant the frame was captured. DEVICE `fake:SETTINGS` is the
/// in-process test camera (docs/real_arm.md).
#[derive(Debug, clap::Parser)]
#[command(version, about, long_about = None)]
pub struct Args {
    /// A camera: NAME=DEVICE[:WIDTHxHEIGHT][@FPS], DEVICE a /dev/videoN or /dev/v4l/by-id/...
    /// path, an index, or fake:SETTINGS (repeatable).
    #[arg(long = "camera", required_unless_present = "list")]
    pub cameras: Vec<CameraRequest>,
    /// Also publish rgb8 frames on camera/NAME/image_raw (decoded from the JPEG).
    #[arg(long)]
    pub raw: bool,
    /// JPEG quality of the frames of YUYV-only cameras, 1-100.
    #[arg(long, default_value_t = 90, value_parser = clap::value_parser!(u8).range(1..=100))]
    pub jpeg_quality: u8,
    /// Print each --camera's modes (formats, sizes, rates) and exit.
    #[arg(long)]
    pub list: bool,
    /// Exit cleanly after this many seconds.
    #[arg(long)]
    pub duration: Option<f64>,
    #[command(flatten)]
    pub node: NodeArgs,
}
