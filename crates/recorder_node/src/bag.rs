//! Writing episodes as rosbag2 MCAP bags: one directory per episode with its .mcap file(s) and
//! metadata.yaml, split by size or duration, chunked and optionally compressed.
//!
//! Crash safety: the MCAP writer sits directly on the file (no user-space buffer), and a chunk
//! that has been open for `max_chunk_age` is closed, so after a SIGKILL every closed chunk is on
//! disk and at most that much is lost. A failing write (a full disk) ends the episode's file: the
//! error is reported once, the file is closed as far as it can be, and later messages of the
//! episode are counted as dropped.

use so101_core::episode_bag;
use std::{
    collections::{BTreeMap, HashMap},
    fs::File,
    io::{self, Seek, SeekFrom, Write},
    path::{Path, PathBuf},
    time::{Duration, Instant},
};

use mcap::{records::MessageHeader, Compression, WriteOptions, Writer};

use crate::{
    episodes::{EpisodeInfo, StartOptions},
    metadata::{metadata_yaml, BagSummary, FileSummary, QosSummary, TopicSummary},
};

/// How bags are written.
#[derive(Debug, Clone)]
pub struct BagOptions {
    pub output: PathBuf,
    /// Episode directories are `<prefix>_<index, 6 digits>`.
    pub prefix: String,
    pub compression: Option<Compression>,
    pub chunk_size: u64,
    pub max_chunk_age: Duration,
    pub split_size: Option<u64>,
    pub split_duration: Option<Duration>,
    /// Task text of episodes whose start does not name one.
    pub default_task: String,
}

/// A topic as recorded: name, type, schema text and QoS.
#[derive(Debug, Clone)]
pub struct TopicInfo {
    pub name: String,
    pub type_name: String,
    pub schema: String,
    pub qos: QosSummary,
}

/// One received message, for topic number `topic` (the order topics were added in).
#[derive(Debug, Clone)]
pub struct Message {
    pub topic: usize,
    pub data: Vec<u8>,
    pub log_ns: u64,
    pub publish_ns: u64,
}

#[derive(Debug, thiserror::Error)]
pub enum BagError {
    #[error("cannot create {path}: {source}")]
    Create {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("writing {path} failed: {source}")]
    Mcap {
        path: PathBuf,
        source: mcap::McapError,
    },
    #[error("cannot write {path}: {source}")]
    Metadata {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("no episode is being recorded")]
    NotRecording,
    #[error("{0}")]
    NothingToDiscard(&'static str),
    #[error("episode {index} stopped, but its recording failed: {error}")]
    Failed { index: u64, error: String },
}

/// The bag file under the MCAP writer. After the first failed write or seek it refuses everything:
/// the MCAP writer's cleanup (finish on drop) would otherwise go back and rewrite the open chunk's
/// header over a half-written message, which then reads as a complete one.
struct GuardedFile {
    file: File,
    failed: bool,
}

impl GuardedFile {
    fn guard<T>(&mut self, operation: impl FnOnce(&mut File) -> io::Result<T>) -> io::Result<T> {
        if self.failed {
            return Err(io::Error::other(
                "the bag file failed earlier and is closed",
            ));
        }
        operation(&mut self.file).inspect_err(|_| self.failed = true)
    }
}

impl Write for GuardedFile {
    fn write(&mut self, bytes: &[u8]) -> io::Result<usize> {
        self.guard(|file| file.write(bytes))
    }

    fn flush(&mut self) -> io::Result<()> {
        self.guard(|file| file.flush())
    }
}

impl Seek for GuardedFile {
    fn seek(&mut self, position: SeekFrom) -> io::Result<u64> {
        self.guard(|file| file.seek(position))
    }
}

struct OpenFile {
    writer: Writer<GuardedFile>,
    path: PathBuf,
    relative: String,
    channels: HashMap<usize, u16>,
    schemas: HashMap<String, u16>,
    start_ns: Option<u64>,
    last_ns: u64,
    count: u64,
    sequence: u32,
    chunk_opened: Option<Instant>,
    /// Topics of the messages in the open chunk (lost together if the disk fails before it
    /// closes), and its size: chunks are closed here, not by the MCAP writer, so that is known.
    chunk_topics: Vec<usize>,
    chunk_bytes: u64,
    since_size_check: u32,
    size: u64,
}

struct Episode {
    info: EpisodeInfo,
    dir: PathBuf,
    name: String,
    file: Option<OpenFile>,
    files: Vec<FileSummary>,
    counts: Vec<u64>,
    first_ns: Option<u64>,
    last_ns: u64,
    count: u64,
    /// Set once a write failed: the rest of the episode is not written.
    failed: Option<String>,
}

/// The writing side of the recorder (runs on its own thread, off the receive path).
pub struct BagWriter {
    options: BagOptions,
    topics: Vec<TopicInfo>,
    next_index: u64,
    episode: Option<Episode>,
    /// The episode closed last (its index and directory), until the next one starts: what
    /// `discard_last` deletes.
    last_closed: Option<(u64, PathBuf)>,
    /// The simulation's latest /sim/episode (JSON): what the open episode, and the next one, were
    /// simulated with.
    simulation: Option<String>,
}

/// Messages between two looks at the file size (split by size).
const SIZE_CHECK_EVERY: u32 = 64;

impl BagWriter {
    pub fn new(options: BagOptions) -> Result<Self, BagError> {
        std::fs::create_dir_all(&options.output).map_err(|source| BagError::Create {
            path: options.output.clone(),
            source,
        })?;
        let next_index = next_free_index(&options.output, &options.prefix);
        Ok(Self {
            options,
            topics: Vec::new(),
            next_index,
            episode: None,
            last_closed: None,
            simulation: None,
        })
    }

    /// The simulation's settings changed (a reset drew a new episode): the open episode, and the
    /// next ones until another change, carry these.
    pub fn set_simulation(&mut self, settings: String) {
        if let Some(episode) = self.episode.as_mut() {
            episode.info.simulation = Some(settings.clone());
        }
        self.simulation = Some(settings);
    }

    pub fn add_topic(&mut self, topic: TopicInfo) {
        if let Some(episode) = &mut self.episode {
            episode.counts.push(0);
        }
        self.topics.push(topic);
    }

    pub fn is_recording(&self) -> bool {
        self.episode.is_some()
    }

    /// Starts a new episode (a running one is stopped first, with `success_hint`). Returns its
    /// directory.
    pub fn start(
        &mut self,
        options: StartOptions,
        now_ns: u64,
        success_hint: Option<bool>,
    ) -> Result<PathBuf, BagError> {
        if self.episode.is_some() {
            if let Err(error) = self.stop(now_ns, success_hint) {
                tracing::warn!(error = %error_chain(&error), "the previous episode ended with an error");
            }
        }
        self.last_closed = None;
        // Claimed with create_dir, not create_dir_all: another recorder on the same directory
        // takes the next number instead of writing into this one.
        let (index, name, dir) = loop {
            let index = self.next_index;
            self.next_index += 1;
            let name = episode_bag::episode_dir_name(&self.options.prefix, index);
            let dir = self.options.output.join(&name);
            match std::fs::create_dir(&dir) {
                Ok(()) => break (index, name, dir),
                Err(error) if error.kind() == io::ErrorKind::AlreadyExists => continue,
                Err(source) => return Err(BagError::Create { path: dir, source }),
            }
        };
        let mut episode = Episode {
            info: EpisodeInfo {
                index,
                task: options
                    .task
                    .unwrap_or_else(|| self.options.default_task.clone()),
                seed: options.seed,
                success: None,
                start_ns: now_ns,
                stop_ns: None,
                dropped: 0,
                error: None,
                simulation: self.simulation.clone(),
            },
            dir: dir.clone(),
            name,
            file: None,
            files: Vec::new(),
            counts: vec![0; self.topics.len()],
            first_ns: None,
            last_ns: now_ns,
            count: 0,
            failed: None,
        };
        match self.open_file(&episode) {
            Ok(file) => episode.file = Some(file),
            Err(error) => {
                let _ = std::fs::remove_dir_all(&dir);
                return Err(error);
            }
        }
        tracing::info!(episode = index, dir = %dir.display(), task = %episode.info.task, "episode started");
        self.episode = Some(episode);
        Ok(dir)
    }

    fn open_file(&self, episode: &Episode) -> Result<OpenFile, BagError> {
        let relative = episode_bag::mcap_file_name(&episode.name, episode.files.len());
        let path = episode.dir.join(&relative);
        let file = File::create(&path).map_err(|source| BagError::Create {
            path: path.clone(),
            source,
        })?;
        let writer = WriteOptions::new()
            .profile("ros2")
            .library(concat!("so101 recorder_node ", env!("CARGO_PKG_VERSION")))
            .compression(self.options.compression)
            .chunk_size(None)
            // rosbag2's defaults: no chunk or data-section CRCs (each would read every byte again).
            .calculate_chunk_crcs(false)
            .calculate_data_section_crc(false)
            .create(GuardedFile {
                file,
                failed: false,
            })
            .map_err(|source| BagError::Mcap {
                path: path.clone(),
                source,
            })?;
        Ok(OpenFile {
            writer,
            path,
            relative,
            channels: HashMap::new(),
            schemas: HashMap::new(),
            start_ns: None,
            last_ns: 0,
            count: 0,
            sequence: 0,
            chunk_opened: None,
            chunk_topics: Vec::new(),
            chunk_bytes: 0,
            since_size_check: 0,
            size: 0,
        })
    }

    /// Writes one message into the running episode; messages outside an episode are not kept.
    pub fn write(&mut self, message: &Message) {
        let Some(episode) = self.episode.as_mut() else {
            return;
        };
        if episode.failed.is_some() {
            episode.info.dropped += 1;
            return;
        }
        // Received before the episode began (queued while it was being started): not part of it.
        if message.log_ns < episode.info.start_ns {
            return;
        }
        let written_before = episode.count;
        if let Err(error) = self.write_in_episode(message) {
            // Unless it failed only when its chunk was closed, the message itself is lost too.
            let counted = self
                .episode
                .as_ref()
                .is_some_and(|episode| episode.count > written_before);
            self.fail(error, u64::from(!counted));
        }
    }

    fn write_in_episode(&mut self, message: &Message) -> Result<(), BagError> {
        self.split_if_due(message.log_ns)?;
        let topic = &self.topics[message.topic];
        let Some(episode) = self.episode.as_mut() else {
            return Ok(());
        };
        let Some(file) = episode.file.as_mut() else {
            return Ok(());
        };
        let mcap_error = |path: &Path| {
            let path = path.to_owned();
            move |source| BagError::Mcap { path, source }
        };
        let channel = match file.channels.get(&message.topic) {
            Some(channel) => *channel,
            None => {
                let schema = match file.schemas.get(&topic.type_name) {
                    Some(schema) => *schema,
                    None => {
                        let id = file
                            .writer
                            .add_schema(&topic.type_name, "ros2msg", topic.schema.as_bytes())
                            .map_err(mcap_error(&file.path))?;
                        file.schemas.insert(topic.type_name.clone(), id);
                        id
                    }
                };
                let metadata = BTreeMap::from([
                    ("offered_qos_profiles".to_owned(), topic.qos.yaml(0)),
                    ("topic_type_hash".to_owned(), String::new()),
                ]);
                let id = file
                    .writer
                    .add_channel(schema, &topic.name, "cdr", &metadata)
                    .map_err(mcap_error(&file.path))?;
                file.channels.insert(message.topic, id);
                id
            }
        };
        file.writer
            .write_to_known_channel(
                &MessageHeader {
                    channel_id: channel,
                    sequence: file.sequence,
                    log_time: message.log_ns,
                    publish_time: message.publish_ns,
                },
                &message.data,
            )
            .map_err(mcap_error(&file.path))?;
        file.sequence = file.sequence.wrapping_add(1);
        file.count += 1;
        // Topics are taken one after the other, so a later write may carry an earlier time.
        file.start_ns = Some(
            file.start_ns
                .map_or(message.log_ns, |t| t.min(message.log_ns)),
        );
        file.last_ns = file.last_ns.max(message.log_ns);
        file.chunk_opened.get_or_insert_with(Instant::now);
        file.size += message.data.len() as u64;
        file.chunk_topics.push(message.topic);
        file.chunk_bytes += message.data.len() as u64;
        episode.counts[message.topic] += 1;
        episode.count += 1;
        episode.first_ns = Some(
            episode
                .first_ns
                .map_or(message.log_ns, |t| t.min(message.log_ns)),
        );
        episode.last_ns = episode.last_ns.max(message.log_ns);
        if file.chunk_bytes >= self.options.chunk_size {
            close_chunk(file)?;
        }
        Ok(())
    }

    /// Starts the next file of the episode when the current one is over the size or duration.
    fn split_if_due(&mut self, now_ns: u64) -> Result<(), BagError> {
        let (split_size, split_duration) = (self.options.split_size, self.options.split_duration);
        let Some(episode) = self.episode.as_mut() else {
            return Ok(());
        };
        let Some(file) = episode.file.as_mut() else {
            return Ok(());
        };
        if split_size.is_some() {
            file.since_size_check += 1;
        }
        if split_size.is_some() && file.since_size_check >= SIZE_CHECK_EVERY {
            file.since_size_check = 0;
            // The real size (compression makes the message bytes an overestimate).
            if let Ok(meta) = std::fs::metadata(&file.path) {
                file.size = meta.len();
            }
        }
        let too_big = split_size.is_some_and(|limit| file.size >= limit);
        let too_long = split_duration.is_some_and(|limit| {
            file.start_ns
                .is_some_and(|start| now_ns.saturating_sub(start) >= limit.as_nanos() as u64)
        });
        if !(too_big || too_long) || file.count == 0 {
            return Ok(());
        }
        self.close_file()?;
        let Some(episode) = self.episode.as_ref() else {
            return Ok(());
        };
        let next = self.open_file(episode)?;
        tracing::info!(file = %next.path.display(), "bag split");
        if let Some(episode) = self.episode.as_mut() {
            episode.file = Some(next);
        }
        Ok(())
    }

    /// Closes the open chunk when it is older than `max_chunk_age` (bounded loss on a crash).
    pub fn tick(&mut self) {
        let age = self.options.max_chunk_age;
        let Some(file) = self.episode.as_mut().and_then(|e| e.file.as_mut()) else {
            return;
        };
        if file
            .chunk_opened
            .is_some_and(|opened| opened.elapsed() >= age)
        {
            if let Err(error) = close_chunk(file) {
                self.fail(error, 0);
            }
        }
    }

    pub fn mark(&mut self, success: bool) -> Result<u64, BagError> {
        let episode = self.episode.as_mut().ok_or(BagError::NotRecording)?;
        episode.info.success = Some(success);
        Ok(episode.info.index)
    }

    pub fn add_dropped(&mut self, count: u64) {
        if let Some(episode) = self.episode.as_mut() {
            episode.info.dropped += count;
        }
    }

    /// Ends the episode: closes its file and writes metadata.yaml. `success_hint` (the last
    /// /task/success) is used when nobody marked the episode.
    pub fn stop(
        &mut self,
        now_ns: u64,
        success_hint: Option<bool>,
    ) -> Result<EpisodeInfo, BagError> {
        let episode = self.episode.as_mut().ok_or(BagError::NotRecording)?;
        episode.info.stop_ns = Some(now_ns);
        if episode.info.success.is_none() {
            episode.info.success = success_hint;
        }
        let closed = self.close_file();
        let Some(mut episode) = self.episode.take() else {
            return Err(BagError::NotRecording);
        };
        episode.info.error = episode.failed.clone();
        self.last_closed = Some((episode.info.index, episode.dir.clone()));
        let metadata = write_metadata_yaml(&episode, &self.topics);
        tracing::info!(
            episode = episode.info.index,
            messages = episode.count,
            success = ?episode.info.success,
            dropped = episode.info.dropped,
            dir = %episode.dir.display(),
            "episode stopped"
        );
        closed.and(metadata)?;
        match episode.failed {
            Some(error) => Err(BagError::Failed {
                index: episode.info.index,
                error,
            }),
            None => Ok(episode.info),
        }
    }

    /// Ends the episode and deletes its directory.
    pub fn discard(&mut self) -> Result<u64, BagError> {
        let index = self
            .episode
            .as_ref()
            .ok_or(BagError::NotRecording)?
            .info
            .index;
        let _ = self.close_file();
        if let Some(episode) = self.episode.take() {
            let _ = std::fs::remove_dir_all(&episode.dir);
            tracing::info!(episode = index, "episode discarded");
        }
        // The discarded index is used again: numbering stays contiguous.
        self.next_index = index;
        Ok(index)
    }

    /// Deletes the episode closed last, between it and the next start (re-recording an episode
    /// judged during the reset period after it). Its index is used again.
    pub fn discard_last(&mut self) -> Result<u64, BagError> {
        if self.episode.is_some() {
            return Err(BagError::NothingToDiscard(
                "an episode is being recorded: discard deletes it",
            ));
        }
        let (index, dir) = self.last_closed.take().ok_or(BagError::NothingToDiscard(
            "no episode closed since the last start",
        ))?;
        let _ = std::fs::remove_dir_all(&dir);
        tracing::info!(episode = index, "closed episode discarded");
        self.next_index = index;
        Ok(index)
    }

    fn close_file(&mut self) -> Result<(), BagError> {
        let Some(episode) = self.episode.as_mut() else {
            return Ok(());
        };
        let Some(mut file) = episode.file.take() else {
            return Ok(());
        };
        // The open chunk first: if it cannot be written, its messages are not in the file.
        let chunk = if episode.failed.is_none() {
            close_chunk(&mut file)
        } else {
            Ok(())
        };
        if let Err(error) = &chunk {
            let text = error_chain(error);
            tracing::error!(error = %text, "closing the bag file failed: its last chunk is lost");
            lose_open_chunk(episode, &mut file);
            episode.failed = Some(text);
        }
        let start = file.start_ns.unwrap_or(episode.info.start_ns);
        episode.files.push(FileSummary {
            path: file.relative.clone(),
            start_ns: start,
            duration_ns: file.last_ns.saturating_sub(start),
            message_count: file.count,
        });
        if episode.failed.is_some() {
            // Nothing more reaches a file after a failed write (see GuardedFile).
            return chunk;
        }
        let bag = summary(episode, &self.topics);
        let records = [
            (
                "rosbag2",
                BTreeMap::from([("serialized_metadata".to_owned(), metadata_yaml(&bag))]),
            ),
            ("episode", episode.info.custom_data().into_iter().collect()),
        ];
        let path = file.path.clone();
        for (name, metadata) in records {
            file.writer
                .write_metadata(&mcap::records::Metadata {
                    name: name.to_owned(),
                    metadata,
                })
                .map_err(|source| BagError::Mcap {
                    path: path.clone(),
                    source,
                })?;
        }
        file.writer
            .finish()
            .map(|_| ())
            .map_err(|source| BagError::Mcap { path, source })
    }

    /// A write failed: say so once, stop writing this episode, keep what is on disk. The messages
    /// of the chunk that was open are not readable: they count as dropped, not as recorded.
    fn fail(&mut self, error: BagError, messages_lost: u64) {
        let error = error_chain(&error);
        tracing::error!(%error, "recording failed: the episode's file is closed where it stands (chunks written so far stay readable); its remaining messages are dropped");
        if let Some(episode) = self.episode.as_mut() {
            episode.failed = Some(error);
            episode.info.dropped += messages_lost;
            if let Some(mut file) = episode.file.take() {
                lose_open_chunk(episode, &mut file);
                episode.file = Some(file);
            }
        }
        let _ = self.close_file();
    }

    pub fn failure(&self) -> Option<&str> {
        self.episode.as_ref().and_then(|e| e.failed.as_deref())
    }
}

/// The open chunk's messages will never be readable: they count as dropped, not as recorded.
fn lose_open_chunk(episode: &mut Episode, file: &mut OpenFile) {
    let lost = std::mem::take(&mut file.chunk_topics);
    for topic in &lost {
        episode.counts[*topic] -= 1;
    }
    let lost = lost.len() as u64;
    file.count -= lost;
    episode.count -= lost;
    episode.info.dropped += lost;
}

/// Writes out the open chunk; its messages are on disk from here on.
fn close_chunk(file: &mut OpenFile) -> Result<(), BagError> {
    file.writer.flush().map_err(|source| BagError::Mcap {
        path: file.path.clone(),
        source,
    })?;
    file.chunk_topics.clear();
    file.chunk_bytes = 0;
    file.chunk_opened = None;
    Ok(())
}

fn summary(episode: &Episode, topics: &[TopicInfo]) -> BagSummary {
    let start = episode.first_ns.unwrap_or(episode.info.start_ns);
    BagSummary {
        start_ns: start,
        duration_ns: episode.last_ns.saturating_sub(start),
        message_count: episode.count,
        topics: topics
            .iter()
            .zip(&episode.counts)
            .filter(|(_, count)| **count > 0)
            .map(|(topic, count)| TopicSummary {
                name: topic.name.clone(),
                type_name: topic.type_name.clone(),
                qos: topic.qos,
                message_count: *count,
            })
            .collect(),
        files: episode.files.clone(),
        custom_data: episode.info.custom_data(),
    }
}

fn write_metadata_yaml(episode: &Episode, topics: &[TopicInfo]) -> Result<(), BagError> {
    let path = episode.dir.join(episode_bag::METADATA_FILE);
    let temporary = episode
        .dir
        .join(format!("{}.tmp", episode_bag::METADATA_FILE));
    let text = metadata_yaml(&summary(episode, topics));
    std::fs::write(&temporary, text)
        .and_then(|()| std::fs::rename(&temporary, &path))
        .map_err(|source| {
            // Never leave a half-written file next to the bag.
            let _ = std::fs::remove_file(&temporary);
            BagError::Metadata { path, source }
        })
}

/// An error with its causes, "a: b: c" (mcap's own message hides the OS error otherwise).
pub fn error_chain(error: &dyn std::error::Error) -> String {
    let mut text = error.to_string();
    let mut source = error.source();
    while let Some(cause) = source {
        let cause_text = cause.to_string();
        if !text.contains(&cause_text) {
            text.push_str(": ");
            text.push_str(&cause_text);
        }
        source = cause.source();
    }
    text
}

/// One past the highest `<prefix>_NNNNNN` in `dir` (earlier recordings are never overwritten).
fn next_free_index(dir: &Path, prefix: &str) -> u64 {
    let lead = format!("{prefix}_");
    std::fs::read_dir(dir)
        .into_iter()
        .flatten()
        .flatten()
        .filter_map(|entry| {
            let name = entry.file_name().into_string().ok()?;
            name.strip_prefix(&lead)?.parse::<u64>().ok()
        })
        .max()
        .map_or(0, |highest| highest + 1)
}

#[cfg(test)]
impl BagOptions {
    /// What the unit tests record with: small chunks, no compression, no split.
    pub(crate) fn for_tests(output: &Path) -> Self {
        Self {
            output: output.to_owned(),
            prefix: so101_core::episode_bag::DEFAULT_PREFIX.into(),
            compression: None,
            chunk_size: 1024,
            max_chunk_age: Duration::from_secs(1),
            split_size: None,
            split_duration: None,
            default_task: "test".into(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn options(dir: &Path) -> BagOptions {
        BagOptions {
            split_duration: Some(Duration::from_secs(1)),
            ..BagOptions::for_tests(dir)
        }
    }

    fn topic() -> TopicInfo {
        TopicInfo {
            name: "/chatter".into(),
            type_name: "std_msgs/msg/String".into(),
            schema: "string data\n".into(),
            qos: QosSummary {
                reliable: true,
                depth: 10,
            },
        }
    }

    #[test]
    fn episodes_get_their_own_numbered_directories_and_split_by_duration() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir(dir.path().join("episode_000004")).unwrap();
        let mut bag = BagWriter::new(options(dir.path())).unwrap();
        bag.add_topic(topic());
        let episode = bag.start(StartOptions::default(), 0, None).unwrap();
        assert!(episode.ends_with("episode_000005"));
        for i in 0..30u64 {
            bag.write(&Message {
                topic: 0,
                data: vec![0, 1, 0, 0, 2, 0, 0, 0, b'h', 0],
                log_ns: i * 100_000_000,
                publish_ns: i * 100_000_000,
            });
        }
        let info = bag.stop(3_000_000_000, Some(true)).unwrap();
        assert_eq!(info.success, Some(true));
        let files: Vec<_> = std::fs::read_dir(&episode)
            .unwrap()
            .flatten()
            .map(|e| e.file_name())
            .collect();
        assert!(files.iter().any(|f| f == "metadata.yaml"));
        assert!(
            files.iter().any(|f| f == "episode_000005_2.mcap"),
            "{files:?}"
        );
        let yaml = std::fs::read_to_string(episode.join("metadata.yaml")).unwrap();
        assert!(yaml.contains("  message_count: 30\n"));
        assert!(yaml.contains("episode_000005_0.mcap"));
        assert!(matches!(bag.stop(0, None), Err(BagError::NotRecording)));
    }

    #[test]
    fn two_recorders_on_one_directory_never_share_an_episode() {
        let dir = tempfile::tempdir().unwrap();
        let mut first = BagWriter::new(options(dir.path())).unwrap();
        let mut second = BagWriter::new(options(dir.path())).unwrap();
        let a = first.start(StartOptions::default(), 0, None).unwrap();
        let b = second.start(StartOptions::default(), 0, None).unwrap();
        assert_ne!(a, b);
        assert!(b.ends_with("episode_000001"));
    }

    #[test]
    fn a_start_that_ends_an_episode_passes_on_its_success() {
        let dir = tempfile::tempdir().unwrap();
        let mut bag = BagWriter::new(options(dir.path())).unwrap();
        let first = bag.start(StartOptions::default(), 0, None).unwrap();
        bag.start(StartOptions::default(), 10, Some(true)).unwrap();
        let yaml = std::fs::read_to_string(first.join("metadata.yaml")).unwrap();
        assert!(yaml.contains("\"success\": \"true\""), "{yaml}");
    }

    #[test]
    fn the_episode_closed_last_can_be_discarded_until_the_next_starts() {
        let dir = tempfile::tempdir().unwrap();
        let mut bag = BagWriter::new(options(dir.path())).unwrap();
        assert!(bag.discard_last().is_err(), "nothing closed yet");
        bag.start(StartOptions::default(), 1, None).unwrap();
        assert!(bag.discard_last().is_err(), "an episode is running");
        bag.stop(2, None).unwrap();
        let first = bag.start(StartOptions::default(), 3, None).unwrap();
        bag.stop(4, None).unwrap();
        assert_eq!(bag.discard_last().unwrap(), 1);
        assert!(!first.exists());
        assert!(bag.discard_last().is_err(), "only the last one");
        let again = bag.start(StartOptions::default(), 5, None).unwrap();
        assert_eq!(again, first, "its number is used again");
        bag.stop(6, None).unwrap();
        assert!(dir
            .path()
            .join(episode_bag::episode_dir_name("episode", 0))
            .exists());
    }

    #[test]
    fn a_discarded_episode_leaves_nothing_and_its_number_is_reused() {
        let dir = tempfile::tempdir().unwrap();
        let mut bag = BagWriter::new(options(dir.path())).unwrap();
        bag.add_topic(topic());
        let first = bag.start(StartOptions::default(), 0, None).unwrap();
        assert_eq!(bag.discard().unwrap(), 0);
        assert!(!first.exists());
        let again = bag.start(StartOptions::default(), 0, None).unwrap();
        assert_eq!(again, first);
        // Messages outside an episode are not kept; the marker needs an episode.
        bag.stop(1, None).unwrap();
        bag.write(&Message {
            topic: 0,
            data: vec![0, 1, 0, 0],
            log_ns: 2,
            publish_ns: 2,
        });
        assert!(matches!(bag.mark(true), Err(BagError::NotRecording)));
    }
}
