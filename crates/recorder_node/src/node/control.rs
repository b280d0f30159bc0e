//! Episode control: /episode/events, /task/success (the default for an unmarked episode),
//! /sim/episode (the simulation's settings) and the recorder's services (/recorder/ready is
//! answered by the loop, from the inputs). Nothing here waits for
//! the writer: events are sent and forgotten, service calls are answered once the writer's reply
//! arrives, on a later turn of the loop.

use std::{
    sync::mpsc::{sync_channel, SyncSender},
    time::{Duration, Instant},
};

use anyhow::Result;
use ros2_client::{RmwRequestId, Server, Subscription};
use so101_core::{
    contract::{services, topics},
    ros::{qos, rate_limit::RateLimiter, RosNode},
};
use so101_msgs::{
    std_msgs::{Bool, String as StringMessage},
    std_srvs::{SetBool, SetBoolRequest, Trigger, TriggerRequest, TriggerResponse},
};

use super::{
    episode_commands::{response, EpisodeCommands, PendingAnswer, Service},
    writer::{now_ns, Command, Reply},
};
use crate::episodes::{parse_event, EpisodeEvent};

/// How long a service call waits for the writer thread's answer.
pub const REPLY_TIMEOUT: Duration = Duration::from_secs(5);

pub struct Control {
    events: Subscription<StringMessage>,
    simulation: Subscription<StringMessage>,
    task_success: Subscription<Bool>,
    start: Server<TriggerRequest, TriggerResponse>,
    stop: Server<TriggerRequest, TriggerResponse>,
    discard: Server<TriggerRequest, TriggerResponse>,
    discard_last: Server<TriggerRequest, TriggerResponse>,
    mark_success: Server<SetBoolRequest, TriggerResponse>,
    ready: Server<TriggerRequest, TriggerResponse>,
    episodes: EpisodeCommands,
    pending: Vec<PendingCall>,
    warnings: RateLimiter,
}

/// A service call waiting for the writer's answer.
struct PendingCall {
    service: Service,
    id: RmwRequestId,
    answer: PendingAnswer,
}

impl Control {
    pub fn serve(node: &mut RosNode) -> Result<Self> {
        Ok(Self {
            events: node.subscription(topics::EPISODE_EVENTS, qos::command_subscription())?,
            simulation: node.subscription(topics::SIM_EPISODE, qos::latched())?,
            task_success: node.subscription(topics::TASK_SUCCESS, qos::command_subscription())?,
            start: node.server::<Trigger>(services::RECORDER_START)?,
            stop: node.server::<Trigger>(services::RECORDER_STOP)?,
            discard: node.server::<Trigger>(services::RECORDER_DISCARD)?,
            discard_last: node.server::<Trigger>(services::RECORDER_DISCARD_LAST)?,
            mark_success: node.server::<SetBool>(services::RECORDER_MARK_SUCCESS)?,
            ready: node.server::<Trigger>(services::RECORDER_READY)?,
            episodes: EpisodeCommands::default(),
            pending: Vec::new(),
            warnings: RateLimiter::new(Duration::from_secs(1)),
        })
    }

    /// Takes what arrived (verdicts, events, settings, service calls) and hands it to the writer;
    /// answers the calls whose reply has come.
    pub fn take(&mut self, commands: &SyncSender<Command>) {
        while let Ok(Some((message, _))) = self.task_success.take() {
            self.episodes.task_success(message.data);
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
        for service in Service::ORDER {
            for (id, flag) in self.requests(service) {
                let (reply, answer) = sync_channel(1);
                self.apply(service.event(flag), commands, Some(reply));
                self.pending.push(PendingCall {
                    service,
                    id,
                    answer: PendingAnswer {
                        answer,
                        deadline: Instant::now() + REPLY_TIMEOUT,
                    },
                });
            }
        }
        self.answer_ready();
    }

    /// The /recorder/ready calls that arrived since the last look.
    pub fn ready_requests(&self) -> Vec<RmwRequestId> {
        std::iter::from_fn(|| match self.ready.receive_request() {
            Ok(Some((id, _))) => Some(id),
            _ => None,
        })
        .collect()
    }

    /// Answers /recorder/ready calls.
    pub fn answer_ready_requests(&self, requests: Vec<RmwRequestId>, answer: &TriggerResponse) {
        for id in requests {
            if let Err(error) = self.ready.send_response(id, answer.clone()) {
                tracing::warn!(?error, "cannot answer a recorder service call");
            }
        }
    }

    /// The command that closes the recording at shutdown.
    pub fn shutdown(&self) -> Command {
        self.episodes.shutdown()
    }

    /// The calls waiting on `service`: their ids and request flags (mark_success's data; true for
    /// the triggers).
    fn requests(&self, service: Service) -> Vec<(RmwRequestId, bool)> {
        let trigger = |server: &Server<TriggerRequest, TriggerResponse>| -> Vec<_> {
            std::iter::from_fn(|| match server.receive_request() {
                Ok(Some((id, _))) => Some((id, true)),
                _ => None,
            })
            .collect()
        };
        match service {
            Service::MarkSuccess => {
                std::iter::from_fn(|| match self.mark_success.receive_request() {
                    Ok(Some((id, request))) => Some((id, request.data)),
                    _ => None,
                })
                .collect()
            }
            Service::Stop => trigger(&self.stop),
            Service::Discard => trigger(&self.discard),
            Service::DiscardLast => trigger(&self.discard_last),
            Service::Start => trigger(&self.start),
        }
    }

    /// Answers the service calls whose reply from the writer has arrived (or is overdue).
    fn answer_ready(&mut self) {
        let now = Instant::now();
        let mut still_waiting = Vec::new();
        for call in std::mem::take(&mut self.pending) {
            let Some(result) = call.answer.poll(now) else {
                still_waiting.push(call);
                continue;
            };
            match &result {
                Ok(message) => tracing::info!("{message}"),
                Err(error) => tracing::warn!("{error}"),
            }
            let answer = response(result);
            let sent = match call.service {
                Service::Start => self.start.send_response(call.id, answer),
                Service::Stop => self.stop.send_response(call.id, answer),
                Service::Discard => self.discard.send_response(call.id, answer),
                Service::DiscardLast => self.discard_last.send_response(call.id, answer),
                Service::MarkSuccess => self.mark_success.send_response(call.id, answer),
            };
            if let Err(error) = sent {
                tracing::warn!(?error, "cannot answer a recorder service call");
            }
        }
        self.pending = still_waiting;
    }

    /// Hands an episode event to the writer, in order with the messages already queued.
    fn apply(&mut self, event: EpisodeEvent, commands: &SyncSender<Command>, reply: Option<Reply>) {
        for command in self.episodes.commands(event, now_ns(), reply) {
            if commands.send(command).is_err() {
                tracing::error!("the writer thread is gone: an episode event was lost");
                return;
            }
        }
    }
}
