//! The narrow interface between the node and a camera: what it offers, opening it in a mode, and
//! its frames with their capture instants. The V4L2 backend and the in-process fake
//! ([`crate::fake`]) stand behind it, so everything above is tested without a device.

use std::time::Duration;

use crate::{
    controls::{ControlKind, ControlState, Setting},
    decode::YuvRange,
    modes::{Mode, OfferedMode, PixelFormat},
};

/// One captured frame, as the device delivered it.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    /// The buffer's bytes: a JPEG (MJPEG) or packed YUYV.
    pub data: Vec<u8>,
    pub format: PixelFormat,
    /// How a YUYV frame's samples span their bytes, as the driver says (MJPEG: unused).
    pub yuv_range: YuvRange,
    pub width: u32,
    pub height: u32,
    /// When its capture began, on CLOCK_MONOTONIC.
    pub captured: Duration,
    /// The device's frame counter: a jump is a frame the device dropped.
    pub sequence: u32,
}

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CaptureError {
    /// No frame within the wait: the camera stalls (or is slow), it is still there.
    #[error("no frame within {0:?}")]
    Timeout(Duration),
    /// The device went away (unplugged, ENODEV): the stream is over; reopen when it returns.
    #[error("the camera is gone: {0}")]
    Gone(String),
    /// The stream failed while the device is still there (EIO: a USB or driver error): it is
    /// started again.
    #[error("the stream failed: {0}")]
    Failed(String),
    /// The device delivered frame `sequence` marked as corrupted (V4L2_BUF_FLAG_ERROR): dropped,
    /// counted as broken (not as a gap in the sequence).
    #[error("frame {sequence} is damaged: {reason}")]
    Damaged { sequence: u32, reason: String },
}

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum OpenError {
    #[error("no such camera: {0}")]
    Missing(String),
    #[error("cannot open the camera: {0}")]
    Failed(String),
}

/// A camera that can be opened.
pub trait CameraDevice: Send {
    /// The modes it offers.
    fn modes(&mut self) -> Result<Vec<OfferedMode>, OpenError>;
    /// Starts streaming in `mode` (one of [`CameraDevice::modes`]).
    fn open(&mut self, mode: Mode) -> Result<Box<dyn CameraStream>, OpenError>;
}

/// A camera streaming in one mode.
pub trait CameraStream: Send {
    /// The next frame, waiting at most `timeout`.
    fn next_frame(&mut self, timeout: Duration) -> Result<Frame, CaptureError>;
    /// The image controls the camera has, with their ranges and settings now.
    fn controls(&mut self) -> Vec<ControlState>;
    /// Sets one control to a setting its [`ControlState::check`] accepts.
    fn set_control(&mut self, kind: ControlKind, setting: Setting) -> Result<(), String>;
}

/// Now on CLOCK_MONOTONIC, the clock of V4L2 buffer timestamps.
pub fn monotonic_now() -> Duration {
    nix::time::clock_gettime(nix::time::ClockId::CLOCK_MONOTONIC)
        .map(|now| {
            Duration::new(
                u64::try_from(now.tv_sec()).unwrap_or(0),
                u32::try_from(now.tv_nsec()).unwrap_or(0),
            )
        })
        .unwrap_or_default()
}
