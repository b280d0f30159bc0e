//! The controller's link to the arm: a bus fault, the link lost (torque off for whoever still
//! hears), and the reconnection that takes back only the arm this calibration belongs to.

use std::time::Instant;

use so101_core::robot::{JOINT_COUNT, JOINT_NAMES};

use super::{Controller, Link};
use crate::{
    arm::{connect_bus, Arm, ArmError},
    bus::{BusError, Connector},
};

impl<C: Connector> Controller<C> {
    pub(super) fn bus_fault(&mut self, error: BusError, now: Instant) {
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
        if error.is_disconnected() || silent_for > self.config.reopen_after {
            tracing::error!(%error, silent_for = ?silent_for, "bus lost: torque off, reconnecting by itself");
            self.disconnect(now, format!("bus lost ({error}); reconnecting"));
        } else {
            tracing::warn!("{}", self.problem.as_deref().unwrap_or(""));
        }
    }

    /// The link is lost: torque off for every servo that can still hear (nobody supervises them
    /// now), then the port is closed and reopened later.
    pub(super) fn disconnect(&mut self, now: Instant, problem: String) {
        // The wish stays: what the user asked for comes back with the arm.
        self.torque_off_everywhere();
        if let Link::Up(arm) = &self.link {
            self.bus_totals = self.bus_totals.plus(arm.bus.stats());
        }
        self.link = Link::Down { next_attempt: now };
        self.problem = Some(problem);
        self.present = None;
        self.torque.on = false;
        self.torque.uncertain = true;
        self.answering = [false; JOINT_COUNT];
        self.link_generation += 1;
    }

    pub(super) fn try_reconnect(&mut self, now: Instant) {
        let Link::Down { next_attempt } = self.link else {
            return;
        };
        if now < next_attempt {
            return;
        }
        let attached = connect_bus(&mut self.connector, self.settings.bus)
            .and_then(|bus| Arm::reattach_on(bus, &self.settings, self.calibration.clone()));
        match attached {
            Ok(arm) => {
                self.reconnects += 1;
                self.link = Link::Up(Box::new(arm));
                self.last_good_read = now;
                self.problem = None;
                self.readings.reset();
                self.link_generation += 1;
                tracing::info!(reconnects = self.reconnects, "bus reconnected");
                self.torque.next_attempt = now;
                self.reconcile_torque(now);
            }
            Err(error) => {
                self.link = Link::Down {
                    next_attempt: now + self.config.reconnect_interval,
                };
                let problem = format!("reconnecting: {error}");
                if self.problem.as_deref() != Some(problem.as_str()) {
                    let refused = matches!(error, ArmError::CalibrationDiffers { .. });
                    if refused {
                        tracing::error!("{problem}");
                    } else {
                        tracing::warn!(%error, "reconnection failed; trying again");
                    }
                }
                self.problem = Some(problem);
            }
        }
    }
}
