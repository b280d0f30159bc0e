//! The controller's torque: what the user asked for brought to the servos, torque on only holding
//! where the joints are, torque off that reaches every servo, and a servo that unloaded itself.

use std::time::Instant;

use so101_core::robot::{JointPositions, JOINT_NAMES};

use super::{implausible, Controller, Link, TorqueError, TorqueProblem, TORQUE_RETRY};

/// Pairs of readings tried before torque-on gives up for this attempt.
const STEADY_ATTEMPTS: usize = 3;
/// Failed torque-on attempts in a row after which the wish is dropped and the user asked again
/// (a servo that keeps refusing must not make the arm sag and catch itself forever).
const TORQUE_ON_ATTEMPTS: u32 = 3;
use crate::{
    arm::{reopen_and_broadcast_torque_off, TorqueOffReport},
    bus::Connector,
    protocol::ServoErrors,
    safety::{torque_on_refusal, ReadingFilter},
};

impl<C: Connector> Controller<C> {
    /// A servo that reports overload has dropped its own torque (its protection): which, if any.
    pub(super) fn overloaded(&self) -> Option<String> {
        let Link::Up(arm) = &self.link else {
            return None;
        };
        self.calibration
            .motors
            .iter()
            .enumerate()
            .find(|(_, motor)| arm.bus.servo_errors(motor.id).0 & ServoErrors::OVERLOAD != 0)
            .map(|(joint, motor)| {
                format!(
                    "torque off: {} (id {}) reports overload and dropped its own torque; torque is off on every servo. Clear the obstruction, then call /torque_enable true",
                    JOINT_NAMES[joint], motor.id
                )
            })
    }

    /// A servo cut its torque by itself: the others follow (never a half-stiff arm), and the
    /// user decides when to go on.
    pub(super) fn drop_torque_after(&mut self, problem: String) {
        tracing::error!("{problem}");
        self.torque_problem = Some(TorqueProblem::NeedsUser(problem));
        self.torque.wanted = false;
        if let Err(error) = self.apply_torque_wish() {
            tracing::error!(%error, "torque off after an overload not confirmed");
        }
    }

    /// Retries a torque state that does not match the wish (a failed change, a reconnect).
    pub(super) fn reconcile_torque(&mut self, now: Instant) {
        let matches = self.torque.on == self.torque.wanted && !self.torque.uncertain;
        if matches || now < self.torque.next_attempt {
            return;
        }
        self.torque.next_attempt = now + TORQUE_RETRY;
        if self.apply_torque_wish().is_ok() {
            tracing::info!(on = self.torque.on, "torque state restored");
        }
    }

    /// Brings the servos' torque in line with the wish. Torque on first makes the present
    /// position the goal, so the arm does not jump to an old one.
    pub(super) fn apply_torque_wish(&mut self) -> Result<(), TorqueError> {
        if !matches!(self.link, Link::Up(_)) {
            return Ok(());
        }
        let result = if self.torque.wanted {
            self.torque_on()
        } else {
            match self.torque_off_everywhere() {
                Some(report) if report.confirmed() => Ok(()),
                Some(report) => Err(TorqueError::Unconfirmed(report.unacknowledged)),
                None => Ok(()),
            }
        };
        match &result {
            Ok(()) => {
                self.torque.on = self.torque.wanted;
                self.torque.uncertain = false;
                self.torque.failed_on = 0;
                if matches!(self.torque_problem, Some(TorqueProblem::Failed(_))) {
                    self.torque_problem = None;
                }
            }
            Err(TorqueError::Refused(reason) | TorqueError::Implausible(reason)) => {
                self.torque.on = false;
                self.torque.uncertain = false;
                tracing::error!("{reason}");
                self.torque_problem = Some(TorqueProblem::NeedsUser(reason.clone()));
            }
            Err(error) => {
                // Some servos may have switched: no goals until a retry confirms all of them.
                self.torque.on = false;
                self.torque.uncertain = true;
                tracing::error!(%error, wanted = self.torque.wanted, "cannot change torque");
                self.torque_problem = Some(TorqueProblem::Failed(format!(
                    "torque change failed: {error}"
                )));
                if self.torque.wanted {
                    self.torque.failed_on += 1;
                    if self.torque.failed_on >= TORQUE_ON_ATTEMPTS {
                        self.torque.wanted = false;
                        self.torque_problem = Some(TorqueProblem::NeedsUser(format!(
                            "torque off: torque on failed {TORQUE_ON_ATTEMPTS} times ({error}); call /torque_enable true to try again"
                        )));
                        self.torque_off_everywhere();
                    }
                }
            }
        }
        result
    }

    pub(super) fn torque_on(&mut self) -> Result<(), TorqueError> {
        let present = self.steady_positions()?;
        if let Some(refusal) = torque_on_refusal(&present, &self.limits, self.shaper.max_step()) {
            // Sticky: the user moves the joint and asks again; torque never comes on by itself
            // under a hand that is still at the arm.
            self.torque.wanted = false;
            self.torque_off_everywhere();
            return Err(TorqueError::Refused(refusal));
        }
        self.shaper.hold(&present);
        self.readings.reset();
        let held = self.shaper.targets().copied().unwrap_or(present);
        let goals = self.calibration.ticks_from_positions(&held);
        let Link::Up(arm) = &mut self.link else {
            return Ok(());
        };
        let result = arm.write_goals(&goals).and_then(|()| arm.torque_on());
        if let Err(error) = result {
            // Never half stiff: the servos that took torque on give it up again.
            self.torque_off_everywhere();
            return Err(error.into());
        }
        Ok(())
    }

    /// Where the joints are, for the goal torque comes on with: two consecutive readings that
    /// agree (a single misread must not become the pose the arm is pulled to), tried a few times.
    fn steady_positions(&mut self) -> Result<JointPositions, TorqueError> {
        let mut disagreement = String::new();
        for _ in 0..STEADY_ATTEMPTS {
            let mut pair = ReadingFilter::default();
            let mut positions = None;
            for _ in 0..2 {
                let Link::Up(arm) = &mut self.link else {
                    return Err(TorqueError::Unsteady("disconnected".to_owned()));
                };
                let ticks = arm.read_positions()?;
                if let Some(problem) = implausible(&self.calibration, &ticks, arm) {
                    self.torque.wanted = false;
                    return Err(TorqueError::Implausible(format!(
                        "torque refused: {problem}"
                    )));
                }
                let radians: JointPositions = self.calibration.positions_from_ticks(&ticks);
                positions = match pair.check(&radians, Instant::now()) {
                    Ok(()) => Some(radians),
                    Err(why) => {
                        self.shaper.counters.implausible_readings += 1;
                        disagreement = why;
                        None
                    }
                };
            }
            if let Some(positions) = positions {
                return Ok(positions);
            }
        }
        Err(TorqueError::Unsteady(disagreement))
    }

    /// Torque off on every servo whatever fails; `None` when the link is down (then a broadcast
    /// on a freshly opened port was tried).
    pub(super) fn torque_off_everywhere(&mut self) -> Option<TorqueOffReport> {
        self.shaper.release();
        match &mut self.link {
            Link::Up(arm) => {
                let report = arm.torque_off_everywhere();
                if report.broadcast_failed {
                    // The port itself failed: a fresh one may still reach the servos.
                    if let Err(error) =
                        reopen_and_broadcast_torque_off(&mut self.connector, self.settings.bus)
                    {
                        tracing::warn!(%error, "torque off broadcast on a reopened port failed");
                    }
                }
                Some(report)
            }
            Link::Down { .. } => {
                if let Err(error) =
                    reopen_and_broadcast_torque_off(&mut self.connector, self.settings.bus)
                {
                    tracing::debug!(%error, "torque off broadcast while disconnected failed");
                }
                None
            }
        }
    }
}
