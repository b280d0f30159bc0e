//! The node: every camera is opened (or refused) before it starts; then one thread per camera
//! ([`crate::camera`]) turns frames into messages while the main thread serves the parameters,
//! hands control changes to the cameras and reports /diagnostics once a second until shutdown.

use std::{
    collections::BTreeMap,
    fs,
    path::Path,
    sync::{
        atomic::Ordering,
        mpsc::{channel, Sender},
        Arc, Mutex, PoisonError,
    },
    thread,
    time::{Duration, Instant},
};

use anyhow::{bail, Context as _, Result};
use so101_core::{
    contract::topics,
    ros::{
        parameters::{Declaration, Options, ParameterServer, Parameters, Value},
        qos,
        shutdown::Shutdown,
        RosNode,
    },
};
use so101_msgs::{builtin_interfaces::Time, diagnostic_msgs::DiagnosticArray, std_msgs::Header};

use crate::{
    calibration::{self, Intrinsics},
    camera::{self, Camera, CameraTopics},
    cli::Args,
    controls::{ControlKind, ControlState, Setting, AUTO},
    device::CameraDevice,
    fake::FakeCamera,
    modes,
    request::{CameraRequest, DeviceName},
    snapshot,
    status::{diagnostic, summary, CameraStatus},
    v4l2::{discovery, V4l2Camera},
};

/// How often a camera that is not plugged in yet is looked for (--wait).
const WAIT_POLL: Duration = Duration::from_millis(250);

/// The device of a request: a missing device node is refused with the cameras that exist, or
/// waited for with `wait`.
pub fn device_of(
    request: &CameraRequest,
    wait: Option<&Shutdown>,
) -> Result<Box<dyn CameraDevice>> {
    let path = match &request.device {
        DeviceName::Fake(settings) => {
            let settings = settings
                .parse()
                .map_err(|error: String| anyhow::anyhow!("--camera {}: {error}", request.name))?;
            return Ok(Box::new(FakeCamera::new(settings)));
        }
        device => device.path().unwrap_or_default(),
    };
    if !path.exists() {
        let Some(shutdown) = wait else {
            bail!(
                "--camera {}: {}",
                request.name,
                discovery::missing_message(&path, &discovery::video_nodes())
            );
        };
        tracing::info!(camera = %request.name, device = %path.display(), "waiting for the camera to be plugged in");
        while !path.exists() {
            if shutdown.is_requested() {
                bail!("stopped while waiting for {}", path.display());
            }
            thread::sleep(WAIT_POLL);
        }
    }
    Ok(Box::new(V4l2Camera::new(path)))
}

/// `--list` without cameras: every video device of this machine, with its modes.
fn list_machine() {
    let nodes = discovery::video_nodes();
    if nodes.is_empty() {
        println!("no video device (/dev/video*) on this machine");
    }
    for node in nodes {
        let about = match discovery::node_kind(&node.path) {
            Ok(kind) => match kind.why_not_a_camera() {
                Some(why) => why.to_owned(),
                None => V4l2Camera::new(node.path.clone())
                    .modes()
                    .map_or_else(|error| error.to_string(), |offered| modes::list(&offered)),
            },
            Err(error) => error,
        };
        println!("{}: {about}", discovery::describe(&node));
    }
}

/// The calibrations named on the command line, each checked against the cameras.
fn calibrations(args: &Args) -> Result<BTreeMap<String, Intrinsics>> {
    let mut found = BTreeMap::new();
    for (name, file) in &args.calibrations {
        if !args.cameras.iter().any(|request| &request.name == name) {
            bail!(
                "--calibration {name}={}: no --camera {name}",
                file.display()
            );
        }
        let intrinsics = read_calibration(file)
            .with_context(|| format!("--calibration {name}={}", file.display()))?;
        found.insert(name.clone(), intrinsics);
    }
    Ok(found)
}

fn read_calibration(file: &Path) -> Result<Intrinsics> {
    let text = fs::read_to_string(file)?;
    calibration::parse(&text).map_err(anyhow::Error::msg)
}

/// The control settings asked for at start, per camera.
fn start_settings(args: &Args) -> Result<BTreeMap<String, BTreeMap<ControlKind, Setting>>> {
    let mut settings: BTreeMap<String, BTreeMap<ControlKind, Setting>> = BTreeMap::new();
    for control in &args.controls {
        if !args
            .cameras
            .iter()
            .any(|request| request.name == control.camera)
        {
            bail!(
                "--control {}.{}: no --camera {}",
                control.camera,
                control.kind,
                control.camera
            );
        }
        settings
            .entry(control.camera.clone())
            .or_default()
            .insert(control.kind, control.setting);
    }
    Ok(settings)
}

pub fn run(args: Args) -> Result<()> {
    if args.list && args.cameras.is_empty() {
        list_machine();
        return Ok(());
    }
    let shutdown = Shutdown::on_signals().context("cannot install the signal handlers")?;
    let devices = args
        .cameras
        .iter()
        .map(|request| device_of(request, args.wait.then_some(&shutdown)))
        .collect::<Result<Vec<_>>>();
    // Stopped while waiting for a camera (--wait): a clean exit.
    let mut devices = match devices {
        Err(_) if shutdown.is_requested() => return Ok(()),
        devices => devices?,
    };
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
    let mut intrinsics = calibrations(&args)?;
    let mut settings = start_settings(&args)?;
    // Every camera opens in its mode with its controls set (or is refused) before the node starts.
    let mut opened = Vec::new();
    for (request, device) in args.cameras.iter().zip(&mut devices) {
        let camera_settings = settings.remove(&request.name).unwrap_or_default();
        let (mode, mut stream) = camera::open(device.as_mut(), request, &camera_settings)?;
        let calibration = intrinsics.remove(&request.name);
        if let Some(calibration) = &calibration {
            calibration
                .check_size(mode.width, mode.height)
                .map_err(anyhow::Error::msg)
                .with_context(|| format!("--calibration {}", request.name))?;
        }
        let controls = stream.controls();
        tracing::info!(camera = %request.name, device = %request.device, %mode, calibrated = calibration.is_some(), "camera open");
        opened.push((mode, stream, calibration, camera_settings, controls));
    }
    if let Some(dir) = &args.snapshot {
        for (request, (_, stream, ..)) in args.cameras.iter().zip(&mut opened) {
            let jpeg = snapshot::take(stream.as_mut(), snapshot::SETTLE, args.jpeg_quality)
                .with_context(|| format!("--camera {}: no still", request.name))?;
            let path = snapshot::save(dir, &request.name, &jpeg, std::time::SystemTime::now())?;
            println!("{}: {}", request.name, path.display());
        }
        return Ok(());
    }
    let mut node = RosNode::start("so101_camera_node", &args.node)?;
    // ros2-client's spinner keeps the counts of matched subscribers (image_raw is decoded only
    // while it has one, or with --raw).
    let spinner = node
        .node_mut()
        .spinner()
        .map_err(|error| anyhow::anyhow!("cannot start the ROS spinner: {error:?}"))?;
    thread::Builder::new()
        .name("ros-spinner".into())
        .spawn(move || {
            if let Err(error) = smol::block_on(spinner.spin()) {
                tracing::warn!(?error, "the ROS spinner stopped");
            }
        })
        .context("cannot start the ROS spinner")?;
    let camera_controls: Vec<(&str, &[ControlState])> = args
        .cameras
        .iter()
        .zip(&opened)
        .map(|(request, (.., controls))| (request.name.as_str(), controls.as_slice()))
        .collect();
    let parameters = ParameterServer::start(&mut node, declarations(&args, &camera_controls))?;
    let diagnostics = node.publisher::<DiagnosticArray>(topics::DIAGNOSTICS, qos::reliable(10))?;
    let mut workers = Vec::new();
    let mut statuses = Vec::new();
    let mut control_senders: BTreeMap<String, Sender<(ControlKind, Setting)>> = BTreeMap::new();
    let mut raw_topics = Vec::new();
    for ((request, device), (mode, stream, calibration, camera_settings, _)) in
        args.cameras.iter().zip(devices).zip(opened)
    {
        let status = Arc::new(Mutex::new(CameraStatus {
            name: request.name.clone(),
            device: request.device.to_string(),
            state: mode.to_string(),
            streaming: true,
            ..CameraStatus::default()
        }));
        let (sender, control_changes) = channel();
        control_senders.insert(request.name.clone(), sender);
        let topics = CameraTopics::advertise(&mut node, &request.name, args.raw)?;
        raw_topics.push((topics.raw_name.clone(), Arc::clone(&topics.raw_wanted)));
        let camera = Camera {
            topics,
            request: request.clone(),
            device,
            jpeg_quality: args.jpeg_quality,
            intrinsics: calibration,
            settings: camera_settings,
            control_changes,
            status: Arc::clone(&status),
            shutdown: shutdown.clone(),
            frame_period: Duration::from_secs_f64(1.0 / mode.fps),
        };
        statuses.push((status, 0_u64));
        workers.push(thread::spawn(move || camera.serve(stream)));
    }
    let started = Instant::now();
    let deadline = args
        .duration
        .map(|s| Instant::now() + Duration::from_secs_f64(s.max(0.0)));
    let mut last_report = Instant::now();
    while !shutdown.is_requested() && deadline.is_none_or(|deadline| Instant::now() < deadline) {
        thread::sleep(Duration::from_millis(50));
        for change in parameters.changes() {
            forward_control_change(&change.name, &change.value, &control_senders);
        }
        for (name, wanted) in &raw_topics {
            // Readers discovered on the topic (ros2-client's per-publisher count logs an error
            // for every look until a reader has matched).
            let subscribed = node.node().subscription_count(name) > 0;
            wanted.store(args.raw || subscribed, Ordering::Relaxed);
        }
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
            stamp: Time::now(),
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
    // What each camera did, for a user checking a camera (`--duration 10`).
    let elapsed = started.elapsed();
    for (status, _) in &statuses {
        let status = status.lock().unwrap_or_else(PoisonError::into_inner);
        let line = summary(&status, elapsed);
        tracing::info!("{line}");
        println!("{line}");
    }
    Ok(())
}

/// Hands a changed `CAMERA.KEY` parameter to its camera's thread.
fn forward_control_change(
    name: &str,
    value: &Value,
    senders: &BTreeMap<String, Sender<(ControlKind, Setting)>>,
) {
    let Some((camera, key)) = name.rsplit_once('.') else {
        return;
    };
    let kind = ControlKind::ALL.into_iter().find(|kind| kind.key() == key);
    if let (Some(kind), Some(sender), Value::Integer(value)) = (kind, senders.get(camera), value) {
        let _ = sender.send((kind, Setting::from_parameter(*value)));
    }
}

/// The node's parameters: its options, read-only, and each camera's image controls, which may be
/// changed while it runs.
pub fn declarations(args: &Args, camera_controls: &[(&str, &[ControlState])]) -> Parameters {
    let options = Options::of::<Args>();
    let cameras = args
        .cameras
        .iter()
        .map(|request| format!("{}={}", request.name, request.device))
        .collect();
    let calibrations = args
        .calibrations
        .iter()
        .map(|(name, file)| format!("{name}={}", file.display()))
        .collect();
    let mut declared = vec![
        options.declare("camera", Value::StringArray(cameras)),
        options.declare("calibration", Value::StringArray(calibrations)),
        options.declare("raw", Value::Bool(args.raw)),
        options.declare("jpeg_quality", Value::Integer(i64::from(args.jpeg_quality))),
    ];
    for (camera, controls) in camera_controls {
        declared.extend(
            controls
                .iter()
                .map(|state| control_declaration(camera, state)),
        );
    }
    Parameters::new(declared)
}

fn control_declaration(camera: &str, state: &ControlState) -> Declaration {
    let from = if state.has_auto { AUTO } else { state.minimum };
    Declaration::new(
        &format!("{camera}.{}", state.kind.key()),
        Value::Integer(state.setting.parameter()),
        &format!("{camera}'s {}.", state.kind.description()),
    )
    .dynamic()
    .integer_range(from, state.maximum)
    .effect("Set on the camera at once, and again when it comes back after an unplug.")
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;
    use so101_core::ros::parameters::documentation::assert_documented;

    #[test]
    fn every_option_is_a_parameter() {
        let args = Args::parse_from(["so101_camera_node", "--camera", "top=fake:"]);
        let mut fake = FakeCamera::new(Default::default());
        let mode = modes::choose(&fake.modes().unwrap(), None, None).unwrap();
        let controls = fake.open(mode).unwrap().controls();
        let parameters = declarations(&args, &[("top", &controls)]);
        // Listing, waiting, stills, a run's length and start controls (each its own parameter)
        // are no settings of the node.
        assert_eq!(
            Options::of::<Args>().undeclared(&parameters),
            ["control", "wait", "list", "snapshot", "duration"]
        );
        assert_documented("so101_camera_node", &parameters);
    }

    #[test]
    fn a_missing_device_node_is_refused_with_the_cameras_there_are() {
        let request: CameraRequest = "top=/dev/video-none-such".parse().unwrap();
        let refused = device_of(&request, None)
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(
            refused.contains("--camera top: no camera at /dev/video-none-such"),
            "{refused}"
        );
        let bad: CameraRequest = "top=fake:hdr".parse().unwrap();
        assert!(device_of(&bad, None).is_err());
    }

    #[test]
    fn a_control_change_reaches_its_camera() {
        let (sender, changes) = channel();
        let senders = BTreeMap::from([("wrist".to_owned(), sender)]);
        forward_control_change("wrist.exposure", &Value::Integer(156), &senders);
        forward_control_change("wrist.gain", &Value::Integer(AUTO), &senders);
        forward_control_change("top.exposure", &Value::Integer(1), &senders);
        forward_control_change("jpeg_quality", &Value::Integer(1), &senders);
        let got: Vec<_> = changes.try_iter().collect();
        assert_eq!(
            got,
            [
                (ControlKind::Exposure, Setting::Manual(156)),
                (ControlKind::Gain, Setting::Auto)
            ]
        );
    }
}
