//! The driver's state machine, without ROS: the link to the arm (up, or down and reconnecting),
//! the torque the user asked for and the torque the servos have, and one control cycle (read,
//! check, goals, write). Generic over where the bus comes from, so it runs on a serial port in
//! the node and on the in-process emulator in its tests.
//!
//! Rules it keeps, whatever fails:
//! - A goal is only computed from positions read in the same cycle, that passed the plausibility
//!   checks; after a failed read nothing is written (the servos keep their last goal).
//! - Torque off reaches every servo: each one told in turn, then a broadcast for any that did not
//!   confirm; at exit, on request, when the link is lost and before any reconfiguration.
//! - Torque comes on only holding where the joints are, and never for a joint so far outside its
//!   range that the servo would jump back into it.
//! - After a reconnect, servos whose EPROM calibration differs are refused, never written.

use std::time::{Duration, Instant};

use so101_core::{
    command::PartialTargets,
    robot::{JointLimit, JointPositions, JOINT_COUNT, JOINT_NAMES},
};

mod link;
mod torque;

use super::diagnostics::ServoReport;
use crate::{
    arm::{
        connect_bus, reopen_and_broadcast_torque_off, Arm, ArmError, ArmSettings, CalibrationWrite,
        Telemetry,
    },
    bus::{BusError, BusStats, Connector, Transport},
    calibration::ArmCalibration,
    protocol::ServoErrors,
    safety::{GoalShaper, ReadingFilter, SafetyConfig, SafetyCounters},
};

/// How often a torque state that does not match the wish is retried.
pub const TORQUE_RETRY: Duration = Duration::from_millis(500);
/// How long a /torque_enable call whose change failed on the bus waits for the retries before it
/// is answered (the third failed torque-on gives up sooner).
pub const TORQUE_ANSWER_WAIT: Duration = Duration::from_secs(2);
/// A position further than this outside its calibrated range (ticks, ~18 degrees) is not a joint
/// pushed by hand but a wrong calibration or a bad reading: no goal is computed from it.
const IMPLAUSIBLE_MARGIN_TICKS: i32 = 200;
/// Telemetry older than this is not used for joint velocities.
const TELEMETRY_MAX_AGE: Duration = Duration::from_millis(500);

/// How the controller behaves; the node fills it from its flags.
#[derive(Debug, Clone)]
pub struct ControllerConfig {
    /// A leader arm: torque stays off, commands are not taken.
    pub leader: bool,
    pub safety: SafetyConfig,
    /// Torque on once connected (not for a leader).
    pub torque_at_start: bool,
    /// Whether the calibration file may be written into the servos at start.
    pub calibration_write: CalibrationWrite,
    /// No good read for this long: the port is closed and the arm reconnected.
    pub reopen_after: Duration,
    pub reconnect_interval: Duration,
    pub telemetry_period: Duration,
}

/// What the user asked for and what the servos have.
#[derive(Debug, Clone, Copy)]
struct Torque {
    wanted: bool,
    /// On, and confirmed by every servo: only then are goals written.
    on: bool,
    /// A change failed part-way: the servos' state is not known until a retry succeeds.
    uncertain: bool,
    next_attempt: Instant,
    /// Torque-on attempts that failed in a row.
    failed_on: u32,
}

enum Link<T: Transport> {
    Up(Box<Arm<T>>),
    Down { next_attempt: Instant },
}

/// Why torque is not what the user asked for.
#[derive(Debug, Clone)]
enum TorqueProblem {
    /// A change failed; retried until it works.
    Failed(String),
    /// Refused or dropped for a reason the user must see to (a joint outside its range, an
    /// overloaded servo); stays until the user asks again and it works.
    NeedsUser(String),
}

impl TorqueProblem {
    fn text(&self) -> &str {
        match self {
            Self::Failed(text) | Self::NeedsUser(text) => text,
        }
    }
}

/// Positions read in the current cycle.
#[derive(Debug, Clone, Copy)]
struct Present {
    radians: JointPositions,
    ticks: [i32; JOINT_COUNT],
}

/// What a cycle produced for the node to publish.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct CycleOutput {
    /// Joint positions (rad), when they were read and plausible.
    pub positions: Option<JointPositions>,
    /// Joint velocities (rad/s) from fresh telemetry; empty when there is none.
    pub velocities: Vec<f64>,
}

/// The controller's part of /diagnostics.
#[derive(Debug, Clone)]
pub struct ControllerStatus {
    pub connected: bool,
    pub problem: Option<String>,
    pub torque_on: bool,
    pub failed_cycles: u64,
    pub reconnects: u64,
    pub bus: BusStats,
    pub safety: SafetyCounters,
    pub servos: [ServoReport; JOINT_COUNT],
}

#[derive(Debug, thiserror::Error)]
pub enum StartError {
    #[error(transparent)]
    Arm(#[from] ArmError),
    #[error("cannot set the servos' torque at start: {0}")]
    Torque(TorqueError),
}

#[derive(Debug, thiserror::Error)]
pub enum TorqueError {
    #[error(transparent)]
    Bus(#[from] BusError),
    #[error("{0}")]
    Refused(String),
    /// The readings themselves cannot be trusted (a wrong calibration file, a failing sensor).
    #[error("{0}")]
    Implausible(String),
    /// Consecutive readings disagree: where the arm is is not known well enough to hold it.
    #[error("the joints' readings disagree: {0}")]
    Unsteady(String),
    #[error("torque off not confirmed by servo(s) {0:?}")]
    Unconfirmed(Vec<u8>),
}

pub struct Controller<C: Connector> {
    config: ControllerConfig,
    connector: C,
    settings: ArmSettings,
    calibration: ArmCalibration,
    limits: [JointLimit; JOINT_COUNT],
    link: Link<C::Transport>,
    shaper: GoalShaper,
    readings: ReadingFilter,
    torque: Torque,
    present: Option<Present>,
    telemetry: Option<([Telemetry; JOINT_COUNT], Instant)>,
    next_telemetry: Instant,
    answering: [bool; JOINT_COUNT],
    last_good_read: Instant,
    failed_cycles: u64,
    reconnects: u64,
    /// What is wrong with the link or the readings; cleared by the next good read.
    problem: Option<String>,
    /// Why torque is not what the user asked for.
    torque_problem: Option<TorqueProblem>,
    /// Bus counters of earlier connections.
    bus_totals: BusStats,
    /// Bumped whenever the link goes up or down (a new port handle, or none).
    link_generation: u64,
}

impl<C: Connector> Controller<C> {
    /// Connects to the arm (the servos found, checked and configured) and brings torque to what
    /// `config` asks. A torque-on refused for a joint outside its range is not an error: the
    /// controller runs with torque off and says why.
    pub fn start(
        mut connector: C,
        settings: ArmSettings,
        calibration: ArmCalibration,
        config: ControllerConfig,
        now: Instant,
    ) -> Result<Self, StartError> {
        let bus = connect_bus(&mut connector, settings.bus)?;
        let arm = Arm::connect_on(
            bus,
            &settings,
            calibration.clone(),
            config.calibration_write,
        )?;
        tracing::info!(port = %connector.describe(), servos = ?arm.servos, "arm connected");
        let limits = calibration
            .limits_in_radians()
            .map(|(low, high)| JointLimit::new(low, high));
        let mut controller = Self {
            shaper: GoalShaper::new(config.safety, limits),
            torque: Torque {
                wanted: config.torque_at_start && !config.leader,
                on: false,
                uncertain: true,
                next_attempt: now,
                failed_on: 0,
            },
            config,
            connector,
            settings,
            calibration,
            limits,
            link: Link::Up(Box::new(arm)),
            readings: ReadingFilter::default(),
            present: None,
            telemetry: None,
            next_telemetry: now,
            answering: [true; JOINT_COUNT],
            last_good_read: now,
            failed_cycles: 0,
            reconnects: 0,
            problem: None,
            torque_problem: None,
            bus_totals: BusStats::default(),
            link_generation: 0,
        };
        match controller.apply_torque_wish() {
            Ok(()) | Err(TorqueError::Refused(_)) => Ok(controller),
            Err(error) => {
                // Some servos may have taken torque on before the failure: none may stay stiff.
                controller.torque.wanted = false;
                controller.torque_off_everywhere();
                Err(StartError::Torque(error))
            }
        }
    }

    /// The calibrated range of each joint (rad), where targets are clamped.
    pub fn limits(&self) -> &[JointLimit; JOINT_COUNT] {
        &self.limits
    }

    /// The latest plausible position reading (rad); `None` while the position is unknown.
    pub fn present_positions(&self) -> Option<JointPositions> {
        self.present.as_ref().map(|present| present.radians)
    }

    /// Whether the servos hold torque now.
    pub fn torque_is_on(&self) -> bool {
        self.torque.on
    }

    pub fn safety(&self) -> SafetyConfig {
        self.shaper.config()
    }

    /// New safety limits from the next cycle on.
    pub fn set_safety(&mut self, safety: SafetyConfig) {
        self.config.safety = safety;
        self.shaper.set_config(safety);
    }

    /// One control cycle at `now`.
    pub fn cycle(&mut self, now: Instant) -> CycleOutput {
        if matches!(self.link, Link::Down { .. }) {
            self.try_reconnect(now);
            return CycleOutput::default();
        }
        self.reconcile_torque(now);
        let positions = self.exchange(now);
        if now >= self.next_telemetry && positions.is_some() {
            self.next_telemetry = now + self.config.telemetry_period;
            self.read_telemetry(now);
        }
        CycleOutput {
            positions,
            velocities: self.velocities(now),
        }
    }

    /// A validated command; `false` when it cannot be taken (position unknown, or a leader).
    pub fn command(&mut self, targets: &PartialTargets, now: Instant) -> bool {
        match (&self.present, self.config.leader) {
            (Some(present), false) => {
                self.shaper.command(targets, &present.radians, now);
                true
            }
            _ => false,
        }
    }

    /// The /torque_enable service: success and a message in words.
    pub fn request_torque(&mut self, on: bool) -> (bool, String) {
        if on && self.config.leader {
            return (
                false,
                "a leader arm keeps torque off (it is moved by hand)".to_owned(),
            );
        }
        self.torque.wanted = on;
        self.torque.failed_on = 0;
        if let Link::Down { .. } = self.link {
            if on {
                return (
                    false,
                    "the arm is disconnected; torque will be on once it is back".to_owned(),
                );
            }
            return match reopen_and_broadcast_torque_off(&mut self.connector, self.settings.bus) {
                Ok(()) => (
                    true,
                    "the arm is disconnected: torque off was broadcast (unconfirmed)".to_owned(),
                ),
                Err(error) => (
                    false,
                    format!("the arm is disconnected and torque off could not be sent: {error}"),
                ),
            };
        }
        match self.apply_torque_wish() {
            Ok(()) => {
                self.torque_problem = None;
                (true, format!("torque {}", if on { "on" } else { "off" }))
            }
            Err(TorqueError::Refused(reason) | TorqueError::Implausible(reason)) => (false, reason),
            Err(error) => (
                false,
                format!("torque change failed ({error}); retrying every {TORQUE_RETRY:?}"),
            ),
        }
    }

    /// Where a torque wish `on` stands: met (`Some(true)`: every servo confirmed), given up or
    /// replaced (`Some(false)`: refused, failed too often, another wish), or still being retried
    /// (`None`: a change that failed on the bus, or an arm that is reconnecting).
    pub fn torque_outcome(&self, on: bool) -> Option<bool> {
        if self.torque.wanted != on {
            Some(false)
        } else if self.torque.on == on && !self.torque.uncertain {
            Some(true)
        } else {
            None
        }
    }

    /// Why the torque is not as wished, if the controller knows.
    pub fn torque_problem(&self) -> Option<&str> {
        self.torque_problem.as_ref().map(TorqueProblem::text)
    }

    /// Torque off on every servo that can hear it (unless `keep_torque_on`), for the way out.
    pub fn shutdown(&mut self, keep_torque_on: bool) {
        if keep_torque_on && !self.config.leader {
            tracing::info!("torque left as it is (--keep-torque-on-exit)");
        } else {
            self.torque.wanted = false;
            match self.torque_off_everywhere() {
                Some(report) if report.confirmed() => tracing::info!("torque off"),
                Some(report) => tracing::error!(
                    unacknowledged = ?report.unacknowledged,
                    broadcast_sent = !report.broadcast_failed,
                    "torque off not confirmed by every servo on exit; broadcast to them"
                ),
                None => tracing::warn!("disconnected on exit: torque off was broadcast"),
            }
        }
    }

    pub fn status(&self) -> ControllerStatus {
        let (bus, errors) = match &self.link {
            Link::Up(arm) => (
                self.bus_totals.plus(arm.bus.stats()),
                self.calibration.ids().map(|id| arm.bus.servo_errors(id)),
            ),
            Link::Down { .. } => (self.bus_totals, Default::default()),
        };
        let ids = self.calibration.ids();
        let torque_problem = self.torque_problem.as_ref().map(TorqueProblem::text);
        let problem = match (&self.problem, torque_problem) {
            (Some(link), Some(torque)) => Some(format!("{link}; {torque}")),
            (link, torque) => link.clone().or_else(|| torque.map(str::to_owned)),
        };
        ControllerStatus {
            connected: matches!(self.link, Link::Up(_)),
            problem,
            torque_on: self.torque.on,
            failed_cycles: self.failed_cycles,
            reconnects: self.reconnects,
            bus,
            safety: self.shaper.counters,
            servos: std::array::from_fn(|joint| ServoReport {
                id: ids[joint],
                answering: self.answering[joint],
                errors: errors[joint],
                position_ticks: self.present.map(|present| present.ticks[joint]),
                telemetry: self.telemetry.map(|(telemetry, _)| telemetry[joint]),
            }),
        }
    }

    /// Changes whenever the link goes up or down: the moment to take a new [`Self::last_words_line`].
    pub fn link_generation(&self) -> u64 {
        self.link_generation
    }

    /// A second handle on the bus for last words (a broadcast torque off as the process dies);
    /// `None` while disconnected.
    pub fn last_words_line(&self) -> Option<Box<dyn std::io::Write + Send>> {
        match &self.link {
            Link::Up(arm) => arm.bus.transport().emergency_writer(),
            Link::Down { .. } => None,
        }
    }

    pub fn is_connected(&self) -> bool {
        matches!(self.link, Link::Up(_))
    }

    /// The bus part of a cycle: read positions, check them, write goals computed from them.
    fn exchange(&mut self, now: Instant) -> Option<JointPositions> {
        let Link::Up(arm) = &mut self.link else {
            return None;
        };
        let ticks = match arm.read_positions() {
            Ok(ticks) => ticks,
            Err(error) => {
                self.failed_read();
                self.bus_fault(error, now);
                return None;
            }
        };
        let checked = implausible(&self.calibration, &ticks, arm).map_or_else(
            || {
                let radians: JointPositions = self.calibration.positions_from_ticks(&ticks);
                self.readings.check(&radians, now).map(|()| radians)
            },
            Err,
        );
        let radians = match checked {
            Ok(radians) => radians,
            Err(problem) => {
                self.shaper.counters.implausible_readings += 1;
                self.failed_read();
                self.report_problem(problem);
                return None;
            }
        };
        self.last_good_read = now;
        self.answering = [true; JOINT_COUNT];
        self.problem = None;
        self.present = Some(Present { radians, ticks });
        if self.torque.on {
            if let Some(problem) = self.overloaded() {
                self.drop_torque_after(problem);
                return Some(radians);
            }
        }
        // Goals first, the report after: the servos should not wait for the publisher.
        if !self.config.leader && self.torque.on {
            let goals = self.shaper.goals(&radians, now);
            let goal_ticks = self.calibration.ticks_from_positions(&goals);
            let Link::Up(arm) = &mut self.link else {
                return Some(radians);
            };
            if let Err(error) = arm.write_goals(&goal_ticks) {
                self.bus_fault(error, now);
            }
        }
        Some(radians)
    }

    fn failed_read(&mut self) {
        self.failed_cycles += 1;
        self.present = None;
    }

    fn report_problem(&mut self, problem: String) {
        if self.problem.as_deref() != Some(problem.as_str()) {
            tracing::error!("{problem}");
        }
        self.problem = Some(problem);
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

    fn velocities(&self, now: Instant) -> Vec<f64> {
        match self.telemetry {
            Some((telemetry, at)) if now.duration_since(at) <= TELEMETRY_MAX_AGE => (0
                ..JOINT_COUNT)
                .map(|joint| {
                    self.calibration
                        .radians_per_second(joint, telemetry[joint].velocity)
                })
                .collect(),
            _ => Vec::new(),
        }
    }
}

/// Why these readings must not be acted on, if they must not: far outside the calibrated range,
/// or from a servo that reports its angle sensor failing.
fn implausible<T: Transport>(
    calibration: &ArmCalibration,
    ticks: &[i32; JOINT_COUNT],
    arm: &Arm<T>,
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
