//! Real cameras as ROS image topics (issue 29). The parts that need no device:
//! - [`request`]: `--camera NAME=DEVICE[:WIDTHxHEIGHT][@FPS]`;
//! - [`modes`]: choosing a mode the camera offers (MJPEG first, for USB bandwidth);
//! - [`jpeg`]: whether a buffer is a whole JPEG (a truncated one is dropped, never published);
//! - [`clock`]: a capture instant on the monotonic clock as a ROS stamp;
//! - [`device`]: the narrow interface to a camera, and [`fake`]: the in-process test camera behind
//!   it (real MJPEG and YUYV frames of a known picture; drops, truncated frames, stalls, unplugs).
//!
//! - [`controls`]: exposure, gain, white balance and focus as parameters and V4L2 controls;
//! - [`calibration`]: camera_info from a camera_calibration YAML file;
//! - [`fuzzing`]: the fuzz targets' bodies over the calibration YAML, the request and the JPEG check;
//!
//! - [`snapshot`]: `--snapshot`, a still of each camera's empty workspace for the sim's backgrounds;
//!
//! The devices: [`v4l2`] (USB cameras through the `v4l` crate; [`v4l2::mapping`] and
//! [`v4l2::discovery`] are its pure parts). The node: [`node`] (start, parameters, diagnostics)
//! and [`camera`] (one camera's thread); [`messages`], [`status`] and [`decode`] serve them.

pub mod calibration;
pub mod camera;
pub mod cli;
pub mod clock;
pub mod controls;
pub mod decode;
pub mod device;
pub mod fake;
pub mod fuzzing;
pub mod jpeg;
pub mod messages;
pub mod modes;
pub mod node;
pub mod request;
pub mod snapshot;
pub mod status;
pub mod v4l2;
