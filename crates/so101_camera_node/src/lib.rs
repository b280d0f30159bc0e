//! Real cameras as ROS image topics (issue 29), built from the parts that need no device first:
//! - [`request`]: `--camera NAME=DEVICE[:WIDTHxHEIGHT][@FPS]`;
//! - [`modes`]: choosing a mode the camera offers (MJPEG first, for USB bandwidth);
//! - [`jpeg`]: whether a buffer is a whole JPEG (a truncated one is dropped, never published);
//! - [`clock`]: a capture instant on the monotonic clock as a ROS stamp;
//! - [`device`]: the narrow interface to a camera, and [`fake`]: the in-process test camera behind
//!   it (real MJPEG and YUYV frames of a known picture; drops, truncated frames, stalls, unplugs).
//!
//! - [`node`]: the node, serving fake cameras so far; the V4L2 backend (through the `v4l` crate)
//!   comes next.

pub mod cli;
pub mod clock;
pub mod decode;
pub mod device;
pub mod fake;
pub mod jpeg;
pub mod modes;
pub mod node;
pub mod request;
pub mod status;
