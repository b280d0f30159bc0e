//! Measures command -> joint_state reaction latency of a node that follows the topic contract (the
//! simulation or the driver): publish a /joint_commands message, wait for the first /joint_states
//! message that arrives after it, repeat. Prints one JSON line with the percentiles.
//!
//! Must run in the same private network namespace as the node under test.

use so101_core::contract::topics;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use clap::Parser;
use so101_core::{
    robot::JOINT_NAMES,
    ros::{logging, qos, NodeArgs, RosNode},
};
use so101_msgs::sensor_msgs::JointState;

/// Command -> /joint_states reaction latency of an SO-101 node, as percentiles in microseconds.
#[derive(Debug, Parser)]
#[command(version, about)]
struct Args {
    /// Number of measured round trips.
    #[arg(long, default_value_t = 500, value_parser = clap::value_parser!(u32).range(1..))]
    samples: u32,
    /// Round trips done first and not counted (discovery, caches).
    #[arg(long, default_value_t = 50)]
    warmup: usize,
    /// Pause before each command, spread evenly over 0..JITTER seconds, so commands land at every
    /// phase of the node's control period instead of locking onto it.
    #[arg(long, default_value_t = 0.01)]
    jitter: f64,
    /// Seconds to wait for the node's /joint_states before giving up.
    #[arg(long, default_value_t = 20.0)]
    discovery_timeout: f64,
    #[command(flatten)]
    node: NodeArgs,
}

fn main() -> Result<()> {
    logging::init();
    let args = Args::parse();
    let mut node = RosNode::start("so101_latency_probe", &args.node)?;
    let commands = node.publisher::<JointState>(topics::JOINT_COMMANDS, qos::default_topic())?;
    let states = node.subscription::<JointState>(topics::JOINT_STATES, qos::reliable(100))?;

    let discovery_deadline = Instant::now() + Duration::from_secs_f64(args.discovery_timeout);
    while states.take()?.is_none() {
        if Instant::now() > discovery_deadline {
            bail!(
                "no /joint_states within {} s: is the node running in this namespace?",
                args.discovery_timeout
            );
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    // Give the node's command subscription time to match our publisher.
    std::thread::sleep(Duration::from_millis(500));

    let mut latencies = Vec::with_capacity(args.samples as usize);
    for round in 0..args.warmup + args.samples as usize {
        // Golden-ratio sequence: evenly spread pauses without a random generator.
        let phase = (round as f64 * 0.618_033_988_75).fract();
        std::thread::sleep(Duration::from_secs_f64(args.jitter.max(0.0) * phase));
        while states.take()?.is_some() {}
        let command = JointState {
            name: vec![JOINT_NAMES[5].to_owned()],
            position: vec![if round % 2 == 0 { 0.3 } else { 0.5 }],
            ..Default::default()
        };
        let sent = Instant::now();
        commands
            .publish(command)
            .map_err(|error| anyhow::anyhow!("publish failed: {error:?}"))?;
        // Wait on the reader's event, not a busy loop: the node under test needs the other core.
        let received = smol::block_on(smol::future::or(
            async { Some(states.async_take().await) },
            async {
                smol::Timer::after(Duration::from_secs(2)).await;
                None
            },
        ));
        match received {
            Some(result) => drop(result.context("reading /joint_states")?),
            None => bail!("no /joint_states within 2 s of a command (round {round})"),
        }
        if round >= args.warmup {
            latencies.push(sent.elapsed().as_secs_f64() * 1e6);
        }
    }
    latencies.sort_by(f64::total_cmp);
    let percentile = |p: f64| latencies[((latencies.len() - 1) as f64 * p).round() as usize];
    println!(
        "{{\"client\": \"rust\", \"samples\": {}, \"p50_us\": {:.1}, \"p99_us\": {:.1}, \"max_us\": {:.1}}}",
        latencies.len(),
        percentile(0.5),
        percentile(0.99),
        percentile(1.0)
    );
    Ok(())
}
