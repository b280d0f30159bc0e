//! The raw subscriptions: the topics the selection wants (found by discovery, or the fixed
//! defaults), read on the loop's thread as DDS wakes it, each sample handed to the writer as
//! wire bytes without waiting for it; and which discovered publishers each reader has matched.

use std::{
    collections::HashSet,
    sync::mpsc::{SyncSender, TrySendError},
    time::{Duration, Instant},
};

use anyhow::{Context as _, Result};
use ros2_client::QosProfile;
use rustdds::{
    mio::{Events, Poll, PollOpt, Ready, Token},
    no_key::SimpleDataReader,
    DataReaderStatus, RTPSEntity, StatusEvented, GUID,
};
use so101_core::ros::{qos, rate_limit::RateLimiter, RosNode};
use so101_msgs::{std_srvs::TriggerResponse, TypeInfo};

use super::{
    intake::{ns_from_ticks, reader_depth, LogClock, Losses, DEPTH},
    readiness::{self, Reception},
    writer::{Command, QueueBudget},
};
use crate::{
    bag::{Message, TopicInfo},
    gaps::GapTracker,
    metadata::QosSummary,
    raw::{RawAdapter, SerializedMessage},
    topics::{known_type, ros_topic_name, ros_type_name, Selection, DEFAULT_FIXED},
};

/// Longest wait for data in one turn of the loop.
const RECEIVE_WAIT: Duration = Duration::from_millis(20);

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
    log_clock: LogClock,
    /// The publishers this reader has matched, refused (incompatible QoS) or had a sample from.
    /// A sample counts too: RustDDS drops match events its small status queue has no room for.
    settled: HashSet<GUID>,
}

impl Input {
    /// Takes the reader's match events.
    fn take_statuses(&mut self) {
        while let Some(status) = self.reader.try_recv_status() {
            match status {
                DataReaderStatus::SubscriptionMatched {
                    current, writer, ..
                } => {
                    if current.count_change() > 0 {
                        self.settled.insert(writer);
                    } else {
                        self.settled.remove(&writer);
                    }
                }
                DataReaderStatus::RequestedIncompatibleQos { writer, .. }
                    if self.settled.insert(writer) =>
                {
                    tracing::warn!(
                        topic = %self.name,
                        ?writer,
                        "a publisher's QoS is not one the recorder (reliable) can take: its samples are not recorded"
                    );
                }
                _ => {}
            }
        }
    }
}

/// The raw subscriptions and their wake-up.
pub struct Inputs {
    subscriber: rustdds::Subscriber,
    poll: Poll,
    events: Events,
    inputs: Vec<Input>,
    /// Topic names already subscribed or refused.
    seen: HashSet<String>,
    selection: Selection,
    gaps: GapTracker,
    pub losses: Losses,
    warnings: RateLimiter,
}

impl Inputs {
    pub fn new(node: &RosNode, selection: Selection) -> Result<Self> {
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
            losses: Losses::default(),
            warnings: RateLimiter::new(Duration::from_secs(2)),
        })
    }

    pub fn subscribe_fixed_defaults(
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
    pub fn discover(&mut self, node: &mut RosNode, commands: &SyncSender<Command>) {
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
        let depth = reader_depth(info.name);
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
            log_clock: LogClock::default(),
            settled: HashSet::new(),
        });
        tracing::info!(topic = name, r#type = %info.full_name(), "recording topic");
        Ok(())
    }

    /// A new selection: subscribed topics it no longer wants stop being written (and start again
    /// if wanted later); the next discovery subscribes the topics it newly wants.
    pub fn select(&mut self, selection: Selection) {
        for input in &mut self.inputs {
            let recording = selection.wants(&input.name);
            if recording != input.recording {
                tracing::info!(topic = %input.name, recording, "topic selection changed");
            }
            input.recording = recording;
        }
        self.selection = selection;
    }

    /// /recorder/ready's answer: whether every publisher of a topic the selection wants reaches
    /// the recorder, else which topics wait (see `readiness`). Its own publishers (rosout,
    /// parameter events) do not count.
    pub fn readiness(&mut self, node: &RosNode) -> TriggerResponse {
        for input in &mut self.inputs {
            input.take_statuses();
        }
        let participant = node.context().domain_participant();
        let own = participant.guid().prefix;
        let publishers: Vec<(String, GUID)> = participant
            .discovered_writers()
            .into_iter()
            .map(|writer| writer.publication_topic_data)
            .filter(|publication| publication.key.prefix != own)
            .filter_map(|publication| {
                let name = ros_topic_name(&publication.topic_name)?;
                self.selection
                    .wants(&name)
                    .then_some((name, publication.key))
            })
            .collect();
        let receptions = publishers.iter().filter_map(|(name, writer)| {
            let reception = match self.inputs.iter().find(|input| &input.name == name) {
                Some(input) if input.settled.contains(writer) => Reception::Settled,
                Some(_) => Reception::Matching,
                // Refused once (a type without a definition, a failed subscription): never recorded.
                None if self.seen.contains(name) => return None,
                None => Reception::NotSubscribed,
            };
            Some((name.as_str(), reception))
        });
        readiness::answer(&readiness::waiting_topics(receptions))
    }

    /// Waits for data (at most RECEIVE_WAIT) and hands every sample to the writer.
    pub fn receive(&mut self, commands: &SyncSender<Command>, budget: &QueueBudget) {
        if let Err(error) = self.poll.poll(&mut self.events, Some(RECEIVE_WAIT)) {
            tracing::warn!(%error, "receive poll failed");
            std::thread::sleep(RECEIVE_WAIT);
        }
        let mut lost = 0;
        for input in &mut self.inputs {
            input.take_statuses();
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
                input.settled.insert(change.writer_guid);
                lost += self.gaps.observe(
                    input.topic,
                    change.writer_guid.to_bytes(),
                    i64::from(change.sequence_number),
                );
                if !input.recording {
                    continue;
                }
                let log_ns = input
                    .log_clock
                    .stamp(ns_from_ticks(change.receive_instant.to_ticks()));
                let publish_ns = change
                    .source_timestamp()
                    .map_or(log_ns, |stamp| ns_from_ticks(stamp.to_ticks()));
                let data = change.sample.0;
                let size = data.len() as u64;
                if !budget.try_reserve(size) {
                    lost += 1;
                    continue;
                }
                let message = Command::Message(Message {
                    topic: input.topic,
                    data,
                    log_ns,
                    publish_ns,
                });
                if let Err(TrySendError::Full(_) | TrySendError::Disconnected(_)) =
                    commands.try_send(message)
                {
                    budget.release(size);
                    lost += 1;
                }
            }
        }
        if lost > 0 {
            // Never wait here: what does not fit now is reported with the next loss.
            self.losses.add(lost, |unreported| {
                commands.try_send(Command::Dropped(unreported)).is_ok()
            });
            if let Some(suppressed) = self.warnings.check(Instant::now()) {
                tracing::warn!(
                    lost,
                    total = self.losses.total,
                    suppressed,
                    "messages lost (sequence gaps or a full writer queue)"
                );
            }
        }
    }
}
