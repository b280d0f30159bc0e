//! bag_write_bench: the recorder's writing side alone, for docs/benchmarks.md. Loads every message
//! of an existing bag into memory, then times writing them through the recorder's `BagWriter`
//! (same options as the node) into a new episode, fsync included. Prints one JSON line:
//! `{"seconds": S, "bytes": B, "messages": N}` (B = message bytes written).

use std::{
    path::PathBuf,
    process::ExitCode,
    time::{Duration, Instant},
};

use anyhow::{Context, Result};
use clap::Parser;
use recorder_node::{
    bag::{BagOptions, BagWriter, Message, TopicInfo},
    cli::CompressionArg,
    episodes::StartOptions,
    metadata::QosSummary,
};

/// Times the recorder's bag writer on the messages of an existing bag.
#[derive(Debug, Parser)]
#[command(version)]
struct Args {
    /// A bag file (.mcap) whose messages are written again.
    #[arg(long)]
    input: PathBuf,
    /// Directory for the new episode.
    #[arg(long)]
    output: PathBuf,
    #[arg(long, value_enum, default_value = "none")]
    compression: CompressionArg,
    #[arg(long, default_value_t = 1 << 20)]
    chunk_size: u64,
}

fn main() -> ExitCode {
    match run(Args::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("bag_write_bench: {error:#}");
            ExitCode::FAILURE
        }
    }
}

fn run(args: Args) -> Result<()> {
    let bytes = std::fs::read(&args.input)
        .with_context(|| format!("cannot read {}", args.input.display()))?;
    let mut topics: Vec<TopicInfo> = Vec::new();
    let mut messages = Vec::new();
    for message in mcap::MessageStream::new(&bytes)? {
        let message = message?;
        let channel = &message.channel;
        let topic = match topics.iter().position(|t| t.name == channel.topic) {
            Some(index) => index,
            None => {
                let schema = channel
                    .schema
                    .as_ref()
                    .context("a channel without schema")?;
                topics.push(TopicInfo {
                    name: channel.topic.clone(),
                    type_name: schema.name.clone(),
                    schema: String::from_utf8_lossy(&schema.data).into_owned(),
                    qos: QosSummary {
                        reliable: true,
                        depth: 10,
                    },
                });
                topics.len() - 1
            }
        };
        messages.push(Message {
            topic,
            data: message.data.into_owned(),
            log_ns: message.log_time,
            publish_ns: message.publish_time,
        });
    }
    drop(bytes);
    let mut bag = BagWriter::new(BagOptions {
        output: args.output.clone(),
        prefix: "bench".into(),
        compression: args.compression.to_mcap(),
        chunk_size: args.chunk_size,
        max_chunk_age: Duration::from_secs(1),
        split_size: None,
        split_duration: None,
        default_task: String::new(),
    })?;
    for topic in topics {
        bag.add_topic(topic);
    }
    let total: usize = messages.iter().map(|m| m.data.len()).sum();
    let started = Instant::now();
    let dir = bag.start(StartOptions::default(), 0)?;
    for message in &messages {
        bag.write(message);
        bag.tick();
    }
    bag.stop(messages.last().map_or(0, |m| m.log_ns), None)?;
    for entry in std::fs::read_dir(&dir)? {
        std::fs::File::open(entry?.path())?.sync_all()?;
    }
    let seconds = started.elapsed().as_secs_f64();
    println!(
        "{}",
        serde_json::json!({"seconds": seconds, "bytes": total, "messages": messages.len()})
    );
    Ok(())
}
