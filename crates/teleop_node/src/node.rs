//! The node: reads the arm's /joint_states and the task topics, asks its source once per control
//! period, turns the answer into joint targets (crate::motion) and publishes them on
//! /joint_commands; episode controls go to /episode/events and /sim/reset.

use so101_core::contract::{services, topics};
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use nalgebra::Vector3;
use ros2_client::{Client, Publisher, Subscription};
use so101_core::{
    command::targets_from_joint_state,
    robot::{JointPositions, JOINT_LIMITS, JOINT_NAMES},
    ros::{
        clock::SimClock, parameters::ParameterServer, qos, rate_limit::RateLimiter,
        shutdown::Shutdown, RosNode,
    },
    task::CONTROL_RATE_HZ,
};
use so101_core::{expert::ExpertConfig, robot::follow};
use so101_msgs::{
    builtin_interfaces::Time,
    geometry_msgs::PoseStamped,
    sensor_msgs::JointState,
    std_msgs::{Bool, Header, String as RosString},
    std_srvs::{Trigger, TriggerRequest, TriggerResponse},
};

use crate::{
    cli::{Args, SourceKind},
    controls::{event_text, recording_after, Control},
    input::{
        expert::Expert, gamepad::Gamepad, keyboard::Keyboard, leader::Leader, scripted::Scripted,
        Request, Scene, Source, Tick,
    },
    lockstep::{self, Lockstep, Taken},
    motion::{jog_cartesian, jog_joints, Mode, Speeds},
    parameters::{self, Tunables},
};

/// How long to wait for /sim/reset to answer before asking again (a request sent before the
/// service was discovered is lost).
const RESET_ANSWER_TIMEOUT: Duration = Duration::from_secs(2);
const RESET_ATTEMPTS: u32 = 3;
/// Nothing is published before this much time after start: DDS discovery of the peers already
/// running (a recorder waiting for /episode/events) takes a moment, and what is sent before
/// they are matched is lost.
const DISCOVERY_GRACE: Duration = Duration::from_millis(1500);
/// Wall time between a "stop" event and the next sim reset: the recorder takes events on another
/// thread than /joint_states, and a reset right after the stop put the reset pose into the closing
/// episode as its last frame (15 of 100 stack demonstrations at 8x real time).
const STOP_BEFORE_RESET: Duration = Duration::from_millis(250);

/// The node's side of the topic contract.
struct Topics {
    commands: Publisher<JointState>,
    events: Publisher<RosString>,
    joint_states: Subscription<JointState>,
    cube_pose: Subscription<PoseStamped>,
    task_success: Subscription<Bool>,
    reset: Client<TriggerRequest, TriggerResponse>,
}

impl Topics {
    fn connect(node: &mut RosNode) -> Result<Self> {
        Ok(Self {
            commands: node.publisher(topics::JOINT_COMMANDS, qos::default_topic())?,
            events: node.publisher(topics::EPISODE_EVENTS, qos::reliable(100))?,
            joint_states: node.subscription(topics::JOINT_STATES, qos::reliable(100))?,
            cube_pose: node.subscription(topics::CUBE_POSE, qos::reliable(100))?,
            task_success: node.subscription(topics::TASK_SUCCESS, qos::reliable(100))?,
            reset: node.client::<Trigger>(services::SIM_RESET)?,
        })
    }

    /// Takes everything that arrived: the arm's latest positions and the scene. Returns what came
    /// (a lockstep tick waits for all of a period's).
    fn take(&self, measured: &mut Option<JointPositions>, scene: &mut Scene) -> Taken {
        let mut taken = Taken::default();
        while let Ok(Some((message, _))) = self.joint_states.take() {
            let stamp = message.header.stamp.as_secs_f64();
            taken.joint_states += 1;
            taken.newest_stamp = Some(taken.newest_stamp.map_or(stamp, |newest| newest.max(stamp)));
            if let Ok(targets) = targets_from_joint_state(&message.name, &message.position) {
                if let Some(positions) = measured {
                    targets.apply_clamped(positions, &JOINT_LIMITS);
                } else if (0..JOINT_NAMES.len()).all(|joint| targets.get(joint).is_some()) {
                    let mut positions = [0.0; 6];
                    targets.apply_clamped(&mut positions, &JOINT_LIMITS);
                    *measured = Some(positions);
                }
            }
        }
        while let Ok(Some((message, _))) = self.cube_pose.take() {
            let pose = message.pose;
            scene.cube = Some((
                [pose.position.x, pose.position.y, pose.position.z],
                [
                    pose.orientation.w,
                    pose.orientation.x,
                    pose.orientation.y,
                    pose.orientation.z,
                ],
            ));
            scene.cube_messages += 1;
            taken.cube_poses += 1;
        }
        while let Ok(Some((message, _))) = self.task_success.take() {
            scene.task_success = message.data;
            taken.task_successes += 1;
        }
        taken
    }

    /// Publishes the targets, stamped `stamp` (seconds; 0 leaves the stamp unset).
    fn publish_targets(&self, targets: &JointPositions, stamp: f64) -> bool {
        self.commands
            .publish(JointState {
                header: Header {
                    stamp: Time::from_secs_f64(stamp),
                    frame_id: String::new(),
                },
                name: JOINT_NAMES.iter().map(|name| name.to_string()).collect(),
                position: targets.to_vec(),
                velocity: Vec::new(),
                effort: Vec::new(),
            })
            .is_ok()
    }

    fn publish_event(&self, text: String) {
        tracing::info!(event = %text, "episode event");
        if let Err(error) = self.events.publish(RosString { data: text }) {
            tracing::warn!(?error, "cannot publish an episode event");
        }
    }

    /// Calls /sim/reset; its answer's message, or why there is none.
    fn reset_sim(&self, shutdown: &Shutdown) -> Result<String, String> {
        let mut sent = Vec::new();
        for _ in 0..RESET_ATTEMPTS {
            sent.push(
                self.reset
                    .send_request(TriggerRequest::default())
                    .map_err(|error| format!("cannot send the request: {error:?}"))?,
            );
            let deadline = Instant::now() + RESET_ANSWER_TIMEOUT;
            while Instant::now() < deadline && !shutdown.is_requested() {
                match self.reset.receive_response() {
                    // A late answer to an earlier request is as good (a slow sim must not be
                    // reset twice).
                    Ok(Some((answer_id, response))) if sent.contains(&answer_id) => {
                        return if response.success {
                            Ok(response.message)
                        } else {
                            Err(response.message)
                        };
                    }
                    Ok(_) => std::thread::sleep(Duration::from_millis(1)),
                    Err(error) => return Err(format!("bad answer: {error:?}")),
                }
            }
        }
        Err("no answer (is a simulation running?)".into())
    }
}

/// The node's clock: a timed one (ticks at --rate), or the stamps of the states a sim in
/// lockstep answers each command with (crate::lockstep: a tick per period that came back).
enum Clock {
    Timed(TimedClock),
    Lockstep(Lockstep),
}

/// Wall time since start, or sim time from /clock.
enum TimedClock {
    Wall(Instant),
    Sim(SimClock),
}

impl TimedClock {
    /// Seconds now; None until /clock has been heard.
    fn now(&self) -> Option<f64> {
        match self {
            Self::Wall(start) => Some(start.elapsed().as_secs_f64()),
            Self::Sim(clock) => clock.now().map(|time| time.to_nanos() as f64 * 1e-9),
        }
    }
}

fn open_source(args: &Args, node: &mut RosNode) -> Result<Box<dyn Source>> {
    Ok(match args.source {
        SourceKind::Keyboard => Box::new(Keyboard::open()?),
        SourceKind::Gamepad => Box::new(Gamepad::open(args.deadzone)),
        SourceKind::Leader => Box::new(Leader::subscribe(
            node,
            &args.leader_topic,
            Duration::from_secs_f64(args.leader_timeout),
        )?),
        SourceKind::Scripted => {
            let path = args.script.as_deref().context("--script is needed")?;
            Box::new(Scripted::load(path)?)
        }
        SourceKind::Expert => {
            let base = Vector3::from(args.base_xyz);
            let config = ExpertConfig::for_scene(
                base,
                Vector3::from(args.bin_xyz),
                args.waypoint_noise,
                args.action_noise,
            )
            .for_task(args.sim_task);
            Box::new(Expert::new(
                config,
                base,
                args.task_text(),
                args.seed,
                (args.episodes > 0).then_some(args.episodes),
                !args.no_reset,
            ))
        }
    })
}

/// The targets after one period of `request`; the current ones where the request would give a
/// non-finite value (a broken device), which is never published.
fn next_targets(
    current: &JointPositions,
    request: &Request,
    mode: Mode,
    speeds: &Speeds,
    period: f64,
    max_step: f64,
    warnings: &mut RateLimiter,
) -> JointPositions {
    let next = match request {
        Request::Jog(jog) if jog.is_still() => *current,
        Request::Jog(jog) => match mode {
            Mode::Joint => jog_joints(current, jog, speeds, period),
            Mode::Cartesian => {
                let step = jog_cartesian(current, jog, speeds, period);
                if !step.reached {
                    if let Some(suppressed) = warnings.check(Instant::now()) {
                        tracing::warn!(
                            suppressed,
                            "Cartesian target out of reach: moving as far as the arm goes"
                        );
                    }
                }
                step.targets
            }
        },
        Request::Targets(wanted) => follow(current, wanted, max_step),
        Request::Lost => *current,
    };
    if next.iter().all(|value| value.is_finite()) {
        next
    } else {
        if let Some(suppressed) = warnings.check(Instant::now()) {
            tracing::warn!(
                suppressed,
                "ignoring a request that gives non-finite targets"
            );
        }
        *current
    }
}

/// The time of the next tick on a wall or sim clock once it is due (None after a short wait
/// while it is not), `next_tick` moved one period on.
fn timed_tick(clock: &TimedClock, next_tick: &mut Option<f64>, period: f64) -> Option<f64> {
    let Some(now) = clock.now() else {
        std::thread::sleep(Duration::from_millis(5));
        return None;
    };
    let due = *next_tick.get_or_insert(now);
    if now + 1e-9 < due {
        let wait = match clock {
            // Sim time may run at any speed: look again soon.
            TimedClock::Sim(_) => Duration::from_micros(500),
            _ => Duration::from_secs_f64((due - now).min(0.005)),
        };
        std::thread::sleep(wait);
        return None;
    }
    // A stall or a sim-time jump (forwards, or backwards when the sim restarted) is not
    // followed by a burst of periods nor by a long silence.
    *next_tick = Some(if (now - due).abs() > period {
        now + period
    } else {
        due + period
    });
    Some(now)
}

/// Runs the node until a signal, a quit control, the source's end or --duration.
pub fn run(args: Args) -> Result<()> {
    let shutdown = Shutdown::on_signals().context("cannot install the signal handlers")?;
    let mut node = RosNode::start("teleop_node", &args.node)?;
    let topics = Topics::connect(&mut node)?;
    if args.lockstep && args.source != SourceKind::Expert {
        anyhow::bail!("--lockstep runs the expert source only (--source expert): a person cannot keep pace with a sim that waits for each command");
    }
    let mut clock = if args.lockstep {
        Clock::Lockstep(Lockstep::default())
    } else if args.sim_time {
        Clock::Timed(TimedClock::Sim(SimClock::subscribe(
            &mut node,
            shutdown.clone(),
        )?))
    } else {
        Clock::Timed(TimedClock::Wall(Instant::now()))
    };
    let in_lockstep = matches!(clock, Clock::Lockstep(_));
    let mut source = open_source(&args, &mut node)?;
    let parameters = ParameterServer::start(&mut node, parameters::declarations(&args))?;
    let mut tunables = Tunables::from_args(&args);
    // In lockstep each command is one of the sim's control periods.
    let period = 1.0
        / if args.lockstep {
            CONTROL_RATE_HZ
        } else {
            args.rate
        };
    let started = Instant::now();
    let mut mode = args.mode;
    let mut recording = false;
    let mut targets: Option<JointPositions> = None;
    let mut measured: Option<JointPositions> = None;
    let mut scene = Scene::default();
    let mut next_tick: Option<f64> = None;
    let mut warnings = RateLimiter::new(Duration::from_secs(2));
    let mut waiting_logged = false;
    // When the last "stop" event went out (STOP_BEFORE_RESET).
    let mut stopped_at: Option<Instant> = None;
    tracing::info!(source = ?args.source, mode = ?mode, rate_hz = 1.0 / period, sim_time = args.sim_time, lockstep = args.lockstep, "teleop ready");

    'control: while !shutdown.is_requested() {
        if args
            .duration
            .is_some_and(|seconds| started.elapsed().as_secs_f64() >= seconds)
        {
            break;
        }
        let now = match &mut clock {
            Clock::Lockstep(lockstep) => {
                match lockstep.gate(topics.take(&mut measured, &mut scene), Instant::now()) {
                    lockstep::Gate::Tick(now) => now,
                    lockstep::Gate::TimedOut(now) => {
                        tracing::warn!(
                        timeouts = lockstep.timeouts,
                        "a command's period did not come back (/joint_states, /cube/pose, /task/success): is the sim in --lockstep --step-on-command?"
                    );
                        now
                    }
                    lockstep::Gate::Wait => {
                        std::thread::sleep(Duration::from_micros(200));
                        continue;
                    }
                }
            }
            Clock::Timed(timed) => {
                let Some(now) = timed_tick(timed, &mut next_tick, period) else {
                    continue;
                };
                now
            }
        };
        // In lockstep a tick that publishes no command steps nothing: the next one follows
        // after a pause on the wall clock instead of at once.
        let mut stepped = false;

        for change in parameters.changes() {
            tunables.apply(&change.name, &change.value);
        }
        topics.take(&mut measured, &mut scene);
        if started.elapsed() < DISCOVERY_GRACE {
            if in_lockstep {
                std::thread::sleep(lockstep::IDLE_TICK);
            }
            continue;
        }
        if targets.is_none() {
            targets = measured;
        }
        scene.targets = targets;
        scene.measured = measured;
        // The source is read even before the arm's pose is known, so its controls (quit) work.
        let reading = source.read(&Tick {
            now,
            cartesian: mode == Mode::Cartesian,
            scene,
        });
        let resetting = reading.controls.contains(&Control::ResetSim);
        match targets {
            // A command sent just before a reset could land after it and pull the arm back.
            Some(current) if !resetting => {
                let next = next_targets(
                    &current,
                    &reading.request,
                    mode,
                    &tunables.speeds,
                    period,
                    tunables.max_step,
                    &mut warnings,
                );
                targets = Some(next);
                // In lockstep a command is the period that starts at the state it answers: its
                // stamp says which, so the converter need not guess from arrival times. The nodes
                // act on arrival whatever the stamp; a timed clock leaves it unset.
                let stamp = if in_lockstep { now } else { 0.0 };
                stepped = topics.publish_targets(&next, stamp);
                if !stepped {
                    if let Some(suppressed) = warnings.check(Instant::now()) {
                        tracing::warn!(suppressed, "publishing /joint_commands failed");
                    }
                }
            }
            Some(_) => {}
            None => {
                if !waiting_logged {
                    tracing::info!("waiting for the arm's /joint_states");
                    waiting_logged = true;
                }
            }
        }
        for control in reading.controls {
            if let Some(text) = event_text(&control, recording) {
                let opens_or_closes = text.starts_with("start") || text == "stop";
                if text == "stop" {
                    stopped_at = Some(Instant::now());
                }
                topics.publish_event(text);
                if opens_or_closes && in_lockstep {
                    // The sim stands still until the next command: a recorder that opens or
                    // closes its episode meanwhile loses no period of it, nor takes one of the next.
                    std::thread::sleep(lockstep::EVENT_PAUSE);
                }
            }
            recording = recording_after(&control, recording);
            match control {
                Control::ResetSim => {
                    if let Some(at) = stopped_at.take() {
                        std::thread::sleep(STOP_BEFORE_RESET.saturating_sub(at.elapsed()));
                    }
                    match topics.reset_sim(&shutdown) {
                        Ok(message) => {
                            tracing::info!(%message, "sim reset");
                            // The arm starts the new episode at home: follow it from there.
                            targets = None;
                            if in_lockstep {
                                // Every earlier state was taken; the next one is the reset's.
                                measured = None;
                                stepped = true;
                            } else {
                                std::thread::sleep(Duration::from_millis(50));
                                topics.take(&mut measured, &mut scene);
                                measured = None;
                            }
                        }
                        Err(reason) => {
                            scene.reset_failures += 1;
                            tracing::warn!(%reason, "/sim/reset failed");
                        }
                    }
                }
                Control::ToggleMode => {
                    mode = mode.toggled();
                    tracing::info!(mode = ?mode, "mode");
                }
                Control::Halt => tracing::info!("halt: holding"),
                Control::Quit => break 'control,
                _ => {}
            }
        }
        if let Clock::Lockstep(lockstep) = &mut clock {
            if stepped {
                lockstep.stepped(Instant::now());
            } else {
                std::thread::sleep(lockstep::IDLE_TICK);
            }
        }
    }
    if let (Some(path), Some(report)) = (&args.report, source.report()) {
        std::fs::write(path, serde_json::to_string_pretty(&report)?)
            .with_context(|| format!("cannot write the report {}", path.display()))?;
    }
    // Let the last commands and events leave before the node goes.
    std::thread::sleep(Duration::from_millis(100));
    tracing::info!("teleop stopped");
    Ok(())
}
