//! bag_write_bench: the recorder's writing side alone, for docs/benchmarks.md. Loads every message
//! of an existing bag into memory, then times writing them through the recorder's `BagWriter`
//! (same options as the node) into a new episode, fsync included; or, with `--mode raw`, the same
//! message bytes written sequentially to one file through a reused 1 MiB buffer, fsync: the anchor. Prints one
//! JSON line: `{"seconds": S, "bytes": B, "messages": N}` (B = message bytes written).

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
    #[arg(long, value_enum, default_value = "bag")]
    mode: Mode,
    /// Leave the data in the page cache (measures the writer, not the disk).
    #[arg(long)]
    no_fsync: bool,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum Mode {
    /// Through the recorder's BagWriter.
    Bag,
    /// The message bytes alone, one sequential file.
    Raw,
}

/// Writes the bytes of every message one after the other through a reused 1 MiB buffer, as `dd`
/// or any plain sequential writer does (the MCAP writers also copy into a reused chunk buffer;
/// writing straight out of one huge fresh buffer is several times slower on this machine).
fn write_raw(messages: &[Message], output: &std::path::Path, fsync: bool) -> Result<f64> {
    use std::io::Write;
    const BLOCK: usize = 1 << 20;
    std::fs::create_dir_all(output)?;
    let started = Instant::now();
    let mut file = std::fs::File::create(output.join("raw.bin"))?;
    let mut block = Vec::with_capacity(BLOCK);
    for message in messages {
        block.extend_from_slice(&message.data);
        if block.len() >= BLOCK {
            file.write_all(&block)?;
            block.clear();
        }
    }
    file.write_all(&block)?;
    if fsync {
        file.sync_all()?;
    }
    Ok(started.elapsed().as_secs_f64())
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
    let total: usize = messages.iter().map(|m| m.data.len()).sum();
    if args.mode == Mode::Raw {
        let seconds = write_raw(&messages, &args.output, !args.no_fsync)?;
        println!(
            "{}",
            serde_json::json!({"seconds": seconds, "bytes": total, "messages": messages.len()})
        );
        return Ok(());
    }
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
    let started = Instant::now();
    let dir = bag.start(StartOptions::default(), 0, None)?;
    for message in &messages {
        bag.write(message);
        bag.tick();
    }
    bag.stop(messages.last().map_or(0, |m| m.log_ns), None)?;
    if !args.no_fsync {
        for entry in std::fs::read_dir(&dir)? {
            std::fs::File::open(entry?.path())?.sync_all()?;
        }
    }
    let seconds = started.elapsed().as_secs_f64();
    println!(
        "{}",
        serde_json::json!({"seconds": seconds, "bytes": total, "messages": messages.len()})
    );
    Ok(())
}
