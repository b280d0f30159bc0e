//! The driver node: the controller (node/controller/) on the serial port, behind ROS. Every
//! cycle: commands in, torque requests served, one controller cycle (SYNC_READ of positions,
//! checks, SYNC_WRITE of goals), joint states out; /diagnostics at 1 Hz; a summary at exit.

use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use ros2_client::RmwRequestId;
use so101_core::ros::{
    arm_controller::ArmController, command_inbox::CommandInbox, parameters::ParameterServer,
    rate_limit::RateLimiter, shutdown::Shutdown, RosNode,
};
use so101_msgs::{
    builtin_interfaces::Time, diagnostic_msgs::DiagnosticArray, sensor_msgs::JointState,
    std_msgs::Header,
};

use super::{
    controller::{Controller, ControllerConfig, CycleOutput, TORQUE_ANSWER_WAIT},
    cycle_stats::{CycleStats, CycleSummary, Schedule},
    diagnostics::{self, DriverReport},
    emergency, parameters,
    ros_io::{Output, Outputs, TorqueService},
};
use crate::{
    arm::{ArmSettings, CalibrationWrite},
    bus::{usb_latency_timer_ms, BusStats, SerialConnector},
    calibration::{ArmCalibration, ArmRole},
    cli::{CycleRate, RunArgs},
    safety::{SafetyConfig, SafetyCounters},
};

const DIAGNOSTICS_PERIOD: Duration = Duration::from_secs(1);
/// Longest single sleep, so a shutdown request is seen quickly.
const MAX_SLEEP: Duration = Duration::from_millis(50);
/// While disconnected at --rate max, how long the loop rests between looks.
const DISCONNECTED_REST: Duration = Duration::from_millis(5);

/// Runs the driver until a signal or --duration.
pub fn run(args: RunArgs) -> Result<()> {
    // Default timer slack (50 us) would be most of the jitter at 200 Hz.
    if let Err(error) = nix::sys::prctl::set_timerslack(1_000) {
        tracing::debug!(%error, "cannot lower the timer slack");
    }
    let role = args.calibration.role();
    let calibration_path = args.calibration.path();
    let calibration = ArmCalibration::load(&calibration_path)?;
    tracing::info!(path = %calibration_path.display(), ?role, "calibration loaded");
    if let Some(ms) = usb_latency_timer_ms(&args.port.port).filter(|ms| *ms > 2) {
        tracing::warn!(
            latency_timer_ms = ms,
            "the USB adapter holds replies back {ms} ms: lower it to 1 (echo 1 > /sys/bus/usb-serial/devices/<tty>/latency_timer) or cycles will be slow"
        );
    }
    let leader = role == ArmRole::Leader;
    // Last words (a panic, a second Ctrl-C) turn torque off unless the user wants it kept.
    emergency::install_panic_hook(true);
    let shutdown = Shutdown::on_signals_then(|| {
        if emergency::torque_off_now() {
            eprintln!("so101_feetech_driver: torque off was broadcast to every servo");
        }
    })
    .context("cannot install the signal handlers")?;
    let connector = SerialConnector {
        path: args.port.port.clone(),
        baud: args.port.baud,
    };
    let settings = ArmSettings {
        bus: args.port.bus_config(),
        role,
        gripper_torque_limit: args.gripper_torque_limit,
    };
    let config = ControllerConfig {
        leader,
        safety: SafetyConfig {
            max_step: args.max_step,
            command_timeout: (args.command_timeout > 0.0)
                .then(|| Duration::from_secs_f64(args.command_timeout)),
        },
        torque_at_start: !leader && !args.start_torque_off,
        calibration_write: if args.write_calibration {
            CalibrationWrite::Allowed
        } else {
            CalibrationWrite::Refused
        },
        reopen_after: Duration::from_secs_f64(args.reopen_after),
        reconnect_interval: Duration::from_secs_f64(args.reconnect_interval),
        telemetry_period: Duration::from_secs_f64(1.0 / args.telemetry_rate),
    };
    let controller = Controller::start(connector, settings, calibration, config, Instant::now())
        .with_context(|| format!("cannot start the arm on {}", args.port.port.display()))?;

    let node_name = if leader {
        "so101_leader_driver"
    } else {
        "so101_feetech_driver"
    };
    let mut node = RosNode::start(node_name, &args.node)?;
    let joint_topic = if leader {
        "leader/joint_states"
    } else {
        "joint_states"
    };
    let outputs = Outputs::start(&mut node, joint_topic)?;
    let (inbox, arm) = if leader {
        (None, None)
    } else {
        (
            Some(CommandInbox::subscribe(&mut node)?),
            Some(ArmController::serve(&mut node)?),
        )
    };
    let torque_service = TorqueService::serve(&mut node)?;
    let parameters = ParameterServer::start(
        &mut node,
        parameters::declarations(&args, controller.limits()),
    )?;
    let started_cpu = cpu_time();
    let mut driver = Driver {
        controller,
        node_name: node_name.to_owned(),
        outputs,
        inbox,
        arm,
        clock_origin: (Time::now().as_secs_f64(), Instant::now()),
        torque_service,
        pending_torque: None,
        parameters,
        stats: CycleStats::new(Instant::now()),
        next_diagnostics: Instant::now() + DIAGNOSTICS_PERIOD,
        warnings: RateLimiter::new(Duration::from_secs(2)),
        last_words_generation: None,
        args,
        _node: node,
    };
    driver.keep_last_words_line();
    let summary = driver.run(&shutdown);
    driver.finish(summary, started_cpu)
}

/// A torque_enable call waiting for the controller's retries.
struct PendingTorque {
    id: RmwRequestId,
    on: bool,
    deadline: Instant,
    /// Why the first attempt failed: the answer if the retries do not succeed in time.
    message: String,
}

/// The controller with its ROS endpoints.
struct Driver {
    controller: Controller<SerialConnector>,
    args: RunArgs,
    node_name: String,
    outputs: Outputs,
    inbox: Option<CommandInbox>,
    /// Trajectories (topic and FollowJointTrajectory action); none on a leader arm.
    arm: Option<ArmController>,
    /// Wall time and the instant it was read at start: trajectories run on wall time (the clock of
    /// their header stamps) counted from there on the monotonic clock, so a clock step (NTP) does
    /// not jump a trajectory's setpoint.
    clock_origin: (f64, Instant),
    torque_service: TorqueService,
    /// A torque_enable call whose change failed on the bus, answered once a retry made it so (or
    /// gave up), at the latest after TORQUE_ANSWER_WAIT: a bus hiccup is not the answer.
    pending_torque: Option<PendingTorque>,
    parameters: ParameterServer,
    stats: CycleStats,
    next_diagnostics: Instant,
    warnings: RateLimiter,
    /// The link generation whose port handle the last words go out on.
    last_words_generation: Option<u64>,
    // Declared last: dropped after the publishers and readers that belong to it.
    _node: RosNode,
}

impl Driver {
    fn run(&mut self, shutdown: &Shutdown) -> CycleSummary {
        let started = Instant::now();
        let deadline = self
            .args
            .duration
            .map(|seconds| started + Duration::from_secs_f64(seconds));
        let mut schedule = self
            .args
            .rate
            .period()
            .map(|period| Schedule::new(period, started));
        self.stats = CycleStats::new(started);
        while !shutdown.is_requested() && deadline.is_none_or(|deadline| Instant::now() < deadline)
        {
            let due = schedule.as_ref().map(Schedule::next_due);
            if let Some(due) = due {
                let now = Instant::now();
                if now < due {
                    std::thread::sleep((due - now).min(MAX_SLEEP));
                    continue;
                }
            }
            let now = Instant::now();
            if let Some(schedule) = schedule.as_mut() {
                if schedule.advance(now) {
                    self.stats.overruns += 1;
                }
            }
            self.stats.record_start(now, due);
            self.cycle(now);
        }
        self.stats.summary(Instant::now())
    }

    fn cycle(&mut self, now: Instant) {
        let clock = self.clock_origin.0 + (now - self.clock_origin.1).as_secs_f64();
        self.apply_parameters();
        self.take_trajectories(clock);
        self.take_commands(now);
        self.follow_trajectory(clock, now);
        self.serve_torque_requests(now);
        let output = self.controller.cycle(now);
        self.answer_pending_torque(now);
        self.keep_last_words_line();
        if let Some(positions) = &output.positions {
            // Stamped when the cycle began, right before the positions were read: the instant
            // they describe (the publish comes after the bus's read and write).
            self.publish_joints(positions, &output, Time::from_secs_f64(clock));
            if let Some(arm) = self.arm.as_mut() {
                arm.after_period(clock, positions, &output.velocities);
            }
        }
        if !self.controller.is_connected() && self.args.rate.period().is_none() {
            std::thread::sleep(DISCONNECTED_REST);
        }
        if now >= self.next_diagnostics {
            self.next_diagnostics = now + DIAGNOSTICS_PERIOD;
            self.publish_diagnostics();
        }
    }

    /// Safety limits set since the last cycle take effect now.
    fn apply_parameters(&mut self) {
        for change in self.parameters.changes() {
            let safety = self.controller.safety();
            if let Some(safety) = parameters::safety_with(safety, &change.name, &change.value) {
                tracing::info!(?safety, "safety limits changed");
                self.controller.set_safety(safety);
            }
        }
    }

    /// Points the last words (panic, second signal) at the current port handle, unless the user
    /// wants torque kept on exit.
    fn keep_last_words_line(&mut self) {
        let generation = self.controller.link_generation();
        if self.last_words_generation == Some(generation) {
            return;
        }
        self.last_words_generation = Some(generation);
        let line = (!self.args.keep_torque_on_exit)
            .then(|| self.controller.last_words_line())
            .flatten();
        emergency::set_line(line);
    }

    /// New trajectories and goals: refused while torque is off or the arm's position is unknown
    /// (they start from it); torque gone (the user, a fault) ends the running one.
    fn take_trajectories(&mut self, clock: f64) {
        let Some(arm) = self.arm.as_mut() else {
            return;
        };
        let torque_on = self.controller.torque_is_on();
        if !torque_on && arm.is_busy() {
            arm.preempt("torque is off");
        }
        let present = self.controller.present_positions();
        let refusal = if !torque_on {
            Some("torque is off: call /torque_enable true first")
        } else if present.is_none() {
            Some("the arm's position is unknown (bus fault)")
        } else {
            None
        };
        // With a refusal nothing starts, so the positions are never read then.
        let start = || present.unwrap_or([0.0; so101_core::robot::JOINT_COUNT]);
        arm.take_new(clock, &start, self.controller.limits(), refusal);
    }

    /// The running trajectory's setpoint becomes the command of this cycle (max_step and the
    /// limits still apply in the controller).
    fn follow_trajectory(&mut self, clock: f64, now: Instant) {
        let Some(targets) = self.arm.as_ref().and_then(|arm| arm.targets(clock)) else {
            return;
        };
        if !self.controller.command(&targets, now) {
            if let Some(arm) = self.arm.as_mut() {
                arm.preempt("the arm's position is unknown (bus fault)");
            }
        }
    }

    fn take_commands(&mut self, now: Instant) {
        let Some(inbox) = self.inbox.as_mut() else {
            return;
        };
        let commands = inbox.drain();
        if !commands.is_empty() {
            if let Some(arm) = self.arm.as_mut() {
                arm.preempt("a direct command arrived");
            }
        }
        let ignored = commands
            .iter()
            .filter(|command| !self.controller.command(command, now))
            .count();
        if ignored > 0 {
            if let Some(suppressed) = self.warnings.check(now) {
                tracing::warn!(
                    suppressed,
                    "commands ignored: the arm's position is unknown (bus fault)"
                );
            }
        }
    }

    fn serve_torque_requests(&mut self, now: Instant) {
        while let Some((request, on)) = self.torque_service.next() {
            if let Some(pending) = self.pending_torque.take() {
                let message = "superseded by a later torque_enable call".to_owned();
                self.torque_service.answer(pending.id, false, message);
            }
            if let Some(arm) = self.arm.as_mut() {
                arm.preempt("torque was switched");
            }
            let (success, message) = self.controller.request_torque(on);
            if !success && self.controller.torque_outcome(on).is_none() {
                tracing::warn!(on, %message, "torque_enable: retrying before answering");
                self.pending_torque = Some(PendingTorque {
                    id: request,
                    on,
                    deadline: now + TORQUE_ANSWER_WAIT,
                    message,
                });
                continue;
            }
            tracing::info!(on, success, %message, "torque_enable");
            self.torque_service.answer(request, success, message);
        }
    }

    /// Answers the waiting torque_enable call once the retries decided it, or its time is up.
    fn answer_pending_torque(&mut self, now: Instant) {
        let Some(pending) = &self.pending_torque else {
            return;
        };
        let state = if pending.on { "on" } else { "off" };
        let (success, message) = match self.controller.torque_outcome(pending.on) {
            Some(true) => (
                true,
                format!("torque {state} (after a retry: {})", pending.message),
            ),
            Some(false) => (
                false,
                self.controller
                    .torque_problem()
                    .map_or_else(|| pending.message.clone(), str::to_owned),
            ),
            None if now >= pending.deadline => (false, pending.message.clone()),
            None => return,
        };
        if let Some(pending) = self.pending_torque.take() {
            tracing::info!(on = pending.on, success, %message, "torque_enable");
            self.torque_service.answer(pending.id, success, message);
        }
    }

    fn publish_joints(&mut self, positions: &[f64], output: &CycleOutput, stamp: Time) {
        self.outputs.send(Output::Joints(JointState {
            header: Header {
                stamp,
                frame_id: String::new(),
            },
            name: so101_core::robot::JOINT_NAMES
                .iter()
                .map(|name| name.to_string())
                .collect(),
            position: positions.to_vec(),
            velocity: output.velocities.clone(),
            effort: Vec::new(),
        }));
    }

    fn report(&self) -> DriverReport {
        let status = self.controller.status();
        let (accepted, rejected) = self
            .inbox
            .as_ref()
            .map_or((0, 0), |inbox| (inbox.tally.accepted, inbox.tally.rejected));
        DriverReport {
            node_name: self.node_name.clone(),
            port: self.args.port.port.display().to_string(),
            connected: status.connected,
            problem: status.problem,
            leader: self.inbox.is_none(),
            torque_on: status.torque_on,
            cycle_rate: self.stats.recent_rate(),
            requested_rate: match self.args.rate {
                CycleRate::Hz(hz) => Some(hz),
                CycleRate::Max => None,
            },
            cycles: self.stats.cycles(),
            lateness_p99_us: self.stats.recent_lateness_p99_us(),
            overruns: self.stats.overruns,
            failed_cycles: status.failed_cycles,
            reconnects: status.reconnects,
            bus: status.bus,
            commands_accepted: accepted,
            commands_rejected: rejected,
            safety: status.safety,
            dropped_messages: self.outputs.dropped,
            servos: status.servos,
        }
    }

    fn publish_diagnostics(&mut self) {
        let status = diagnostics::statuses(&self.report());
        self.outputs.send(Output::Diagnostics(DiagnosticArray {
            header: Header {
                stamp: Time::now(),
                frame_id: String::new(),
            },
            status,
        }));
    }

    /// Torque off (unless asked to keep it), then the exit summary.
    fn finish(mut self, cycles: CycleSummary, started_cpu: Duration) -> Result<()> {
        self.controller.shutdown(self.args.keep_torque_on_exit);
        emergency::set_line(None);
        let cpu = cpu_time().saturating_sub(started_cpu);
        let report = self.report();
        let summary = RunSummary {
            port: report.port.clone(),
            requested_rate_hz: report.requested_rate,
            cycles,
            cpu_percent: 100.0 * cpu.as_secs_f64() / cycles.seconds.max(1e-9),
            bus: report.bus,
            safety: report.safety,
            failed_cycles: report.failed_cycles,
            reconnects: report.reconnects,
            commands_accepted: report.commands_accepted,
            commands_rejected: report.commands_rejected,
            dropped_messages: report.dropped_messages,
        };
        tracing::info!(
            cycles = cycles.cycles,
            cycles_per_second = format!("{:.1}", cycles.cycles_per_second),
            lateness_p99_us = cycles.lateness_p99_us,
            cpu_percent = format!("{:.1}", summary.cpu_percent),
            failed_cycles = summary.failed_cycles,
            reconnects = summary.reconnects,
            timeouts = summary.bus.timeouts,
            "shutting down"
        );
        if let Some(path) = &self.args.stats_json {
            let text = serde_json::to_string_pretty(&summary)?;
            std::fs::write(path, text)
                .with_context(|| format!("cannot write {}", path.display()))?;
        }
        Ok(())
    }
}

/// The exit summary (--stats-json): what the benchmark reads.
#[derive(Debug, serde::Serialize)]
struct RunSummary {
    port: String,
    requested_rate_hz: Option<f64>,
    cycles: CycleSummary,
    cpu_percent: f64,
    bus: BusStats,
    safety: SafetyCounters,
    failed_cycles: u64,
    reconnects: u64,
    commands_accepted: u64,
    commands_rejected: u64,
    dropped_messages: u64,
}

/// CPU time (user + system) this process used so far.
fn cpu_time() -> Duration {
    use nix::sys::resource::{getrusage, UsageWho};
    match getrusage(UsageWho::RUSAGE_SELF) {
        Ok(usage) => {
            let micros = |time: nix::sys::time::TimeVal| {
                Duration::from_secs(time.tv_sec().max(0) as u64)
                    + Duration::from_micros(time.tv_usec().max(0) as u64)
            };
            micros(usage.user_time()) + micros(usage.system_time())
        }
        Err(_) => Duration::ZERO,
    }
}
