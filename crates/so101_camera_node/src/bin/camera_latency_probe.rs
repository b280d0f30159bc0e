//! camera_latency_probe: a Rust subscriber of one camera's JPEG frames for the camera benchmark
//! (so101-bench camera_node): for --seconds it receives camera/NAME/image_raw/compressed and
//! prints, as one JSON line, how many frames came and their capture-to-subscriber latency (the
//! instant each arrived minus its header stamp, the capture instant), p50 and p99 in ms.

use std::{
    process::ExitCode,
    time::{Duration, Instant},
};

use anyhow::Result;
use clap::Parser;
use so101_camera_node::status::{quantile, sorted};
use so101_core::{
    contract::topics,
    ros::{logging, qos, NodeArgs, RosNode},
};
use so101_msgs::{builtin_interfaces::Time, sensor_msgs::CompressedImage};

/// Receives one camera's JPEG frames for --seconds and prints their count and capture-to-subscriber
/// latency (p50, p99) as JSON.
#[derive(Debug, Parser)]
#[command(version, about, long_about = None)]
struct Args {
    /// The camera's name (camera/NAME/image_raw/compressed).
    #[arg(long, default_value = "top")]
    camera: String,
    /// How long to receive, s (after the first frame).
    #[arg(long, default_value_t = 10.0)]
    seconds: f64,
    #[command(flatten)]
    node: NodeArgs,
}

fn main() -> ExitCode {
    logging::init();
    logging::exit_code(run(Args::parse()))
}

fn run(args: Args) -> Result<()> {
    let mut node = RosNode::start("camera_latency_probe", &args.node)?;
    let frames = node.subscription::<CompressedImage>(
        &topics::camera(&args.camera, topics::IMAGE_COMPRESSED),
        qos::default_topic(),
    )?;
    let mut latencies_ms: Vec<f64> = Vec::new();
    let mut first: Option<Instant> = None;
    let give_up = Instant::now() + Duration::from_secs(60);
    while first.is_none_or(|at| at.elapsed().as_secs_f64() < args.seconds)
        && Instant::now() < give_up
    {
        match frames.take() {
            Ok(Some((message, _))) => {
                let arrived = Time::now().as_secs_f64();
                first.get_or_insert_with(Instant::now);
                latencies_ms.push((arrived - message.header.stamp.as_secs_f64()) * 1e3);
            }
            _ => std::thread::sleep(Duration::from_micros(200)),
        }
    }
    let latencies_ms = sorted(latencies_ms);
    let ms = |q: f64| quantile(&latencies_ms, q).map_or("null".into(), |v| format!("{v:.3}"));
    println!(
        "{{\"frames\": {}, \"p50_ms\": {}, \"p99_ms\": {}}}",
        latencies_ms.len(),
        ms(0.5),
        ms(0.99),
    );
    Ok(())
}
