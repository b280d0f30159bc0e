//! The V4L2 backend: a USB camera behind [`CameraDevice`] through the `v4l` crate (formats and
//! rates from VIDIOC_ENUM_*, the mode by VIDIOC_S_FMT and S_PARM, four mmap buffers, the image
//! controls by VIDIOC_[GS]_EXT_CTRLS). What needs no device is in [`mapping`] and
//! [`crate::controls`]; [`discovery`] finds the cameras a machine has.

pub mod discovery;
pub mod mapping;
mod range;

use std::{
    io,
    panic::{catch_unwind, AssertUnwindSafe},
    path::{Path, PathBuf},
    time::Duration,
};

use v4l::{
    buffer::{Flags, Type},
    control::{Control, Value},
    io::traits::CaptureStream as _,
    prelude::MmapStream,
    video::{capture::Parameters, Capture as _},
    Device, Format, FourCC,
};

use crate::{
    controls::{self, ControlKind, ControlState, Setting},
    decode::YuvRange,
    device::{monotonic_now, CameraDevice, CameraStream, CaptureError, Frame, OpenError},
    modes::{Mode, OfferedMode, PixelFormat},
};

/// Buffers the driver fills while the node publishes: enough to ride out a slow publish without a
/// drop, few enough that a frame is never served late.
const BUFFERS: u32 = 4;
/// The kernel's "no such device": the camera was unplugged.
const ENODEV: i32 = 19;

/// A camera at a device node.
pub struct V4l2Camera {
    path: PathBuf,
}

impl V4l2Camera {
    pub fn new(path: PathBuf) -> Self {
        Self { path }
    }

    fn device(&self) -> Result<Device, OpenError> {
        Device::with_path(&self.path).map_err(|error| match error.kind() {
            io::ErrorKind::NotFound => OpenError::Missing(self.path.display().to_string()),
            _ => OpenError::Failed(format!("{}: {error}", self.path.display())),
        })
    }
}

/// The MJPEG and YUYV modes a device offers.
pub fn offered_modes(device: &Device) -> io::Result<Vec<OfferedMode>> {
    let mut offered = Vec::new();
    for description in device.enum_formats()? {
        let Some(format) = PixelFormat::from_fourcc(description.fourcc.repr) else {
            continue;
        };
        let sizes = mapping::sizes_of(&device.enum_framesizes(description.fourcc)?);
        for (width, height) in sizes {
            let intervals = device
                .enum_frameintervals(description.fourcc, width, height)
                .unwrap_or_default();
            offered.push(OfferedMode {
                format,
                width,
                height,
                rates: mapping::rates_of(&intervals),
            });
        }
    }
    Ok(offered)
}

impl CameraDevice for V4l2Camera {
    fn modes(&mut self) -> Result<Vec<OfferedMode>, OpenError> {
        let device = self.device()?;
        offered_modes(&device).map_err(|error| {
            OpenError::Failed(format!(
                "{}: listing its modes: {error}",
                self.path.display()
            ))
        })
    }

    fn open(&mut self, mode: Mode) -> Result<Box<dyn CameraStream>, OpenError> {
        let device = self.device()?;
        let failed = |what: &str, error: io::Error| {
            OpenError::Failed(format!("{}: {what}: {error}", self.path.display()))
        };
        let fourcc = FourCC::new(&mode.format.fourcc());
        let format = device
            .set_format(&Format::new(mode.width, mode.height, fourcc))
            .map_err(|error| failed("setting the format", error))?;
        if (format.width, format.height, format.fourcc) != (mode.width, mode.height, fourcc) {
            return Err(OpenError::Failed(format!(
                "{}: asked for {mode}, the driver set {} {}x{}",
                self.path.display(),
                format.fourcc,
                format.width,
                format.height
            )));
        }
        let parameters = device
            .set_params(&Parameters::new(mapping::interval_of(mode.fps)))
            .map_err(|error| failed("setting the frame rate", error))?;
        if let Some(rate) = mapping::rate_of(parameters.interval) {
            if (rate - mode.fps).abs() > 0.05 {
                tracing::warn!(camera = %self.path.display(), asked = mode.fps, set = rate, "the driver chose another frame rate");
            }
        }
        let stream = MmapStream::with_buffers(&device, Type::VideoCapture, BUFFERS)
            .map_err(|error| failed("mapping its buffers", error))?;
        Ok(Box::new(V4l2Stream {
            path: self.path.clone(),
            mode,
            stride: format.stride as usize,
            yuv_range: mapping::yuv_range(format.quantization, format.colorspace),
            stream: Some(stream),
            device,
        }))
    }
}

struct V4l2Stream {
    path: PathBuf,
    mode: Mode,
    /// Bytes per row as the driver lays YUYV frames out (at least width * 2).
    stride: usize,
    yuv_range: YuvRange,
    /// Dropped before the device (it stops streaming on drop).
    stream: Option<MmapStream<'static>>,
    device: Device,
}

impl CameraStream for V4l2Stream {
    fn next_frame(&mut self, timeout: Duration) -> Result<Frame, CaptureError> {
        let stream = self
            .stream
            .as_mut()
            .ok_or_else(|| CaptureError::Gone("stream closed".into()))?;
        stream.set_timeout(timeout);
        let (buffer, metadata) = match stream.next() {
            Ok(next) => next,
            Err(error) if error.kind() == io::ErrorKind::TimedOut => {
                return Err(CaptureError::Timeout(timeout))
            }
            Err(error) => return Err(capture_error(&self.path, &error)),
        };
        if metadata.flags.contains(Flags::ERROR) {
            return Err(CaptureError::Damaged {
                sequence: metadata.sequence,
                reason: "marked corrupted by the driver".into(),
            });
        }
        let used = (metadata.bytesused as usize).min(buffer.len());
        let data = match self.mode.format {
            PixelFormat::Mjpeg => buffer[..used].to_vec(),
            PixelFormat::Yuyv => mapping::packed_rows(
                &buffer[..used],
                self.stride,
                self.mode.width as usize * 2,
                self.mode.height as usize,
            ),
        };
        Ok(Frame {
            data,
            format: self.mode.format,
            yuv_range: self.yuv_range,
            width: self.mode.width,
            height: self.mode.height,
            captured: mapping::capture_instant(metadata.flags, metadata.timestamp, monotonic_now()),
            sequence: metadata.sequence,
        })
    }

    fn controls(&mut self) -> Vec<ControlState> {
        ControlKind::ALL
            .into_iter()
            .filter_map(|kind| control_state(&self.device, kind))
            .collect()
    }

    fn set_control(&mut self, kind: ControlKind, setting: Setting) -> Result<(), String> {
        let has_auto = control_state(&self.device, kind).is_some_and(|state| state.has_auto);
        for (id, value) in controls::writes(kind, setting, has_auto) {
            self.device
                .set_control(Control {
                    id,
                    value: Value::Integer(value),
                })
                .map_err(|error| format!("setting {kind} to {}: {error}", setting.parameter()))?;
        }
        Ok(())
    }
}

impl Drop for V4l2Stream {
    fn drop(&mut self) {
        // v4l's stream panics when VIDIOC_STREAMOFF fails other than with ENODEV; a camera that
        // failed so is closed all the same, and the node goes on.
        if let Some(stream) = self.stream.take() {
            if catch_unwind(AssertUnwindSafe(move || drop(stream))).is_err() {
                tracing::warn!(camera = %self.path.display(), "stopping the stream failed");
            }
        }
    }
}

/// A failed dequeue: ENODEV is an unplug; anything else (EIO: a USB or driver error, which the
/// V4L2 spec allows to be temporary) is a stream to start again, the camera still there.
fn capture_error(path: &Path, error: &io::Error) -> CaptureError {
    if error.raw_os_error() == Some(ENODEV) {
        CaptureError::Gone(format!("{} unplugged", path.display()))
    } else {
        CaptureError::Failed(format!("{}: {error}", path.display()))
    }
}

/// A control's range and setting, if the camera has it. Only integer, boolean and menu controls
/// are asked for: v4l panics describing other types.
fn control_state(device: &Device, kind: ControlKind) -> Option<ControlState> {
    let integer = |id: u32| match device.control(id).ok()?.value {
        Value::Integer(value) => Some(value),
        Value::Boolean(value) => Some(i64::from(value)),
        _ => None,
    };
    let manual = integer(kind.value_control())?;
    let (minimum, maximum) = range::of(device, kind.value_control())?;
    let auto = kind.auto_control().and_then(integer);
    let setting = match auto {
        Some(auto) if controls::is_auto(kind, auto) => Setting::Auto,
        _ => Setting::Manual(manual),
    };
    Some(ControlState {
        kind,
        minimum,
        maximum,
        has_auto: auto.is_some(),
        setting,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_control_ids_are_the_kernel_s() {
        use v4l::v4l_sys as sys;
        assert_eq!(controls::cid::EXPOSURE_AUTO, sys::V4L2_CID_EXPOSURE_AUTO);
        assert_eq!(
            controls::cid::EXPOSURE_ABSOLUTE,
            sys::V4L2_CID_EXPOSURE_ABSOLUTE
        );
        assert_eq!(controls::cid::GAIN, sys::V4L2_CID_GAIN);
        assert_eq!(controls::cid::AUTOGAIN, sys::V4L2_CID_AUTOGAIN);
        assert_eq!(
            controls::cid::AUTO_WHITE_BALANCE,
            sys::V4L2_CID_AUTO_WHITE_BALANCE
        );
        assert_eq!(
            controls::cid::WHITE_BALANCE_TEMPERATURE,
            sys::V4L2_CID_WHITE_BALANCE_TEMPERATURE
        );
        assert_eq!(controls::cid::FOCUS_ABSOLUTE, sys::V4L2_CID_FOCUS_ABSOLUTE);
        assert_eq!(controls::cid::FOCUS_AUTO, sys::V4L2_CID_FOCUS_AUTO);
        assert_eq!(
            controls::cid::EXPOSURE_APERTURE_PRIORITY,
            i64::from(sys::v4l2_exposure_auto_type_V4L2_EXPOSURE_APERTURE_PRIORITY)
        );
    }

    #[test]
    fn only_enodev_is_an_unplug() {
        let path = Path::new("/dev/video0");
        let gone = capture_error(path, &io::Error::from_raw_os_error(ENODEV));
        assert_eq!(gone, CaptureError::Gone("/dev/video0 unplugged".into()));
        let eio = capture_error(path, &io::Error::from_raw_os_error(5));
        assert!(
            matches!(eio, CaptureError::Failed(ref why) if why.contains("/dev/video0")),
            "{eio:?}"
        );
    }

    #[test]
    fn a_device_node_that_is_not_there_is_missing() {
        let mut camera = V4l2Camera::new("/dev/video-none-such".into());
        assert!(matches!(camera.modes(), Err(OpenError::Missing(_))));
    }
}
