//! The recorder node: raw subscriptions on one receive thread (woken by DDS, never blocked by the
//! disk), episode control from events and services, and the writer thread that owns the bag.
//!
//! - `inputs`: the subscriptions and what they feed the writer (I/O), on `intake`'s arithmetic
//!   (timestamps, log times, reader depths, loss counts; pure).
//! - `control`: episode events, verdicts and services (I/O), on `episode_commands`' rules (what
//!   each becomes for the writer, in which order, answered how; pure).
//! - `readiness`: whether the inputs receive every publisher of what they record (pure), for
//!   /recorder/ready.
//! - `writer`: the thread that carries the commands out on the bag.

mod control;
mod episode_commands;
mod inputs;
mod intake;
mod readiness;
mod writer;

use std::{
    sync::{mpsc::sync_channel, Arc},
    time::{Duration, Instant},
};

use anyhow::{Context as _, Result};
use so101_core::ros::{parameters::ParameterServer, shutdown::Shutdown, RosNode};

use self::{
    control::{Control, REPLY_TIMEOUT},
    inputs::Inputs,
    writer::{now_ns, Command, QueueBudget},
};
use crate::{
    bag::{BagOptions, BagWriter},
    cli::{seconds, Args},
    episodes::StartOptions,
    parameters::{self, SelectionOptions},
};

/// Commands waiting for the writer thread, at most (besides the byte budget).
const QUEUE_LEN: usize = 65_536;
const DISCOVERY_PERIOD: Duration = Duration::from_secs(1);

/// Runs the recorder until a signal or --duration.
pub fn run(args: Args) -> Result<()> {
    let shutdown = Shutdown::on_signals().context("cannot install the signal handlers")?;
    let mut node = RosNode::start("recorder_node", &args.node)?;
    let namespace = node.names().namespace().to_owned();
    let mut selection_options = SelectionOptions::from_args(&args);
    let selection = selection_options.selection(&namespace)?;
    let parameters = ParameterServer::start(&mut node, parameters::declarations(&args))?;
    let bag = BagWriter::new(BagOptions {
        output: args.output.clone(),
        prefix: args.prefix.clone(),
        compression: args.compression.to_mcap(),
        chunk_size: args.chunk_size,
        max_chunk_age: seconds(args.max_chunk_age),
        split_size: args.split_size_mb.map(|mb| (mb * 1e6) as u64),
        split_duration: args.split_duration.map(seconds),
        default_task: args.task.clone(),
    })
    .with_context(|| format!("cannot record into {}", args.output.display()))?;
    let budget = Arc::new(QueueBudget::new((args.queue_mb * 1e6) as u64));
    let (sender, receiver) = sync_channel(QUEUE_LEN);
    let writer = writer::spawn(bag, receiver, Arc::clone(&budget))?;
    let mut control = Control::serve(&mut node)?;
    let mut inputs = Inputs::new(&node, selection)?;
    if args.topics.is_empty() && !args.all && args.patterns.is_empty() {
        inputs.subscribe_fixed_defaults(&mut node, &sender)?;
    }
    tracing::info!(output = %args.output.display(), compression = ?args.compression, "recorder ready");
    if args.start {
        let (reply, answer) = sync_channel(1);
        sender
            .send(Command::Start(
                StartOptions::default(),
                now_ns(),
                None,
                Some(reply),
            ))
            .map_err(|_| anyhow::anyhow!("the writer thread is gone"))?;
        let started = answer
            .recv_timeout(REPLY_TIMEOUT)
            .unwrap_or_else(|_| Err("the writer did not answer in time".to_owned()));
        let message =
            started.map_err(|error| anyhow::anyhow!("cannot start recording: {error}"))?;
        tracing::info!("{message}");
    }
    let deadline = args.duration.map(|s| Instant::now() + seconds(s));
    let mut next_discovery = Instant::now();
    while !shutdown.is_requested() && deadline.is_none_or(|d| Instant::now() < d) {
        if Instant::now() >= next_discovery {
            next_discovery = Instant::now() + DISCOVERY_PERIOD;
            inputs.discover(&mut node, &sender);
        }
        let changes = parameters.changes();
        if changes
            .iter()
            .any(|change| selection_options.apply(&change.name, &change.value))
        {
            match selection_options.selection(&namespace) {
                Ok(selection) => {
                    inputs.select(selection);
                    next_discovery = Instant::now();
                }
                Err(error) => tracing::warn!(%error, "topic selection unchanged"),
            }
        }
        control.take(&sender);
        let asked = control.ready_requests();
        if !asked.is_empty() {
            // Publishers found since the last discovery get their readers now, not a second later.
            inputs.discover(&mut node, &sender);
            control.answer_ready_requests(asked, &inputs.readiness(&node));
        }
        inputs.receive(&sender, &budget);
    }
    let _ = sender.send(control.shutdown());
    drop(sender);
    writer
        .join()
        .map_err(|_| anyhow::anyhow!("the writer thread panicked"))?;
    tracing::info!(dropped = inputs.losses.total, "recorder stopped");
    Ok(())
}
