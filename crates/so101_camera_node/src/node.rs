//! The node: one thread per camera turns its frames into messages; the main thread serves the
//! parameters and reports /diagnostics once a second until shutdown.

use std::{
    sync::{Arc, Mutex, PoisonError},
    thread,
    time::{Duration, Instant, SystemTime, UNIX_EPOCH},
};

use anyhow::{bail, Context as _, Result};
use ros2_client::Publisher;
use so101_core::{
    contract::topics,
    ros::{
        parameters::{Options, ParameterServer, Parameters, Value},
        qos,
        shutdown::Shutdown,
        RosNode,
    },
};
use so101_msgs::{
    builtin_interfaces::Time,
    diagnostic_msgs::DiagnosticArray,
    sensor_msgs::{CameraInfo, CompressedImage, Image, RegionOfInterest},
    std_msgs::Header,
};

use crate::{
    cli::Args,
    clock::{system_time_of, ClockPair},
    decode::{jpeg_from_rgb, rgb_from_jpeg, rgb_from_yuyv},
    device::{monotonic_now, CameraDevice, CameraStream, CaptureError, Frame},
    fake::FakeCamera,
    jpeg::whole_jpeg,
    modes::{self, Mode, PixelFormat},
    request::{CameraRequest, DeviceName},
    status::{diagnostic, CameraStatus},
};

/// How long a wait for a frame lasts before it counts as a stall (and shutdown is checked).
const FRAME_WAIT: Duration = Duration::from_millis(500);
/// How often a camera that went away is looked for.
const REOPEN_EVERY: Duration = Duration::from_millis(500);

/// The device of a request.
pub fn device_of(request: &CameraRequest) -> Result<Box<dyn CameraDevice>> {
    match &request.device {
        DeviceName::Fake(settings) => {
            let settings = settings
                .parse()
                .map_err(|error: String| anyhow::anyhow!("--camera {}: {error}", request.name))?;
            Ok(Box::new(FakeCamera::new(settings)))
        }
        device => bail!(
            "--camera {}={device}: this build has no V4L2 backend yet (issue 29); only fake: \
             test cameras can be served",
            request.name
        ),
    }
}

/// Opens a camera in the mode its request asks for, or says why not (the modes it offers).
fn open(
    device: &mut dyn CameraDevice,
    request: &CameraRequest,
) -> Result<(Mode, Box<dyn CameraStream>)> {
    let offered = device.modes()?;
    let mode = modes::choose(&offered, request.size, request.fps)
        .with_context(|| format!("--camera {}", request.name))?;
    Ok((mode, device.open(mode)?))
}

pub fn run(args: Args) -> Result<()> {
    let mut devices = args
        .cameras
        .iter()
        .map(device_of)
        .collect::<Result<Vec<_>>>()?;
    if args.list {
        for (request, device) in args.cameras.iter().zip(&mut devices) {
            println!(
                "{}={}: {}",
                request.name,
                request.device,
                modes::list(&device.modes()?)
            );
        }
        return Ok(());
    }
    // Every camera opens (or is refused) before the node starts.
    let mut streams = Vec::new();
    for (request, device) in args.cameras.iter().zip(&mut devices) {
        let (mode, stream) = open(device.as_mut(), request)?;
        tracing::info!(camera = %request.name, device = %request.device, %mode, "camera open");
        streams.push((mode, stream));
    }
    let shutdown = Shutdown::on_signals().context("cannot install the signal handlers")?;
    let mut node = RosNode::start("so101_camera_node", &args.node)?;
    let _parameters = ParameterServer::start(&mut node, declarations(&args))?;
    let diagnostics = node.publisher::<DiagnosticArray>(topics::DIAGNOSTICS, qos::reliable(10))?;
    let mut workers = Vec::new();
    let mut statuses = Vec::new();
    for ((request, device), (mode, stream)) in args.cameras.iter().zip(devices).zip(streams) {
        let status = Arc::new(Mutex::new(CameraStatus {
            name: request.name.clone(),
            device: request.device.to_string(),
            state: mode.to_string(),
            streaming: true,
            ..CameraStatus::default()
        }));
        let camera = Camera {
            topics: CameraTopics::advertise(&mut node, &request.name, args.raw)?,
            request: request.clone(),
            device,
            jpeg_quality: args.jpeg_quality,
            status: Arc::clone(&status),
            shutdown: shutdown.clone(),
        };
        statuses.push((status, 0_u64));
        workers.push(thread::spawn(move || camera.serve(stream)));
    }
    let deadline = args
        .duration
        .map(|s| Instant::now() + Duration::from_secs_f64(s.max(0.0)));
    let mut last_report = Instant::now();
    while !shutdown.is_requested() && deadline.is_none_or(|deadline| Instant::now() < deadline) {
        thread::sleep(Duration::from_millis(50));
        let elapsed = last_report.elapsed();
        if elapsed < Duration::from_secs(1) {
            continue;
        }
        last_report = Instant::now();
        let status = statuses
            .iter_mut()
            .map(|(status, frames_before)| {
                let status = status
                    .lock()
                    .unwrap_or_else(PoisonError::into_inner)
                    .clone();
                let fps = (status.frames - *frames_before) as f64 / elapsed.as_secs_f64();
                *frames_before = status.frames;
                diagnostic(&status, fps)
            })
            .collect();
        let header = Header {
            stamp: stamp_of(now_since_epoch()),
            frame_id: String::new(),
        };
        if diagnostics
            .publish(DiagnosticArray { header, status })
            .is_err()
        {
            tracing::debug!("publishing /diagnostics failed");
        }
    }
    shutdown.request();
    for worker in workers {
        let _ = worker.join();
    }
    Ok(())
}

/// The node's parameters: its options, read-only.
pub fn declarations(args: &Args) -> Parameters {
    let options = Options::of::<Args>();
    let cameras = args
        .cameras
        .iter()
        .map(|request| format!("{}={}", request.name, request.device))
        .collect();
    Parameters::new([
        options.declare("camera", Value::StringArray(cameras)),
        options.declare("raw", Value::Bool(args.raw)),
        options.declare("jpeg_quality", Value::Integer(i64::from(args.jpeg_quality))),
    ])
}

/// One camera's topics.
struct CameraTopics {
    frame_id: String,
    compressed: Publisher<CompressedImage>,
    info: Publisher<CameraInfo>,
    raw: Option<Publisher<Image>>,
}

impl CameraTopics {
    fn advertise(node: &mut RosNode, name: &str, raw: bool) -> Result<Self> {
        let qos = qos::default_topic();
        let topic = |leaf| topics::camera(name, leaf);
        Ok(Self {
            frame_id: topics::camera_optical_frame(name),
            compressed: node.publisher(&topic(topics::IMAGE_COMPRESSED), qos.clone())?,
            info: node.publisher(&topic(topics::CAMERA_INFO), qos.clone())?,
            raw: if raw {
                Some(node.publisher(&topic(topics::IMAGE_RAW), qos)?)
            } else {
                None
            },
        })
    }
}

/// A camera's thread.
struct Camera {
    topics: CameraTopics,
    request: CameraRequest,
    device: Box<dyn CameraDevice>,
    jpeg_quality: u8,
    status: Arc<Mutex<CameraStatus>>,
    shutdown: Shutdown,
}

impl Camera {
    fn status(&self) -> std::sync::MutexGuard<'_, CameraStatus> {
        self.status.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Streams until shutdown; a camera that goes away is reopened when it comes back.
    fn serve(mut self, mut stream: Box<dyn CameraStream>) {
        let mut last_sequence: Option<u32> = None;
        while !self.shutdown.is_requested() {
            match stream.next_frame(FRAME_WAIT) {
                Ok(frame) => {
                    if let Some(last) = last_sequence {
                        let missed = frame.sequence.wrapping_sub(last).saturating_sub(1);
                        self.status().device_drops += u64::from(missed);
                    }
                    last_sequence = Some(frame.sequence);
                    self.publish(&frame);
                }
                Err(CaptureError::Timeout(_)) => self.status().timeouts += 1,
                Err(CaptureError::Gone(reason)) => {
                    tracing::warn!(camera = %self.request.name, %reason, "camera gone: reopening when it returns");
                    {
                        let mut status = self.status();
                        status.unplugs += 1;
                        status.streaming = false;
                        status.state = format!("gone ({reason}): reopening when it returns");
                    }
                    let Some((mode, reopened)) = self.reopen() else {
                        return;
                    };
                    (stream, last_sequence) = (reopened, None);
                    tracing::info!(camera = %self.request.name, %mode, "camera back");
                    let mut status = self.status();
                    status.streaming = true;
                    status.state = mode.to_string();
                }
            }
        }
    }

    fn reopen(&mut self) -> Option<(Mode, Box<dyn CameraStream>)> {
        while !self.shutdown.is_requested() {
            if let Ok(opened) = open(self.device.as_mut(), &self.request) {
                return Some(opened);
            }
            thread::sleep(REOPEN_EVERY);
        }
        None
    }

    fn publish(&self, frame: &Frame) {
        let (jpeg, rgb) = match frame.format {
            PixelFormat::Mjpeg => {
                let Some(jpeg) = whole_jpeg(&frame.data) else {
                    self.status().broken_frames += 1;
                    return;
                };
                let rgb = self
                    .topics
                    .raw
                    .as_ref()
                    .map(|_| rgb_from_jpeg(jpeg, frame.width, frame.height));
                (Ok(jpeg.to_vec()), rgb)
            }
            PixelFormat::Yuyv => {
                let rgb = rgb_from_yuyv(&frame.data);
                let jpeg = jpeg_from_rgb(&rgb, frame.width, frame.height, self.jpeg_quality);
                (jpeg, Some(Ok(rgb)))
            }
        };
        let (jpeg, rgb) = match (jpeg, rgb.transpose()) {
            (Ok(jpeg), Ok(rgb)) => (jpeg, rgb),
            (Err(error), _) | (_, Err(error)) => {
                tracing::debug!(camera = %self.request.name, %error, "a frame that does not decode");
                self.status().broken_frames += 1;
                return;
            }
        };
        let now = ClockPair::read(monotonic_now, now_since_epoch);
        let captured = system_time_of(frame.captured, now).unwrap_or(now.system);
        let header = Header {
            stamp: stamp_of(captured),
            frame_id: self.topics.frame_id.clone(),
        };
        let mut ok = self
            .topics
            .info
            .publish(uncalibrated_info(header.clone(), frame.width, frame.height))
            .is_ok();
        if let (Some(publisher), Some(rgb)) = (&self.topics.raw, rgb) {
            ok &= publisher
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
        let mut status = self.status();
        status.frames += 1;
        status.latency_ms = monotonic_now().saturating_sub(frame.captured).as_secs_f64() * 1e3;
        if !ok {
            tracing::debug!(camera = %self.request.name, "publishing a frame failed");
        }
    }
}

/// CameraInfo of a camera without a calibration: its size, every matrix zero (what ROS tools
/// read as "not calibrated").
fn uncalibrated_info(header: Header, width: u32, height: u32) -> CameraInfo {
    CameraInfo {
        header,
        height,
        width,
        distortion_model: String::new(),
        d: Vec::new(),
        k: [0.0; 9],
        r: [0.0; 9],
        p: [0.0; 12],
        binning_x: 0,
        binning_y: 0,
        roi: RegionOfInterest::default(),
    }
}

fn now_since_epoch() -> Duration {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .unwrap_or_default()
}

fn stamp_of(since_epoch: Duration) -> Time {
    Time {
        sec: i32::try_from(since_epoch.as_secs()).unwrap_or(i32::MAX),
        nanosec: since_epoch.subsec_nanos(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;
    use so101_core::ros::parameters::documentation::assert_documented;

    #[test]
    fn every_option_is_a_parameter() {
        let args = Args::parse_from(["so101_camera_node", "--camera", "top=fake:"]);
        let parameters = declarations(&args);
        // Listing and a run's length are no settings of the node.
        assert_eq!(
            Options::of::<Args>().undeclared(&parameters),
            ["list", "duration"]
        );
        assert_documented("so101_camera_node", &parameters);
    }

    #[test]
    fn real_devices_are_refused_until_the_v4l2_backend_exists() {
        let request: CameraRequest = "top=/dev/video0".parse().unwrap();
        let refused = device_of(&request)
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(refused.contains("no V4L2 backend"), "{refused}");
        let bad: CameraRequest = "top=fake:hdr".parse().unwrap();
        assert!(device_of(&bad).is_err());
    }
}
