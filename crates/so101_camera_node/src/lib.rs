//! Real cameras as ROS image topics (issue 29), built from the parts that need no device first:
//! - [`request`]: `--camera NAME=DEVICE[:WIDTHxHEIGHT][@FPS]`;
//! - [`modes`]: choosing a mode the camera offers (MJPEG first, for USB bandwidth);
//! - [`jpeg`]: whether a buffer is a whole JPEG (a truncated one is dropped, never published);
//! - [`clock`]: a capture instant on the monotonic clock as a ROS stamp.
//!
//! The device itself (V4L2 through the `v4l` crate, and the in-process fake that tests use) comes
//! behind a narrow trait next; these modules are what both share.

pub mod clock;
pub mod jpeg;
pub mod modes;
pub mod request;
