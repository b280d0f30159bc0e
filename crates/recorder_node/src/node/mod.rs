//! The recorder node: raw subscriptions on one receive thread (woken by DDS, never blocked by the
//! disk), episode control from events and services, and the writer thread that owns the bag.

use so101_core::contract::{services, topics};
use std::{
    collections::HashSet,
    sync::{
        atomic::{AtomicU64, Ordering},
        mpsc::{sync_channel, Receiver, RecvTimeoutError, SyncSender, TrySendError},
        Arc,
    },
    thread::JoinHandle,
    time::{Duration, Instant, SystemTime, UNIX_EPOCH},
};

use anyhow::{Context as _, Result};
use ros2_client::{QosProfile, Server, Subscription};
use rustdds::{
    mio::{Events, Poll, PollOpt, Ready, Token},
    no_key::SimpleDataReader,
    Timestamp,
};
use so101_core::ros::{
    parameters::ParameterServer, qos, rate_limit::RateLimiter, shutdown::Shutdown, RosNode,
};
use so101_msgs::{
    std_msgs::{Bool, String as StringMessage},
    std_srvs::{SetBool, SetBoolRequest, Trigger, TriggerRequest, TriggerResponse},
    TypeInfo,
};

use crate::{
    bag::{BagOptions, BagWriter, Message, TopicInfo},
    cli::{seconds, Args},
    episodes::{parse_event, EpisodeEvent, StartOptions},
    gaps::GapTracker,
    metadata::QosSummary,
    parameters::{self, SelectionOptions},
    raw::{RawAdapter, SerializedMessage},
    topics::{known_type, ros_topic_name, ros_type_name, Selection, DEFAULT_FIXED},
};

/// Commands waiting for the writer thread, at most (besides the byte budget).
const QUEUE_LEN: usize = 65_536;
/// Reader history depth: enough for bursts while the receive thread is busy. Images are large,
/// so their readers keep fewer.
const DEPTH: usize = 1000;
const IMAGE_DEPTH: usize = 64;
const DISCOVERY_PERIOD: Duration = Duration::from_secs(1);
const RECEIVE_WAIT: Duration = Duration::from_millis(20);
/// How long a service call waits for the writer thread's answer.
const REPLY_TIMEOUT: Duration = Duration::from_secs(5);

type Reply = SyncSender<Result<String, String>>;

enum Command {
    Topic(TopicInfo),
    Message(Message),
    /// Start options, time, the success hint for an episode this start ends, reply.
    Start(StartOptions, u64, Option<bool>, Option<Reply>),
    Stop(u64, Option<bool>, Option<Reply>),
    Mark(bool, Option<Reply>),
    Discard(Option<Reply>),
    DiscardLast(Option<Reply>),
    Dropped(u64),
    /// A /sim/episode message: the simulation's settings for the episode.
    Simulation(String),
    Shutdown(Option<bool>),
}

/// Bytes of messages in the queue, against a limit: the receive path never waits for the disk.
struct QueueBudget {
    bytes: AtomicU64,
    limit: u64,
}

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
    let budget = Arc::new(QueueBudget {
        bytes: AtomicU64::new(0),
        limit: (args.queue_mb * 1e6) as u64,
    });
    let (sender, receiver) = sync_channel(QUEUE_LEN);
    let writer = spawn_writer(bag, receiver, Arc::clone(&budget))?;
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
        inputs.receive(&sender, &budget);
    }
    let _ = sender.send(Command::Shutdown(control.last_task_success));
    drop(sender);
    writer
        .join()
        .map_err(|_| anyhow::anyhow!("the writer thread panicked"))?;
    tracing::info!(dropped = inputs.dropped, "recorder stopped");
    Ok(())
}

/// Wall clock in ns since the epoch (log time of messages, episode times).
fn now_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64)
}

fn ns_from_timestamp(timestamp: Timestamp) -> u64 {
    let ticks = timestamp.to_ticks();
    (ticks >> 32) * 1_000_000_000 + (((ticks & 0xFFFF_FFFF) * 1_000_000_000) >> 32)
}

fn spawn_writer(
    mut bag: BagWriter,
    commands: Receiver<Command>,
    budget: Arc<QueueBudget>,
) -> Result<JoinHandle<()>> {
    std::thread::Builder::new()
        .name("bag writer".into())
        .spawn(move || loop {
            match commands.recv_timeout(Duration::from_millis(100)) {
                Ok(Command::Message(message)) => {
                    budget
                        .bytes
                        .fetch_sub(message.data.len() as u64, Ordering::Relaxed);
                    bag.write(&message);
                }
                Ok(Command::Topic(topic)) => bag.add_topic(topic),
                Ok(Command::Start(options, at, hint, reply)) => answer(
                    reply,
                    bag.start(options, at, hint)
                        .map(|dir| format!("recording into {}", dir.display())),
                ),
                Ok(Command::Stop(at, hint, reply)) => answer(
                    reply,
                    bag.stop(at, hint).map(|info| {
                        format!(
                            "episode {} stopped (success: {})",
                            info.index,
                            info.success.map_or("unknown".into(), |s| s.to_string())
                        )
                    }),
                ),
                Ok(Command::Mark(success, reply)) => answer(
                    reply,
                    bag.mark(success)
                        .map(|index| format!("episode {index} marked success={success}")),
                ),
                Ok(Command::Discard(reply)) => answer(
                    reply,
                    bag.discard()
                        .map(|index| format!("episode {index} discarded")),
                ),
                Ok(Command::DiscardLast(reply)) => answer(
                    reply,
                    bag.discard_last()
                        .map(|index| format!("closed episode {index} discarded")),
                ),
                Ok(Command::Dropped(count)) => bag.add_dropped(count),
                Ok(Command::Simulation(settings)) => bag.set_simulation(settings),
                Ok(Command::Shutdown(hint)) => {
                    if bag.is_recording() {
                        if let Err(error) = bag.stop(now_ns(), hint) {
                            tracing::error!(%error, "closing the last episode failed");
                        }
                    }
                    return;
                }
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => return,
            }
            bag.tick();
        })
        .context("cannot start the writer thread")
}

fn answer<E: std::fmt::Display>(reply: Option<Reply>, result: Result<String, E>) {
    let result = result.map_err(|error| error.to_string());
    match (&result, reply) {
        (_, Some(reply)) => {
            let _ = reply.send(result);
        }
        (Err(error), None) => tracing::warn!(%error, "episode command failed"),
        (Ok(_), None) => {}
    }
}

/// The QoS the recorder subscribes with: reliable (lossless), volatile, a deep history.
fn reader_qos(depth: usize) -> QosProfile {
    qos::reliable(depth)
}

struct Input {
    topic: usize,
    name: String,
    reader: SimpleDataReader<SerializedMessage, RawAdapter>,
    /// Whether the selection still wants it (its samples are taken either way, written only then).
    recording: bool,
    /// Log time of the last sample taken: RustDDS's receive instants can step back by
    /// microseconds when samples arrive reordered, and a topic's log times must not.
    last_log_ns: u64,
}

/// The raw subscriptions and their wake-up.
struct Inputs {
    subscriber: rustdds::Subscriber,
    poll: Poll,
    events: Events,
    inputs: Vec<Input>,
    /// Topic names already subscribed or refused.
    seen: HashSet<String>,
    selection: Selection,
    gaps: GapTracker,
    dropped: u64,
    /// Losses not yet handed to the writer (its queue was full).
    unreported: u64,
    warnings: RateLimiter,
}

impl Inputs {
    fn new(node: &RosNode, selection: Selection) -> Result<Self> {
        let subscriber = node
            .context()
            .domain_participant()
            .create_subscriber(&(&reader_qos(DEPTH)).into())
            .map_err(|error| anyhow::anyhow!("cannot create the DDS subscriber: {error:?}"))?;
        Ok(Self {
            subscriber,
            poll: Poll::new().context("cannot create the receive poll")?,
            events: Events::with_capacity(256),
            inputs: Vec::new(),
            seen: HashSet::new(),
            selection,
            gaps: GapTracker::default(),
            dropped: 0,
            unreported: 0,
            warnings: RateLimiter::new(Duration::from_secs(2)),
        })
    }

    fn subscribe_fixed_defaults(
        &mut self,
        node: &mut RosNode,
        commands: &SyncSender<Command>,
    ) -> Result<()> {
        for (relative, type_name) in DEFAULT_FIXED {
            let name = node.names().resolve(relative);
            if !self.selection.wants(&name) {
                continue;
            }
            if let Some(info) = known_type(type_name) {
                self.subscribe(node, &name, info, commands)?;
            }
        }
        Ok(())
    }

    /// Subscribes to newly discovered topics the selection wants.
    fn discover(&mut self, node: &mut RosNode, commands: &SyncSender<Command>) {
        for topic in node.context().discovered_topics() {
            let (Some(name), Some(type_name)) =
                (ros_topic_name(&topic.name), ros_type_name(&topic.type_name))
            else {
                continue;
            };
            if self.seen.contains(&name) || !self.selection.wants(&name) {
                continue;
            }
            match known_type(&type_name) {
                Some(info) => {
                    if let Err(error) = self.subscribe(node, &name, info, commands) {
                        // Said once: retrying every second would only repeat it.
                        self.seen.insert(name.clone());
                        tracing::warn!(topic = %name, %error, "cannot subscribe");
                    }
                }
                None => {
                    self.seen.insert(name.clone());
                    tracing::warn!(
                        topic = %name,
                        r#type = %type_name,
                        "not recorded: the recorder has no definition of this type to write its schema"
                    );
                }
            }
        }
    }

    fn subscribe(
        &mut self,
        node: &mut RosNode,
        name: &str,
        info: &'static TypeInfo,
        commands: &SyncSender<Command>,
    ) -> Result<()> {
        let depth = if info.name.contains("Image") {
            IMAGE_DEPTH
        } else {
            DEPTH
        };
        let qos = reader_qos(depth);
        let topic_name = node.names().name(name)?;
        let topic = node
            .node()
            .create_topic(&topic_name, info.message_type_name(), &qos)
            .map_err(|error| anyhow::anyhow!("cannot create topic {name}: {error:?}"))?;
        let reader = self
            .subscriber
            .create_simple_datareader_no_key::<SerializedMessage, RawAdapter>(
                &topic,
                Some((&qos).into()),
            )
            .map_err(|error| anyhow::anyhow!("cannot subscribe {name}: {error:?}"))?;
        let index = self.inputs.len();
        self.poll
            .register(&reader, Token(index), Ready::readable(), PollOpt::edge())
            .with_context(|| format!("cannot watch {name}"))?;
        // The writer learns the topic before any of its messages (same queue, in order).
        commands
            .send(Command::Topic(TopicInfo {
                name: name.to_owned(),
                type_name: info.full_name(),
                schema: info.ros2msg_schema(),
                qos: QosSummary {
                    reliable: true,
                    depth,
                },
            }))
            .map_err(|_| anyhow::anyhow!("the writer thread is gone"))?;
        self.seen.insert(name.to_owned());
        self.inputs.push(Input {
            topic: index,
            name: name.to_owned(),
            reader,
            recording: true,
            last_log_ns: 0,
        });
        tracing::info!(topic = name, r#type = %info.full_name(), "recording topic");
        Ok(())
    }

    /// A new selection: subscribed topics it no longer wants stop being written (and start again
    /// if wanted later); the next discovery subscribes the topics it newly wants.
    fn select(&mut self, selection: Selection) {
        for input in &mut self.inputs {
            let recording = selection.wants(&input.name);
            if recording != input.recording {
                tracing::info!(topic = %input.name, recording, "topic selection changed");
            }
            input.recording = recording;
        }
        self.selection = selection;
    }

    /// Waits for data (at most RECEIVE_WAIT) and hands every sample to the writer.
    fn receive(&mut self, commands: &SyncSender<Command>, budget: &QueueBudget) {
        if let Err(error) = self.poll.poll(&mut self.events, Some(RECEIVE_WAIT)) {
            tracing::warn!(%error, "receive poll failed");
            std::thread::sleep(RECEIVE_WAIT);
        }
        let mut lost = 0;
        for input in &mut self.inputs {
            input.reader.drain_read_notifications();
            loop {
                let change = match input.reader.try_take_one() {
                    Ok(Some(change)) => change,
                    Ok(None) => break,
                    Err(error) => {
                        if let Some(suppressed) = self.warnings.check(Instant::now()) {
                            tracing::warn!(topic = %input.name, ?error, suppressed, "bad sample");
                        }
                        break;
                    }
                };
                lost += self.gaps.observe(
                    input.topic,
                    change.writer_guid.to_bytes(),
                    i64::from(change.sequence_number),
                );
                if !input.recording {
                    continue;
                }
                let log_ns = ns_from_timestamp(change.receive_instant).max(input.last_log_ns);
                input.last_log_ns = log_ns;
                let publish_ns = change.source_timestamp().map_or(log_ns, ns_from_timestamp);
                let data = change.sample.0;
                let size = data.len() as u64;
                if budget.bytes.load(Ordering::Relaxed) + size > budget.limit {
                    lost += 1;
                    continue;
                }
                budget.bytes.fetch_add(size, Ordering::Relaxed);
                let message = Command::Message(Message {
                    topic: input.topic,
                    data,
                    log_ns,
                    publish_ns,
                });
                if let Err(TrySendError::Full(_) | TrySendError::Disconnected(_)) =
                    commands.try_send(message)
                {
                    budget.bytes.fetch_sub(size, Ordering::Relaxed);
                    lost += 1;
                }
            }
        }
        if lost > 0 {
            self.dropped += lost;
            if let Some(suppressed) = self.warnings.check(Instant::now()) {
                tracing::warn!(
                    lost,
                    total = self.dropped,
                    suppressed,
                    "messages lost (sequence gaps or a full writer queue)"
                );
            }
            // Never wait here: what does not fit now is reported with the next loss.
            self.unreported += lost;
            if commands.try_send(Command::Dropped(self.unreported)).is_ok() {
                self.unreported = 0;
            }
        }
    }
}

/// Episode control: /episode/events, /task/success (the default for an unmarked episode) and the
/// recorder's services. Nothing here waits for the writer: events are sent and forgotten, service
/// calls are answered once the writer's reply arrives, on a later turn of the loop.
struct Control {
    events: Subscription<StringMessage>,
    simulation: Subscription<StringMessage>,
    task_success: Subscription<Bool>,
    start: Server<TriggerRequest, TriggerResponse>,
    stop: Server<TriggerRequest, TriggerResponse>,
    discard: Server<TriggerRequest, TriggerResponse>,
    discard_last: Server<TriggerRequest, TriggerResponse>,
    mark_success: Server<SetBoolRequest, TriggerResponse>,
    last_task_success: Option<bool>,
    pending: Vec<PendingCall>,
    warnings: RateLimiter,
}

#[derive(Clone, Copy)]
enum Service {
    Start,
    Stop,
    Discard,
    DiscardLast,
    MarkSuccess,
}

/// A service call waiting for the writer's answer.
struct PendingCall {
    service: Service,
    id: ros2_client::RmwRequestId,
    answer: Receiver<Result<String, String>>,
    deadline: Instant,
}

impl Control {
    fn serve(node: &mut RosNode) -> Result<Self> {
        Ok(Self {
            events: node.subscription(topics::EPISODE_EVENTS, qos::command_subscription())?,
            simulation: node.subscription(topics::SIM_EPISODE, qos::latched())?,
            task_success: node.subscription(topics::TASK_SUCCESS, qos::command_subscription())?,
            start: node.server::<Trigger>(services::RECORDER_START)?,
            stop: node.server::<Trigger>(services::RECORDER_STOP)?,
            discard: node.server::<Trigger>(services::RECORDER_DISCARD)?,
            discard_last: node.server::<Trigger>(services::RECORDER_DISCARD_LAST)?,
            mark_success: node.server::<SetBool>(services::RECORDER_MARK_SUCCESS)?,
            last_task_success: None,
            pending: Vec::new(),
            warnings: RateLimiter::new(Duration::from_secs(1)),
        })
    }

    fn take(&mut self, commands: &SyncSender<Command>) {
        while let Ok(Some((message, _))) = self.task_success.take() {
            self.last_task_success = Some(message.data);
        }
        while let Ok(Some((message, _))) = self.events.take() {
            match parse_event(&message.data) {
                Ok(event) => self.apply(event, commands, None),
                Err(error) => {
                    if let Some(suppressed) = self.warnings.check(Instant::now()) {
                        tracing::warn!(suppressed, "episode event ignored: {error}");
                    }
                }
            }
        }
        // After the events: a reset's settings come after the event that closed the episode before
        // it (teleop marks the end, then resets), and belong to the next one.
        while let Ok(Some((message, _))) = self.simulation.take() {
            if commands.send(Command::Simulation(message.data)).is_err() {
                tracing::error!("the writer thread is gone: the simulation's settings were lost");
            }
        }
        // Calls on different services carry no common order; this one makes "mark, then stop"
        // and "stop, then start" do what they say.
        let mut calls: Vec<(Service, ros2_client::RmwRequestId, EpisodeEvent)> = Vec::new();
        while let Ok(Some((id, request))) = self.mark_success.receive_request() {
            let event = if request.data {
                EpisodeEvent::Success
            } else {
                EpisodeEvent::Failure
            };
            calls.push((Service::MarkSuccess, id, event));
        }
        for id in take_trigger(&self.stop) {
            calls.push((Service::Stop, id, EpisodeEvent::Stop));
        }
        for id in take_trigger(&self.discard) {
            calls.push((Service::Discard, id, EpisodeEvent::Discard));
        }
        for id in take_trigger(&self.discard_last) {
            calls.push((Service::DiscardLast, id, EpisodeEvent::DiscardLast));
        }
        for id in take_trigger(&self.start) {
            calls.push((
                Service::Start,
                id,
                EpisodeEvent::Start(StartOptions::default()),
            ));
        }
        for (service, id, event) in calls {
            let (reply, answer) = sync_channel(1);
            self.apply(event, commands, Some(reply));
            self.pending.push(PendingCall {
                service,
                id,
                answer,
                deadline: Instant::now() + REPLY_TIMEOUT,
            });
        }
        self.answer_ready();
    }

    /// Answers the service calls whose reply from the writer has arrived (or is overdue).
    fn answer_ready(&mut self) {
        let now = Instant::now();
        let mut still_waiting = Vec::new();
        for call in std::mem::take(&mut self.pending) {
            let result = match call.answer.try_recv() {
                Ok(result) => result,
                Err(std::sync::mpsc::TryRecvError::Empty) if now < call.deadline => {
                    still_waiting.push(call);
                    continue;
                }
                Err(_) => Err("the writer did not answer in time".to_owned()),
            };
            match &result {
                Ok(message) => tracing::info!("{message}"),
                Err(error) => tracing::warn!("{error}"),
            }
            match call.service {
                Service::Start => respond(&self.start, call.id, result),
                Service::Stop => respond(&self.stop, call.id, result),
                Service::Discard => respond(&self.discard, call.id, result),
                Service::DiscardLast => respond(&self.discard_last, call.id, result),
                Service::MarkSuccess => respond(&self.mark_success, call.id, result),
            }
        }
        self.pending = still_waiting;
    }

    /// Hands an episode event to the writer, in order with the messages already queued.
    fn apply(&mut self, event: EpisodeEvent, commands: &SyncSender<Command>, reply: Option<Reply>) {
        let command = match event {
            EpisodeEvent::Start(options) => {
                let hint = self.last_task_success.take();
                Command::Start(options, now_ns(), hint, reply)
            }
            EpisodeEvent::Stop => Command::Stop(now_ns(), self.last_task_success, reply),
            EpisodeEvent::Success => Command::Mark(true, reply),
            EpisodeEvent::Failure => Command::Mark(false, reply),
            EpisodeEvent::Discard => Command::Discard(reply),
            EpisodeEvent::DiscardLast => Command::DiscardLast(reply),
            EpisodeEvent::Rerecord => {
                if commands.send(Command::Discard(None)).is_err() {
                    return;
                }
                self.last_task_success = None;
                Command::Start(StartOptions::default(), now_ns(), None, reply)
            }
        };
        if commands.send(command).is_err() {
            tracing::error!("the writer thread is gone: an episode event was lost");
        }
    }
}

fn take_trigger(
    server: &Server<TriggerRequest, TriggerResponse>,
) -> Vec<ros2_client::RmwRequestId> {
    std::iter::from_fn(|| match server.receive_request() {
        Ok(Some((id, _))) => Some(id),
        _ => None,
    })
    .collect()
}

fn respond<Q: ros2_client::Message + 'static>(
    server: &Server<Q, TriggerResponse>,
    id: ros2_client::RmwRequestId,
    result: Result<String, String>,
) {
    let response = match result {
        Ok(message) => TriggerResponse {
            success: true,
            message,
        },
        Err(message) => TriggerResponse {
            success: false,
            message,
        },
    };
    if let Err(error) = server.send_response(id, response) {
        tracing::warn!(?error, "cannot answer a recorder service call");
    }
}
