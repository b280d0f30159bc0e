//! The control loop: every cycle one SYNC_READ of positions, joint states out, commands in, one
//! SYNC_WRITE of goals; telemetry and diagnostics at lower rates; faults contained and the bus
//! reconnected by itself.
//!
//! A goal is only ever computed from positions read in the same cycle: when a read fails, nothing
//! is written (the servos keep their last goal) and nothing is published.

use std::{
    path::PathBuf,
    time::{Duration, Instant},
};

use anyhow::{Context, Result};
use so101_core::{
    robot::{JointLimit, JointPositions, JOINT_COUNT, JOINT_NAMES},
    ros::{command_inbox::CommandInbox, rate_limit::RateLimiter, shutdown::Shutdown, RosNode},
};
use so101_msgs::{
    builtin_interfaces::Time, diagnostic_msgs::DiagnosticArray, sensor_msgs::JointState,
    std_msgs::Header,
};

use super::{
    cycle_stats::{CycleStats, CycleSummary, Schedule},
    diagnostics::{self, DriverReport, ServoReport},
    ros_io::{Output, Outputs, TorqueService},
};
use crate::{
    arm::{broadcast_torque_off, Arm, ArmSettings, Telemetry},
    bus::{usb_latency_timer_ms, BusError, BusStats},
    calibration::{ArmCalibration, ArmRole},
    cli::RunArgs,
    protocol::ServoErrors,
    safety::{GoalShaper, SafetyConfig, SafetyCounters},
};

const DIAGNOSTICS_PERIOD: Duration = Duration::from_secs(1);
/// Longest single sleep, so a shutdown request is seen quickly.
const MAX_SLEEP: Duration = Duration::from_millis(50);
/// Telemetry older than this is not used for joint velocities.
const TELEMETRY_MAX_AGE: Duration = Duration::from_millis(500);
/// How often a torque state that does not match the wish is retried.
const TORQUE_RETRY: Duration = Duration::from_millis(500);
/// A position further than this outside its calibrated range (ticks, ~18 degrees) is not a joint
/// pushed by hand but a wrong calibration or a bad reading: no goal is computed from it.
const IMPLAUSIBLE_MARGIN_TICKS: i32 = 200;
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
    let settings = ArmSettings {
        bus: args.port.bus_config(),
        role,
        gripper_torque_limit: args.gripper_torque_limit,
    };
    let arm = Arm::connect(&args.port.port, &settings, calibration.clone())
        .with_context(|| format!("cannot start the arm on {}", args.port.port.display()))?;
    tracing::info!(port = %args.port.port.display(), servos = ?arm.servos, "arm connected");

    let shutdown = Shutdown::on_signals().context("cannot install the signal handlers")?;
    let leader = role == ArmRole::Leader;
    let node_name = if leader {
        "so101_leader_driver"
    } else {
        "so101_feetech_driver"
    };
    let mut node = RosNode::start(node_name, &args.node)?;
    let outputs = Outputs::start(
        &mut node,
        if leader {
            "leader/joint_states"
        } else {
            "joint_states"
        },
    )?;
    let inbox = if leader {
        None
    } else {
        Some(CommandInbox::subscribe(&mut node)?)
    };
    let torque_service = TorqueService::serve(&mut node)?;
    let limits = calibration
        .limits_in_radians()
        .map(|(low, high)| JointLimit::new(low, high));
    let shaper = GoalShaper::new(
        SafetyConfig {
            max_step: args.max_step,
            command_timeout: (args.command_timeout > 0.0)
                .then(|| Duration::from_secs_f64(args.command_timeout)),
        },
        limits,
    );
    let now = Instant::now();
    let mut driver = Driver {
        torque_wanted: !leader && !args.start_torque_off,
        torque_on: false,
        torque_uncertain: false,
        next_torque_attempt: now,
        leader,
        node_name: node_name.to_owned(),
        port: args.port.port.clone(),
        settings,
        calibration,
        link: Link::Up(Box::new(arm)),
        shaper,
        outputs,
        inbox,
        torque_service,
        stats: CycleStats::new(now),
        present: None,
        present_ticks: None,
        telemetry: None,
        answering: [true; JOINT_COUNT],
        last_good_read: now,
        failed_cycles: 0,
        reconnects: 0,
        problem: None,
        bus_totals: BusStats::default(),
        next_telemetry: now,
        next_diagnostics: now + DIAGNOSTICS_PERIOD,
        warnings: RateLimiter::new(Duration::from_secs(2)),
        started_cpu: cpu_time(),
        args,
        _node: node,
    };
    if let Err(error) = driver.apply_torque_wish() {
        // Some servos may have taken torque on before the failure: none may stay stiff.
        driver.torque_wanted = false;
        driver.torque_off_on_exit();
        return Err(error).context("cannot set the servos' torque at start");
    }
    let summary = driver.run(&shutdown);
    driver.finish(summary)
}

enum Link {
    Up(Box<Arm>),
    Down { next_attempt: Instant },
}

struct Driver {
    args: RunArgs,
    leader: bool,
    node_name: String,
    port: PathBuf,
    settings: ArmSettings,
    calibration: ArmCalibration,
    link: Link,
    shaper: GoalShaper,
    /// What the user asked for (start-up flag, service); restored after a reconnect.
    torque_wanted: bool,
    /// Torque is on and confirmed by every servo: only then are goals written.
    torque_on: bool,
    /// A torque change failed part-way: the servos' state is not known until a retry succeeds.
    torque_uncertain: bool,
    next_torque_attempt: Instant,
    outputs: Outputs,
    inbox: Option<CommandInbox>,
    torque_service: TorqueService,
    stats: CycleStats,
    present: Option<JointPositions>,
    present_ticks: Option<[i32; JOINT_COUNT]>,
    telemetry: Option<([Telemetry; JOINT_COUNT], Instant)>,
    answering: [bool; JOINT_COUNT],
    last_good_read: Instant,
    failed_cycles: u64,
    reconnects: u64,
    problem: Option<String>,
    /// Bus counters of earlier connections.
    bus_totals: BusStats,
    next_telemetry: Instant,
    next_diagnostics: Instant,
    warnings: RateLimiter,
    started_cpu: Duration,
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
        self.take_commands(now);
        self.serve_torque_requests();
        if matches!(self.link, Link::Down { .. }) {
            self.try_reconnect(now);
            if self.args.rate.period().is_none() && matches!(self.link, Link::Down { .. }) {
                std::thread::sleep(DISCONNECTED_REST);
            }
        } else {
            self.reconcile_torque(now);
            self.exchange(now);
            if now >= self.next_telemetry && self.present.is_some() {
                self.next_telemetry = now + Duration::from_secs_f64(1.0 / self.args.telemetry_rate);
                self.read_telemetry(now);
            }
        }
        if now >= self.next_diagnostics {
            self.next_diagnostics = now + DIAGNOSTICS_PERIOD;
            self.publish_diagnostics();
        }
    }

    /// The bus part of a cycle: read positions, publish them, write goals computed from them.
    fn exchange(&mut self, now: Instant) {
        let Link::Up(arm) = &mut self.link else {
            return;
        };
        let ticks = match arm.read_positions() {
            Ok(ticks) => ticks,
            Err(error) => {
                self.failed_cycles += 1;
                self.present = None;
                self.bus_fault(error, now);
                return;
            }
        };
        if let Some(problem) = Self::implausible(&self.calibration, &ticks, arm) {
            self.failed_cycles += 1;
            self.present = None;
            if self.problem.as_deref() != Some(problem.as_str()) {
                tracing::error!("{problem}");
            }
            self.problem = Some(problem);
            return;
        }
        let positions: JointPositions =
            std::array::from_fn(|joint| self.calibration.radians_from_ticks(joint, ticks[joint]));
        self.last_good_read = now;
        self.answering = [true; JOINT_COUNT];
        self.problem = None;
        self.present = Some(positions);
        self.present_ticks = Some(ticks);
        // Goals first, the report after: the servos should not wait for the publisher.
        if !self.leader && self.torque_on {
            let goals = self.shaper.goals(&positions, now);
            let goal_ticks = std::array::from_fn(|joint| {
                self.calibration.ticks_from_radians(joint, goals[joint])
            });
            if let Err(error) = arm.write_goals(&goal_ticks) {
                self.bus_fault(error, now);
            }
        }
        self.publish_joints(&positions, now);
    }

    /// Why these readings must not be acted on, if they must not: far outside the calibrated
    /// range, or from a servo that reports its angle sensor failing.
    fn implausible(
        calibration: &ArmCalibration,
        ticks: &[i32; JOINT_COUNT],
        arm: &Arm,
    ) -> Option<String> {
        for (joint, (&tick, motor)) in ticks.iter().zip(&calibration.motors).enumerate() {
            if arm.bus.servo_errors(motor.id).0 & ServoErrors::ANGLE_SENSOR != 0 {
                return Some(format!(
                    "{} (id {}) reports an angle sensor error: goals withheld",
                    JOINT_NAMES[joint], motor.id
                ));
            }
            let low = motor.range_min - IMPLAUSIBLE_MARGIN_TICKS;
            let high = motor.range_max + IMPLAUSIBLE_MARGIN_TICKS;
            if !(low..=high).contains(&tick) {
                return Some(format!(
                    "{} (id {}) reads {tick} ticks, far outside its calibrated range {}..{}: wrong calibration file? Goals withheld",
                    JOINT_NAMES[joint], motor.id, motor.range_min, motor.range_max
                ));
            }
        }
        None
    }

    /// Retries a torque state that does not match the wish (a failed change, a reconnect).
    fn reconcile_torque(&mut self, now: Instant) {
        let matches = self.torque_on == self.torque_wanted && !self.torque_uncertain;
        if matches || now < self.next_torque_attempt {
            return;
        }
        self.next_torque_attempt = now + TORQUE_RETRY;
        if self.apply_torque_wish().is_ok() {
            tracing::info!(on = self.torque_on, "torque state restored");
        }
    }

    fn read_telemetry(&mut self, now: Instant) {
        let Link::Up(arm) = &mut self.link else {
            return;
        };
        match arm.read_telemetry() {
            Ok(telemetry) => self.telemetry = Some((telemetry, now)),
            // Not fatal: positions are what the loop needs; a lost port shows up there too.
            Err(error) if error.is_disconnected() => self.bus_fault(error, now),
            Err(error) => tracing::debug!(%error, "telemetry read failed"),
        }
    }

    fn take_commands(&mut self, now: Instant) {
        let Some(inbox) = self.inbox.as_mut() else {
            return;
        };
        let commands = inbox.drain();
        if commands.is_empty() {
            return;
        }
        match self.present {
            Some(present) => {
                for command in &commands {
                    self.shaper.command(command, &present, now);
                }
            }
            None => {
                if let Some(suppressed) = self.warnings.check(now) {
                    tracing::warn!(
                        suppressed,
                        "commands ignored: the arm's position is unknown (bus fault)"
                    );
                }
            }
        }
    }

    fn serve_torque_requests(&mut self) {
        while let Some((request, on)) = self.torque_service.next() {
            let (success, message) = if on && self.leader {
                (
                    false,
                    "a leader arm keeps torque off (it is moved by hand)".to_owned(),
                )
            } else {
                self.torque_wanted = on;
                match &self.link {
                    Link::Down { .. } if !on => {
                        match broadcast_torque_off(&self.port, self.settings.bus) {
                            Ok(()) => (
                                true,
                                "the arm is disconnected: torque off was broadcast (unconfirmed)"
                                    .to_owned(),
                            ),
                            Err(error) => (
                                false,
                                format!(
                                "the arm is disconnected and torque off could not be sent: {error}"
                            ),
                            ),
                        }
                    }
                    Link::Down { .. } => (
                        false,
                        "the arm is disconnected; torque will be on once it is back".to_owned(),
                    ),
                    Link::Up(_) => match self.apply_torque_wish() {
                        Ok(()) => (true, format!("torque {}", if on { "on" } else { "off" })),
                        Err(error) => (
                            false,
                            format!(
                                "torque change failed ({error}); retrying every {TORQUE_RETRY:?}"
                            ),
                        ),
                    },
                }
            };
            tracing::info!(on, success, %message, "torque_enable");
            self.torque_service.answer(request, success, message);
        }
    }

    /// Brings the servos' torque in line with `torque_wanted`. Turning it on first makes the
    /// present position the goal, so the arm does not jump to an old one.
    fn apply_torque_wish(&mut self) -> Result<(), TorqueError> {
        let Link::Up(arm) = &mut self.link else {
            return Ok(());
        };
        let result = if self.torque_wanted {
            let calibration = &self.calibration;
            arm.read_positions()
                .map_err(TorqueError::from)
                .and_then(|ticks| match Self::implausible(calibration, &ticks, arm) {
                    Some(problem) => Err(TorqueError::Implausible(problem)),
                    None => Ok(ticks),
                })
                .and_then(|ticks| {
                    let present: JointPositions = std::array::from_fn(|joint| {
                        self.calibration.radians_from_ticks(joint, ticks[joint])
                    });
                    self.shaper.hold(&present);
                    let held = self.shaper.targets().copied().unwrap_or(present);
                    let goals = std::array::from_fn(|joint| {
                        self.calibration.ticks_from_radians(joint, held[joint])
                    });
                    arm.write_goals(&goals)?;
                    Ok(arm.set_torque(true)?)
                })
        } else {
            arm.set_torque(false).map_err(TorqueError::from)
        };
        match &result {
            Ok(()) => {
                self.torque_on = self.torque_wanted;
                self.torque_uncertain = false;
            }
            Err(error) => {
                // Some servos may have switched: no goals until a retry confirms all of them.
                self.torque_on = false;
                self.torque_uncertain = true;
                self.problem = Some(format!("torque change failed: {error}"));
                tracing::error!(%error, wanted = self.torque_wanted, "cannot change torque");
            }
        }
        result
    }

    fn bus_fault(&mut self, error: BusError, now: Instant) {
        if let BusError::NoAnswer { missing, .. } = &error {
            let ids = self.calibration.ids();
            self.answering = std::array::from_fn(|joint| !missing.contains(&ids[joint]));
            let joints: Vec<&str> = (0..JOINT_COUNT)
                .filter(|joint| !self.answering[*joint])
                .map(|joint| JOINT_NAMES[joint])
                .collect();
            self.problem = Some(format!(
                "no answer from {} (ids {missing:?}): goals withheld",
                joints.join(", ")
            ));
        } else {
            self.problem = Some(error.to_string());
        }
        let silent_for = now.duration_since(self.last_good_read);
        let reopen =
            error.is_disconnected() || silent_for > Duration::from_secs_f64(self.args.reopen_after);
        if reopen {
            tracing::error!(%error, silent_for = ?silent_for, "bus lost: reconnecting by itself");
            self.disconnect(now, format!("bus lost ({error}); reconnecting"));
        } else if let Some(suppressed) = self.warnings.check(now) {
            tracing::warn!(suppressed, "{}", self.problem.as_deref().unwrap_or(""));
        }
    }

    fn disconnect(&mut self, now: Instant, problem: String) {
        if let Link::Up(arm) = &self.link {
            self.bus_totals = self.bus_totals.plus(arm.bus.stats());
        }
        self.link = Link::Down { next_attempt: now };
        self.problem = Some(problem);
        self.present = None;
        // Unknown until the servos answer again; reconcile_torque restores the wish then.
        self.torque_on = false;
        self.torque_uncertain = true;
        self.answering = [false; JOINT_COUNT];
    }

    fn try_reconnect(&mut self, now: Instant) {
        let Link::Down { next_attempt } = self.link else {
            return;
        };
        if now < next_attempt {
            return;
        }
        match Arm::reattach(&self.port, &self.settings, self.calibration.clone()) {
            Ok(arm) => {
                self.reconnects += 1;
                self.link = Link::Up(Box::new(arm));
                self.last_good_read = now;
                self.problem = None;
                tracing::info!(reconnects = self.reconnects, "bus reconnected");
                self.next_torque_attempt = now;
                self.reconcile_torque(now);
            }
            Err(error) => {
                self.link = Link::Down {
                    next_attempt: now + Duration::from_secs_f64(self.args.reconnect_interval),
                };
                self.problem = Some(format!("reconnecting: {error}"));
                if let Some(suppressed) = self.warnings.check(now) {
                    tracing::warn!(suppressed, %error, "reconnection failed; trying again");
                }
            }
        }
    }

    fn publish_joints(&mut self, positions: &JointPositions, now: Instant) {
        let velocity = match self.telemetry {
            Some((telemetry, at)) if now.duration_since(at) <= TELEMETRY_MAX_AGE => (0
                ..JOINT_COUNT)
                .map(|joint| {
                    self.calibration
                        .radians_per_second(joint, telemetry[joint].velocity)
                })
                .collect(),
            _ => Vec::new(),
        };
        self.outputs.send(Output::Joints(JointState {
            header: Header {
                stamp: Time::now(),
                frame_id: String::new(),
            },
            name: JOINT_NAMES.iter().map(|name| name.to_string()).collect(),
            position: positions.to_vec(),
            velocity,
            effort: Vec::new(),
        }));
    }

    fn report(&self) -> DriverReport {
        let (bus, errors) = match &self.link {
            Link::Up(arm) => (
                self.bus_totals.plus(arm.bus.stats()),
                self.calibration.ids().map(|id| arm.bus.servo_errors(id)),
            ),
            Link::Down { .. } => (self.bus_totals, Default::default()),
        };
        let ids = self.calibration.ids();
        let (accepted, rejected) = self
            .inbox
            .as_ref()
            .map_or((0, 0), |inbox| (inbox.tally.accepted, inbox.tally.rejected));
        DriverReport {
            node_name: self.node_name.clone(),
            port: self.port.display().to_string(),
            connected: matches!(self.link, Link::Up(_)),
            problem: self.problem.clone(),
            leader: self.leader,
            torque_on: self.torque_on,
            cycle_rate: self.stats.recent_rate(),
            requested_rate: match self.args.rate {
                crate::cli::CycleRate::Hz(hz) => Some(hz),
                crate::cli::CycleRate::Max => None,
            },
            cycles: self.stats.cycles(),
            lateness_p99_us: self.stats.recent_lateness_p99_us(),
            overruns: self.stats.overruns,
            failed_cycles: self.failed_cycles,
            reconnects: self.reconnects,
            bus,
            commands_accepted: accepted,
            commands_rejected: rejected,
            safety: self.shaper.counters,
            dropped_messages: self.outputs.dropped,
            servos: std::array::from_fn(|joint| ServoReport {
                id: ids[joint],
                answering: self.answering[joint],
                errors: errors[joint],
                position_ticks: self.present_ticks.map(|ticks| ticks[joint]),
                telemetry: self.telemetry.map(|(telemetry, _)| telemetry[joint]),
            }),
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

    /// Torque off on every servo that can hear it: acknowledged one by one when the arm is
    /// connected, broadcast when it is not (it may be half there).
    fn torque_off_on_exit(&mut self) {
        let result = match &mut self.link {
            Link::Up(arm) => arm.set_torque(false).map_err(|error| error.to_string()),
            Link::Down { .. } => broadcast_torque_off(&self.port, self.settings.bus)
                .map_err(|error| error.to_string()),
        };
        match result {
            Ok(()) => tracing::info!("torque off"),
            Err(error) => tracing::error!(%error, "could not confirm torque off on exit"),
        }
    }

    /// Torque off (unless asked to keep it), then the exit summary.
    fn finish(mut self, cycles: CycleSummary) -> Result<()> {
        if !self.args.keep_torque_on_exit && !self.leader {
            self.torque_off_on_exit();
        }
        let cpu = cpu_time().saturating_sub(self.started_cpu);
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

#[derive(Debug, thiserror::Error)]
enum TorqueError {
    #[error(transparent)]
    Bus(#[from] BusError),
    #[error("{0}")]
    Implausible(String),
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
