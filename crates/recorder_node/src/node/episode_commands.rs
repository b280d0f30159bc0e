//! What episode control asks of the writer: the commands an event or a service call becomes, the
//! order of service calls that arrive together, and the answers they get. Pure logic.

use std::{
    sync::mpsc::{Receiver, TryRecvError},
    time::Instant,
};

use so101_msgs::std_srvs::TriggerResponse;

use super::writer::{Command, Reply};
use crate::episodes::{EpisodeEvent, StartOptions};

/// The recorder's episode services.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Service {
    MarkSuccess,
    Stop,
    Discard,
    DiscardLast,
    Start,
}

impl Service {
    /// The order in which calls taken in one turn are carried out: calls on different services
    /// carry no common order, and this one makes "mark, then stop" and "stop, then start" do what
    /// they say.
    pub const ORDER: [Self; 5] = [
        Self::MarkSuccess,
        Self::Stop,
        Self::Discard,
        Self::DiscardLast,
        Self::Start,
    ];

    /// The event a call asks for (`flag`: the request's data, for mark_success).
    pub fn event(self, flag: bool) -> EpisodeEvent {
        match self {
            Self::MarkSuccess if flag => EpisodeEvent::Success,
            Self::MarkSuccess => EpisodeEvent::Failure,
            Self::Stop => EpisodeEvent::Stop,
            Self::Discard => EpisodeEvent::Discard,
            Self::DiscardLast => EpisodeEvent::DiscardLast,
            Self::Start => EpisodeEvent::Start(StartOptions::default()),
        }
    }
}

/// Turns episode events into writer commands, remembering the task's verdict between them.
#[derive(Debug, Default)]
pub struct EpisodeCommands {
    /// The last /task/success: the verdict of an episode nobody marked.
    last_task_success: Option<bool>,
}

impl EpisodeCommands {
    pub fn task_success(&mut self, success: bool) {
        self.last_task_success = Some(success);
    }

    /// The writer commands of `event` at `now_ns`, in order; `reply` goes with the last one.
    pub fn commands(
        &mut self,
        event: EpisodeEvent,
        now_ns: u64,
        reply: Option<Reply>,
    ) -> Vec<Command> {
        match event {
            // A start ends the running episode: the verdict so far is that episode's, not the
            // next one's.
            EpisodeEvent::Start(options) => {
                let hint = self.last_task_success.take();
                vec![Command::Start(options, now_ns, hint, reply)]
            }
            EpisodeEvent::Stop => vec![Command::Stop(now_ns, self.last_task_success, reply)],
            EpisodeEvent::Success => vec![Command::Mark(true, reply)],
            EpisodeEvent::Failure => vec![Command::Mark(false, reply)],
            EpisodeEvent::Discard => vec![Command::Discard(reply)],
            EpisodeEvent::DiscardLast => vec![Command::DiscardLast(reply)],
            EpisodeEvent::Rerecord => {
                self.last_task_success = None;
                vec![
                    Command::Discard(None),
                    Command::Start(StartOptions::default(), now_ns, None, reply),
                ]
            }
        }
    }

    /// The last command: close the episode being recorded with the task's verdict.
    pub fn shutdown(&self) -> Command {
        Command::Shutdown(self.last_task_success)
    }
}

/// A service call's answer on its way from the writer, due by `deadline`.
pub struct PendingAnswer {
    pub answer: Receiver<Result<String, String>>,
    pub deadline: Instant,
}

impl PendingAnswer {
    /// The answer if it has come or is overdue at `now` (then an error); `None` while it may
    /// still come.
    pub fn poll(&self, now: Instant) -> Option<Result<String, String>> {
        match self.answer.try_recv() {
            Ok(result) => Some(result),
            Err(TryRecvError::Empty) if now < self.deadline => None,
            Err(_) => Some(Err("the writer did not answer in time".to_owned())),
        }
    }
}

/// A service's response to the writer's answer.
pub fn response(result: Result<String, String>) -> TriggerResponse {
    match result {
        Ok(message) => TriggerResponse {
            success: true,
            message,
        },
        Err(message) => TriggerResponse {
            success: false,
            message,
        },
    }
}

#[cfg(test)]
mod tests {
    use std::{sync::mpsc::sync_channel, time::Duration};

    use super::*;

    /// (kind, time, hint) of each command, for comparing.
    fn summary(commands: &[Command]) -> Vec<(&'static str, Option<u64>, Option<bool>)> {
        commands
            .iter()
            .map(|command| match command {
                Command::Start(_, at, hint, _) => ("start", Some(*at), *hint),
                Command::Stop(at, hint, _) => ("stop", Some(*at), *hint),
                Command::Mark(success, _) => ("mark", None, Some(*success)),
                Command::Discard(_) => ("discard", None, None),
                Command::DiscardLast(_) => ("discard_last", None, None),
                _ => ("other", None, None),
            })
            .collect()
    }

    #[test]
    fn the_tasks_verdict_closes_the_episode_it_was_given_in() {
        let mut control = EpisodeCommands::default();
        control.task_success(true);
        let stop = control.commands(EpisodeEvent::Stop, 5, None);
        assert_eq!(summary(&stop), [("stop", Some(5), Some(true))]);
        // The start after a stop still carries it (for an episode the start would close), then
        // forgets it: the new episode has no verdict yet.
        let start = control.commands(EpisodeEvent::Start(StartOptions::default()), 6, None);
        assert_eq!(summary(&start), [("start", Some(6), Some(true))]);
        let stop = control.commands(EpisodeEvent::Stop, 7, None);
        assert_eq!(summary(&stop), [("stop", Some(7), None)]);
        assert!(matches!(control.shutdown(), Command::Shutdown(None)));
        control.task_success(false);
        assert!(matches!(control.shutdown(), Command::Shutdown(Some(false))));
    }

    #[test]
    fn rerecord_discards_then_starts_afresh_and_answers_with_the_start() {
        let mut control = EpisodeCommands::default();
        control.task_success(true);
        let (reply, _answer) = sync_channel(1);
        let commands = control.commands(EpisodeEvent::Rerecord, 9, Some(reply));
        assert_eq!(
            summary(&commands),
            [("discard", None, None), ("start", Some(9), None)]
        );
        assert!(matches!(commands[0], Command::Discard(None)));
        assert!(matches!(commands[1], Command::Start(_, _, _, Some(_))));
        assert!(matches!(control.shutdown(), Command::Shutdown(None)));
    }

    #[test]
    fn marks_and_discards_map_one_to_one() {
        let mut control = EpisodeCommands::default();
        for (event, expected) in [
            (EpisodeEvent::Success, ("mark", None, Some(true))),
            (EpisodeEvent::Failure, ("mark", None, Some(false))),
            (EpisodeEvent::Discard, ("discard", None, None)),
            (EpisodeEvent::DiscardLast, ("discard_last", None, None)),
        ] {
            assert_eq!(summary(&control.commands(event, 1, None)), [expected]);
        }
    }

    #[test]
    fn service_calls_of_one_turn_mark_before_they_stop_and_stop_before_they_start() {
        let events: Vec<_> = Service::ORDER
            .iter()
            .map(|service| service.event(true))
            .collect();
        assert_eq!(
            events,
            [
                EpisodeEvent::Success,
                EpisodeEvent::Stop,
                EpisodeEvent::Discard,
                EpisodeEvent::DiscardLast,
                EpisodeEvent::Start(StartOptions::default()),
            ]
        );
        assert_eq!(Service::MarkSuccess.event(false), EpisodeEvent::Failure);
    }

    #[test]
    fn an_answer_is_awaited_until_its_deadline() {
        let now = Instant::now();
        let (reply, answer) = sync_channel(1);
        let pending = PendingAnswer {
            answer,
            deadline: now + Duration::from_secs(5),
        };
        assert_eq!(pending.poll(now), None);
        assert_eq!(
            pending.poll(now + Duration::from_secs(5)),
            Some(Err("the writer did not answer in time".into()))
        );
        reply.send(Ok("episode 3 stopped".into())).unwrap();
        assert_eq!(pending.poll(now), Some(Ok("episode 3 stopped".into())));
        drop(reply);
        assert!(pending.poll(now).unwrap().is_err(), "the writer is gone");
    }

    #[test]
    fn answers_become_trigger_responses() {
        let ok = response(Ok("done".into()));
        assert!(ok.success && ok.message == "done");
        let failed = response(Err("not recording".into()));
        assert!(!failed.success && failed.message == "not recording");
    }
}
