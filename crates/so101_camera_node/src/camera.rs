//! One camera's thread: its frames become messages (the JPEG as it came, rgb8 where asked for,
//! CameraInfo), its image controls follow the parameters, and a camera that went away is reopened
//! and set up again when it returns.

use std::{
    collections::BTreeMap,
    sync::{
        atomic::{AtomicBool, Ordering},
        mpsc::Receiver,
        Arc, Mutex, MutexGuard, PoisonError,
    },
    thread,
    time::Duration,
};

use anyhow::{Context as _, Result};
use ros2_client::Publisher;
use so101_core::{
    contract::topics,
    ros::{qos, shutdown::Shutdown, RosNode},
};
use so101_msgs::{
    sensor_msgs::{CameraInfo, CompressedImage, Image},
    std_msgs::Header,
};

use crate::{
    calibration::Intrinsics,
    clock::{latency, system_time_of, ClockPair},
    controls::{self, ControlKind, Setting},
    decode::{jpeg_from_rgb, rgb_from_jpeg, rgb_from_yuyv},
    device::{monotonic_now, CameraDevice, CameraStream, CaptureError, Frame},
    jpeg::whole_jpeg,
    messages::{camera_info, now_since_epoch, stamp_of},
    modes::{self, Mode, PixelFormat},
    request::CameraRequest,
    status::CameraStatus,
};

/// How long a wait for a frame lasts before it counts as a stall (and shutdown is checked).
const FRAME_WAIT: Duration = Duration::from_millis(500);
/// How often a camera that went away is looked for.
const REOPEN_EVERY: Duration = Duration::from_millis(500);

/// Opens a camera in the mode its request asks for (or says why not: the modes it offers), and
/// sets its controls.
pub fn open(
    device: &mut dyn CameraDevice,
    request: &CameraRequest,
    settings: &BTreeMap<ControlKind, Setting>,
) -> Result<(Mode, Box<dyn CameraStream>)> {
    let offered = device.modes()?;
    let mode = modes::choose(&offered, request.size, request.fps)
        .with_context(|| format!("--camera {}", request.name))?;
    let mut stream = device.open(mode)?;
    apply(stream.as_mut(), settings, &request.name)
        .with_context(|| format!("--camera {}", request.name))?;
    Ok((mode, stream))
}

/// Sets each control, refusing a setting the camera does not take (with its range), then reads
/// them back: a mode the camera did not take is refused, a value it rounded is said.
fn apply(
    stream: &mut dyn CameraStream,
    settings: &BTreeMap<ControlKind, Setting>,
    camera: &str,
) -> Result<()> {
    if settings.is_empty() {
        return Ok(());
    }
    let states = stream.controls();
    for (&kind, &setting) in settings {
        let state = states
            .iter()
            .find(|state| state.kind == kind)
            .ok_or_else(|| anyhow::anyhow!("the camera has no {kind} control"))?;
        state.check(setting).map_err(anyhow::Error::msg)?;
        stream
            .set_control(kind, setting)
            .map_err(anyhow::Error::msg)?;
    }
    let reported = stream.controls();
    for (&kind, &setting) in settings {
        let now = reported
            .iter()
            .find(|state| state.kind == kind)
            .map(|state| state.setting);
        match controls::read_back(kind, setting, now).map_err(anyhow::Error::msg)? {
            Some(note) => tracing::warn!(camera, "{note}"),
            None => {
                tracing::info!(camera, control = %kind, value = setting.parameter(), "control set (read back)")
            }
        }
    }
    Ok(())
}

/// One camera's topics.
pub struct CameraTopics {
    frame_id: String,
    compressed: Publisher<CompressedImage>,
    info: Publisher<CameraInfo>,
    raw: Publisher<Image>,
    /// image_raw's absolute name, whose readers the main thread counts.
    pub raw_name: String,
    /// Whether frames are decoded and published on image_raw: --raw, or while image_raw has a
    /// subscriber (the main thread looks).
    pub raw_wanted: Arc<AtomicBool>,
}

impl CameraTopics {
    pub fn advertise(node: &mut RosNode, name: &str, raw: bool) -> Result<Self> {
        let qos = qos::default_topic();
        let topic = |leaf| topics::camera(name, leaf);
        Ok(Self {
            frame_id: topics::camera_optical_frame(name),
            compressed: node.publisher(&topic(topics::IMAGE_COMPRESSED), qos.clone())?,
            info: node.publisher(&topic(topics::CAMERA_INFO), qos.clone())?,
            raw: node.publisher(&topic(topics::IMAGE_RAW), qos)?,
            raw_name: node.names().resolve(&topic(topics::IMAGE_RAW)),
            raw_wanted: Arc::new(AtomicBool::new(raw)),
        })
    }
}

/// A camera's thread.
pub struct Camera {
    pub topics: CameraTopics,
    pub request: CameraRequest,
    pub device: Box<dyn CameraDevice>,
    pub jpeg_quality: u8,
    pub intrinsics: Option<Intrinsics>,
    /// The control settings asked for so far: set again on a camera that comes back.
    pub settings: BTreeMap<ControlKind, Setting>,
    /// Settings changed through the parameters.
    pub control_changes: Receiver<(ControlKind, Setting)>,
    pub status: Arc<Mutex<CameraStatus>>,
    pub shutdown: Shutdown,
    /// 1 / the mode's rate: a frame published later than this after its capture is late.
    pub frame_period: Duration,
}

impl Camera {
    fn status(&self) -> MutexGuard<'_, CameraStatus> {
        self.status.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Streams until shutdown; a camera that goes away is reopened when it comes back.
    pub fn serve(mut self, mut stream: Box<dyn CameraStream>) {
        let mut last_sequence: Option<u32> = None;
        self.report_controls(stream.as_mut());
        while !self.shutdown.is_requested() {
            self.change_controls(stream.as_mut());
            match stream.next_frame(FRAME_WAIT) {
                Ok(frame) => {
                    if let Some(last) = last_sequence {
                        let missed = frame.sequence.wrapping_sub(last).saturating_sub(1);
                        let waited = latency(frame.captured, monotonic_now());
                        let behind = waited.is_some_and(|waited| waited > self.frame_period);
                        self.status().missed(missed, behind);
                    }
                    last_sequence = Some(frame.sequence);
                    self.publish(&frame);
                }
                Err(CaptureError::Timeout(_)) => self.status().timeouts += 1,
                Err(CaptureError::Damaged { sequence, reason }) => {
                    tracing::debug!(camera = %self.request.name, sequence, %reason, "damaged frame dropped");
                    // Its sequence number is taken: the next frame does not follow a gap.
                    last_sequence = Some(sequence);
                    self.status().broken_frames += 1;
                }
                Err(CaptureError::Gone(reason)) => {
                    tracing::warn!(camera = %self.request.name, %reason, "camera gone: reopening when it returns");
                    self.status().unplugs += 1;
                    let why = format!("gone ({reason}): reopening when it returns");
                    let Some(reopened) = self.restart(stream, why) else {
                        return;
                    };
                    (stream, last_sequence) = (reopened, None);
                }
                Err(CaptureError::Failed(reason)) => {
                    tracing::warn!(camera = %self.request.name, %reason, "the stream failed (the camera is still there): starting it again");
                    self.status().stream_errors += 1;
                    let why = format!("stream failed ({reason}): starting it again");
                    let Some(reopened) = self.restart(stream, why) else {
                        return;
                    };
                    (stream, last_sequence) = (reopened, None);
                }
            }
        }
    }

    /// Closes `stream` and opens the camera again (with its settings) once it can; None at
    /// shutdown. `why` is the state /diagnostics shows meanwhile.
    fn restart(
        &mut self,
        stream: Box<dyn CameraStream>,
        why: String,
    ) -> Option<Box<dyn CameraStream>> {
        {
            let mut status = self.status();
            status.streaming = false;
            status.state = why;
        }
        // The old stream lets go of the device before it is opened again.
        drop(stream);
        let (mode, mut reopened) = self.reopen()?;
        self.frame_period = Duration::from_secs_f64(1.0 / mode.fps);
        tracing::info!(camera = %self.request.name, %mode, "camera back");
        self.report_controls(reopened.as_mut());
        let mut status = self.status();
        status.streaming = true;
        status.state = mode.to_string();
        Some(reopened)
    }

    fn reopen(&mut self) -> Option<(Mode, Box<dyn CameraStream>)> {
        while !self.shutdown.is_requested() {
            match open(self.device.as_mut(), &self.request, &self.settings) {
                Ok(opened) => return Some(opened),
                Err(error) => tracing::trace!(camera = %self.request.name, "not back: {error:#}"),
            }
            thread::sleep(REOPEN_EVERY);
        }
        None
    }

    /// Applies the settings changed through the parameters since the last frame.
    fn change_controls(&mut self, stream: &mut dyn CameraStream) {
        let changes: Vec<_> = self.control_changes.try_iter().collect();
        if changes.is_empty() {
            return;
        }
        for (kind, setting) in changes {
            let one = BTreeMap::from([(kind, setting)]);
            match apply(stream, &one, &self.request.name) {
                Ok(()) => {
                    self.settings.insert(kind, setting);
                }
                Err(error) => {
                    tracing::warn!(camera = %self.request.name, control = %kind, "not set: {error:#}")
                }
            }
        }
        self.report_controls(stream);
    }

    /// What the camera says its controls are, for /diagnostics.
    fn report_controls(&self, stream: &mut dyn CameraStream) {
        let controls = stream
            .controls()
            .iter()
            .map(|state| (state.kind, state.setting.parameter()))
            .collect();
        self.status().controls = controls;
    }

    fn publish(&self, frame: &Frame) {
        let raw = self.topics.raw_wanted.load(Ordering::Relaxed);
        let Some((jpeg, rgb)) = self.encodings(frame, raw) else {
            self.status().broken_frames += 1;
            return;
        };
        let now = ClockPair::read(monotonic_now, now_since_epoch);
        let captured = system_time_of(frame.captured, now).unwrap_or(now.system);
        let header = Header {
            stamp: stamp_of(captured),
            frame_id: self.topics.frame_id.clone(),
        };
        let info = camera_info(
            header.clone(),
            frame.width,
            frame.height,
            self.intrinsics.as_ref(),
        );
        let mut ok = self.topics.info.publish(info).is_ok();
        if let (true, Some(rgb)) = (raw, rgb) {
            ok &= self
                .topics
                .raw
                .publish(Image {
                    header: header.clone(),
                    height: frame.height,
                    width: frame.width,
                    encoding: "rgb8".into(),
                    is_bigendian: 0,
                    step: 3 * frame.width,
                    data: rgb,
                })
                .is_ok();
        }
        ok &= self
            .topics
            .compressed
            .publish(CompressedImage {
                header,
                format: topics::JPEG_FORMAT.into(),
                data: jpeg,
            })
            .is_ok();
        let now = monotonic_now();
        let mut status = self.status();
        match latency(frame.captured, now) {
            Some(latency) => {
                status.published(latency.as_secs_f64() * 1e3);
                if latency > self.frame_period {
                    status.late_frames += 1;
                }
            }
            None => {
                status.published_stamped_ahead();
                if status.stamped_ahead == 1 {
                    let ahead_ms = (frame.captured - now).as_secs_f64() * 1e3;
                    tracing::warn!(
                        camera = %self.request.name,
                        "a frame's capture instant is {ahead_ms:.1} ms after the node's clock: the \
                         driver's timestamps are not start-of-capture on CLOCK_MONOTONIC \
                         (end-of-frame stamps?); such frames are stamped when published and their \
                         latency is not measured"
                    );
                }
            }
        }
        drop(status);
        if !ok {
            tracing::debug!(camera = %self.request.name, "publishing a frame failed");
        }
    }

    /// The frame's JPEG (as it came, for MJPEG) and its rgb8 where `raw` (or needed anyway), or
    /// None for a frame that is not a whole JPEG or does not decode.
    fn encodings(&self, frame: &Frame, raw: bool) -> Option<(Vec<u8>, Option<Vec<u8>>)> {
        let encoded = match frame.format {
            PixelFormat::Mjpeg => {
                let jpeg = whole_jpeg(&frame.data)?;
                let rgb = raw
                    .then(|| rgb_from_jpeg(jpeg, frame.width, frame.height))
                    .transpose();
                rgb.map(|rgb| (jpeg.to_vec(), rgb))
            }
            PixelFormat::Yuyv => {
                let rgb = rgb_from_yuyv(&frame.data, frame.yuv_range);
                jpeg_from_rgb(&rgb, frame.width, frame.height, self.jpeg_quality)
                    .map(|jpeg| (jpeg, Some(rgb)))
            }
        };
        encoded
            .map_err(|error| {
                tracing::debug!(camera = %self.request.name, %error, "a frame that does not decode");
            })
            .ok()
    }
}
