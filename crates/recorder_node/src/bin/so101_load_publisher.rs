//! so101_load_publisher: the stack's recording load, synthetic and checkable: camera images and
//! joint states at chosen rates, with contents a reader can verify byte by byte. For the
//! recorder's tests and benchmark while the simulated cameras do not exist yet.
//!
//! Image k of a camera: rgb8, `data[i] = (i * 7 + k) % 256`. JointState k: `position[j] = k *
//! 0.001 + j`. At exit one JSON line on stdout: `{"published": {topic: count}, "failed": {...},
//! "seconds": S}`.

use so101_core::contract::topics;
use std::{
    collections::BTreeMap,
    process::ExitCode,
    time::{Duration, Instant},
};

use anyhow::{Context, Result};
use clap::Parser;
use ros2_client::Publisher;
use so101_core::{
    robot::JOINT_NAMES,
    ros::{logging, qos, shutdown::Shutdown, NodeArgs, RosNode},
};
use so101_msgs::{
    builtin_interfaces::Time,
    sensor_msgs::{Image, JointState},
    std_msgs::Header,
};

/// Publishes synthetic camera images and joint states: by default the recorder benchmark's
/// reference load (two 640x480 cameras at 30 Hz, joint states at 500 Hz), or flat out.
#[derive(Debug, Parser)]
#[command(version)]
struct Args {
    /// Camera names: one /camera/<name>/image_raw each (empty: no cameras).
    #[arg(long, value_delimiter = ',', default_value = "top,front")]
    cameras: Vec<String>,
    #[arg(long, default_value_t = 640)]
    width: u32,
    #[arg(long, default_value_t = 480)]
    height: u32,
    /// Images per second per camera; 0 publishes them as fast as DDS takes them.
    #[arg(long, default_value_t = so101_core::task::CONTROL_RATE_HZ)]
    camera_rate: f64,
    /// JointState messages per second on /joint_states; 0 for none.
    #[arg(long, default_value_t = 500.0)]
    joint_rate: f64,
    /// Seconds of publishing.
    #[arg(long, default_value_t = 5.0)]
    duration: f64,
    /// Seconds to wait before publishing, so subscribers are discovered and matched.
    #[arg(long, default_value_t = 3.0)]
    wait_subscribers: f64,
    #[command(flatten)]
    node: NodeArgs,
}

struct Stream {
    topic: String,
    period: Option<Duration>,
    next_due: Instant,
    count: u64,
    failed: u64,
    kind: StreamKind,
}

enum StreamKind {
    Camera {
        publisher: Publisher<Image>,
        frame_id: String,
    },
    Joints(Publisher<JointState>),
}

fn period(rate: f64) -> Option<Duration> {
    (rate > 0.0).then(|| Duration::from_secs_f64(1.0 / rate))
}

fn image_data(len: usize, k: u64) -> Vec<u8> {
    (0..len).map(|i| ((i as u64 * 7 + k) % 256) as u8).collect()
}

fn main() -> ExitCode {
    logging::init();
    logging::exit_code(run(Args::parse()))
}

fn run(args: Args) -> Result<()> {
    let shutdown = Shutdown::on_signals().context("cannot install the signal handlers")?;
    let mut node = RosNode::start("so101_load_publisher", &args.node)?;
    let start = Instant::now() + Duration::from_secs_f64(args.wait_subscribers.max(0.0));
    let mut streams = Vec::new();
    for camera in args.cameras.iter().filter(|name| !name.is_empty()) {
        let topic = format!("camera/{camera}/image_raw");
        streams.push(Stream {
            topic: node.names().resolve(&topic),
            period: period(args.camera_rate),
            next_due: start,
            count: 0,
            failed: 0,
            kind: StreamKind::Camera {
                publisher: node.publisher(&topic, qos::default_topic())?,
                frame_id: format!("camera_{camera}"),
            },
        });
    }
    if args.joint_rate > 0.0 {
        streams.push(Stream {
            topic: node.names().resolve("joint_states"),
            period: period(args.joint_rate),
            next_due: start,
            count: 0,
            failed: 0,
            kind: StreamKind::Joints(node.publisher(topics::JOINT_STATES, qos::default_topic())?),
        });
    }
    let (width, height) = (args.width, args.height);
    let image_len = (width * height * 3) as usize;
    while Instant::now() < start && !shutdown.is_requested() {
        std::thread::sleep(Duration::from_millis(20));
    }
    let began = Instant::now();
    let end = began + Duration::from_secs_f64(args.duration);
    while Instant::now() < end && !shutdown.is_requested() {
        let now = Instant::now();
        let Some(stream) = streams
            .iter_mut()
            .filter(|s| s.period.is_none() || s.next_due <= now)
            .min_by_key(|s| s.next_due)
        else {
            let next = streams.iter().map(|s| s.next_due).min().unwrap_or(end);
            std::thread::sleep(
                next.saturating_duration_since(now)
                    .min(Duration::from_millis(5)),
            );
            continue;
        };
        let k = stream.count;
        let header = |frame_id: &str| Header {
            stamp: Time::now(),
            frame_id: frame_id.to_owned(),
        };
        let ok = match &stream.kind {
            StreamKind::Camera {
                publisher,
                frame_id,
            } => publisher
                .publish(Image {
                    header: header(frame_id),
                    height,
                    width,
                    encoding: "rgb8".into(),
                    is_bigendian: 0,
                    step: width * 3,
                    data: image_data(image_len, k),
                })
                .is_ok(),
            StreamKind::Joints(publisher) => publisher
                .publish(JointState {
                    header: header(""),
                    name: JOINT_NAMES.iter().map(|n| n.to_string()).collect(),
                    position: (0..JOINT_NAMES.len())
                        .map(|j| k as f64 * 0.001 + j as f64)
                        .collect(),
                    velocity: Vec::new(),
                    effort: Vec::new(),
                })
                .is_ok(),
        };
        if ok {
            stream.count += 1;
        } else {
            stream.failed += 1;
        }
        stream.next_due = match stream.period {
            Some(period) => stream.next_due + period,
            None => Instant::now(),
        };
    }
    let seconds = began.elapsed().as_secs_f64();
    // Let reliable repairs of the last samples go out before the participant leaves.
    std::thread::sleep(Duration::from_millis(500));
    let published: BTreeMap<&str, u64> = streams
        .iter()
        .map(|s| (s.topic.as_str(), s.count))
        .collect();
    let failed: BTreeMap<&str, u64> = streams
        .iter()
        .map(|s| (s.topic.as_str(), s.failed))
        .collect();
    println!(
        "{}",
        serde_json::json!({"published": published, "failed": failed, "seconds": seconds})
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn image_pattern_encodes_the_frame_number() {
        let data = image_data(10, 300);
        assert_eq!(data[0], (300 % 256) as u8);
        assert_eq!(data[1], ((7 + 300) % 256) as u8);
    }
}
