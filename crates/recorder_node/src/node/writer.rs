//! The writer thread, the bag's only owner. Everything reaches it as a [`Command`] on one queue:
//! a topic is known before its first message, and an episode event falls between the messages it
//! separates. The receive path never waits for the disk: a byte budget bounds the queue instead.

use std::{
    sync::{
        atomic::{AtomicU64, Ordering},
        mpsc::{Receiver, RecvTimeoutError, SyncSender},
        Arc,
    },
    thread::JoinHandle,
    time::{Duration, SystemTime, UNIX_EPOCH},
};

use anyhow::{Context as _, Result};

use crate::{
    bag::{BagWriter, Message, TopicInfo},
    episodes::StartOptions,
};

/// How long the writer waits for a command before it lets the bag flush an aging chunk.
const IDLE_TICK: Duration = Duration::from_millis(100);

/// Where an episode command's outcome goes: the text a service answers with, or the error.
pub type Reply = SyncSender<Result<String, String>>;

pub enum Command {
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
    /// Close the episode being recorded (with this success hint) and end the thread.
    Shutdown(Option<bool>),
}

/// Bytes of messages in the queue, against a limit.
pub struct QueueBudget {
    bytes: AtomicU64,
    limit: u64,
}

impl QueueBudget {
    pub fn new(limit: u64) -> Self {
        Self {
            bytes: AtomicU64::new(0),
            limit,
        }
    }

    /// Counts `size` bytes in, unless they would pass the limit (false: drop the message).
    pub fn try_reserve(&self, size: u64) -> bool {
        if self.bytes.load(Ordering::Relaxed) + size > self.limit {
            return false;
        }
        self.bytes.fetch_add(size, Ordering::Relaxed);
        true
    }

    /// Counts `size` bytes out (written, or never queued after all).
    pub fn release(&self, size: u64) {
        self.bytes.fetch_sub(size, Ordering::Relaxed);
    }
}

/// Wall clock in ns since the epoch (log time of messages, episode times).
pub fn now_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64)
}

/// Starts the thread that carries out `commands` on `bag` until a shutdown or until every sender
/// is gone.
pub fn spawn(
    mut bag: BagWriter,
    commands: Receiver<Command>,
    budget: Arc<QueueBudget>,
) -> Result<JoinHandle<()>> {
    std::thread::Builder::new()
        .name("bag writer".into())
        .spawn(move || loop {
            match commands.recv_timeout(IDLE_TICK) {
                Ok(command) => {
                    if !execute(&mut bag, command, &budget) {
                        return;
                    }
                }
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => return,
            }
            bag.tick();
        })
        .context("cannot start the writer thread")
}

/// Carries out one command on the bag, answering its reply; false once the recorder shuts down.
fn execute(bag: &mut BagWriter, command: Command, budget: &QueueBudget) -> bool {
    match command {
        Command::Message(message) => {
            budget.release(message.data.len() as u64);
            bag.write(&message);
        }
        Command::Topic(topic) => bag.add_topic(topic),
        Command::Start(options, at, hint, reply) => answer(
            reply,
            bag.start(options, at, hint)
                .map(|dir| format!("recording into {}", dir.display())),
        ),
        Command::Stop(at, hint, reply) => answer(
            reply,
            bag.stop(at, hint).map(|info| {
                format!(
                    "episode {} stopped (success: {})",
                    info.index,
                    info.success.map_or("unknown".into(), |s| s.to_string())
                )
            }),
        ),
        Command::Mark(success, reply) => answer(
            reply,
            bag.mark(success)
                .map(|index| format!("episode {index} marked success={success}")),
        ),
        Command::Discard(reply) => answer(
            reply,
            bag.discard()
                .map(|index| format!("episode {index} discarded")),
        ),
        Command::DiscardLast(reply) => answer(
            reply,
            bag.discard_last()
                .map(|index| format!("closed episode {index} discarded")),
        ),
        Command::Dropped(count) => bag.add_dropped(count),
        Command::Simulation(settings) => bag.set_simulation(settings),
        Command::Shutdown(hint) => {
            if bag.is_recording() {
                if let Err(error) = bag.stop(now_ns(), hint) {
                    tracing::error!(%error, "closing the last episode failed");
                }
            }
            return false;
        }
    }
    true
}

/// Sends the outcome to whoever asked; an event nobody waits for logs its failure instead.
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

#[cfg(test)]
mod tests {
    use std::sync::mpsc::sync_channel;

    use super::*;
    use crate::{bag::BagOptions, metadata::QosSummary};

    fn bag(dir: &std::path::Path) -> BagWriter {
        BagWriter::new(BagOptions::for_tests(dir)).unwrap()
    }

    /// Carries out `command` with a reply and returns the answer.
    fn asked(
        bag: &mut BagWriter,
        budget: &QueueBudget,
        command: impl FnOnce(Option<Reply>) -> Command,
    ) -> Result<String, String> {
        let (reply, answer) = sync_channel(1);
        assert!(execute(bag, command(Some(reply)), budget));
        answer
            .try_recv()
            .expect("every episode command is answered")
    }

    #[test]
    fn episode_commands_are_answered_with_what_happened() {
        let dir = tempfile::tempdir().unwrap();
        let mut bag = bag(dir.path());
        let budget = QueueBudget::new(1000);
        let start = |reply| Command::Start(StartOptions::default(), 1, None, reply);
        let started = asked(&mut bag, &budget, start).unwrap();
        assert!(started.starts_with("recording into ") && started.ends_with("episode_000000"));
        assert_eq!(
            asked(&mut bag, &budget, |reply| Command::Mark(true, reply)),
            Ok("episode 0 marked success=true".into())
        );
        assert_eq!(
            asked(&mut bag, &budget, |reply| Command::Stop(2, None, reply)),
            Ok("episode 0 stopped (success: true)".into())
        );
        assert!(asked(&mut bag, &budget, |reply| Command::Mark(false, reply)).is_err());
        assert_eq!(
            asked(&mut bag, &budget, Command::DiscardLast),
            Ok("closed episode 0 discarded".into())
        );
        asked(&mut bag, &budget, start).unwrap();
        assert_eq!(
            asked(&mut bag, &budget, Command::Discard),
            Ok("episode 0 discarded".into())
        );
    }

    #[test]
    fn a_written_message_gives_its_bytes_back_to_the_budget() {
        let dir = tempfile::tempdir().unwrap();
        let mut bag = bag(dir.path());
        let budget = QueueBudget::new(25);
        assert!(budget.try_reserve(10) && budget.try_reserve(15));
        assert!(!budget.try_reserve(1), "the queue is full");
        assert!(execute(
            &mut bag,
            Command::Topic(crate::bag::TopicInfo {
                name: "/chatter".into(),
                type_name: "std_msgs/msg/String".into(),
                schema: "string data\n".into(),
                qos: QosSummary {
                    reliable: true,
                    depth: 10,
                },
            }),
            &budget
        ));
        let message = Message {
            topic: 0,
            data: vec![0; 10],
            log_ns: 1,
            publish_ns: 1,
        };
        assert!(execute(&mut bag, Command::Message(message), &budget));
        assert!(budget.try_reserve(10) && !budget.try_reserve(1));
    }

    #[test]
    fn shutdown_closes_the_episode_with_the_tasks_verdict_and_ends_the_thread() {
        let dir = tempfile::tempdir().unwrap();
        let mut bag = bag(dir.path());
        let budget = QueueBudget::new(1000);
        asked(&mut bag, &budget, |reply| {
            Command::Start(StartOptions::default(), 1, None, reply)
        })
        .unwrap();
        assert!(!execute(&mut bag, Command::Shutdown(Some(false)), &budget));
        assert!(!bag.is_recording());
        let metadata =
            std::fs::read_to_string(dir.path().join("episode_000000/metadata.yaml")).unwrap();
        assert!(metadata.contains("\"success\": \"false\""), "{metadata}");
    }
}
