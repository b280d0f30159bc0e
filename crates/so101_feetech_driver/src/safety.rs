//! What goal each servo gets in a cycle: the commanded target, clamped into the calibrated range,
//! at most `max_step` away from where the joint is now (LeRobot's max_relative_target), and held
//! in place when commands stop coming (a crashed teleop must not leave the arm chasing an old
//! target). Pure logic; the control loop feeds it measured positions and the clock.

use std::time::{Duration, Instant};

use so101_core::{
    command::PartialTargets,
    robot::{JointLimit, JointPositions, JOINT_COUNT},
};

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SafetyConfig {
    /// Largest distance (rad) between a goal and the joint's present position.
    pub max_step: f64,
    /// Commands older than this make the arm hold where it is; `None` never holds.
    pub command_timeout: Option<Duration>,
}

/// Counters for /diagnostics.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct SafetyCounters {
    /// Targets that were outside the calibrated range.
    pub clamped_targets: u64,
    /// Goals cut short by `max_step`.
    pub limited_steps: u64,
    /// Times the watchdog made the arm hold.
    pub watchdog_holds: u64,
}

pub struct GoalShaper {
    config: SafetyConfig,
    limits: [JointLimit; JOINT_COUNT],
    /// Where the arm should go; `None` until the first hold or command.
    targets: Option<JointPositions>,
    last_command: Option<Instant>,
    holding_for_watchdog: bool,
    pub counters: SafetyCounters,
}

impl GoalShaper {
    /// `limits`: the calibrated range of each joint, in rad.
    pub fn new(config: SafetyConfig, limits: [JointLimit; JOINT_COUNT]) -> Self {
        Self {
            config,
            limits,
            targets: None,
            last_command: None,
            holding_for_watchdog: false,
            counters: SafetyCounters::default(),
        }
    }

    /// Makes the present position the target (after connecting, enabling torque, reconnecting).
    pub fn hold(&mut self, present: &JointPositions) {
        self.targets = Some(self.clamped(present));
    }

    pub fn targets(&self) -> Option<&JointPositions> {
        self.targets.as_ref()
    }

    /// Applies a validated command; joints it does not name keep their target.
    pub fn command(&mut self, command: &PartialTargets, present: &JointPositions, now: Instant) {
        let mut targets = self.targets.unwrap_or_else(|| self.clamped(present));
        for (joint, target) in targets.iter_mut().enumerate() {
            if let Some(value) = command.get(joint) {
                let clamped = self.limits[joint].clamp(value);
                if clamped != value {
                    self.counters.clamped_targets += 1;
                }
                *target = clamped;
            }
        }
        self.targets = Some(targets);
        self.last_command = Some(now);
        self.holding_for_watchdog = false;
    }

    /// The goals for this cycle, from fresh `present` positions.
    pub fn goals(&mut self, present: &JointPositions, now: Instant) -> JointPositions {
        let stale = match (self.config.command_timeout, self.last_command) {
            (Some(timeout), Some(last)) => now.duration_since(last) > timeout,
            _ => false,
        };
        if stale && !self.holding_for_watchdog {
            self.holding_for_watchdog = true;
            self.counters.watchdog_holds += 1;
            self.hold(present);
            tracing::warn!(
                timeout = ?self.config.command_timeout,
                "no command for longer than the timeout: holding position"
            );
        }
        let targets = match self.targets {
            Some(targets) => targets,
            None => {
                self.hold(present);
                self.clamped(present)
            }
        };
        std::array::from_fn(|joint| {
            let step = self.config.max_step;
            let goal = targets[joint].clamp(present[joint] - step, present[joint] + step);
            if goal != targets[joint] {
                self.counters.limited_steps += 1;
            }
            // A joint outside its range (pushed there by hand) is led back into it.
            self.limits[joint].clamp(goal)
        })
    }

    pub fn is_holding_for_watchdog(&self) -> bool {
        self.holding_for_watchdog
    }

    fn clamped(&self, positions: &JointPositions) -> JointPositions {
        std::array::from_fn(|joint| self.limits[joint].clamp(positions[joint]))
    }
}

#[cfg(test)]
mod tests {
    use so101_core::command::targets_from_joint_state;

    use super::*;

    fn shaper(timeout_ms: Option<u64>) -> GoalShaper {
        GoalShaper::new(
            SafetyConfig {
                max_step: 0.1,
                command_timeout: timeout_ms.map(Duration::from_millis),
            },
            [JointLimit::new(-1.0, 1.0); JOINT_COUNT],
        )
    }

    fn command(name: &str, value: f64) -> PartialTargets {
        targets_from_joint_state(&[name.to_string()], &[value]).unwrap()
    }

    #[test]
    fn without_commands_the_arm_holds_where_it_was_first_seen() {
        let mut shaper = shaper(None);
        let now = Instant::now();
        let first = [0.2; JOINT_COUNT];
        assert_eq!(shaper.goals(&first, now), first);
        // Sagging under gravity does not drag the goal along.
        let sagged = [0.15; JOINT_COUNT];
        assert_eq!(shaper.goals(&sagged, now), first);
    }

    #[test]
    fn targets_are_clamped_and_approached_at_most_max_step_per_cycle() {
        let mut shaper = shaper(None);
        let now = Instant::now();
        let present = [0.0; JOINT_COUNT];
        shaper.command(&command("elbow_flex", 5.0), &present, now);
        assert_eq!(shaper.targets().unwrap()[2], 1.0);
        let goals = shaper.goals(&present, now);
        assert!((goals[2] - 0.1).abs() < 1e-12);
        assert_eq!(goals[0], 0.0);
        assert_eq!(shaper.counters.clamped_targets, 1);
        assert_eq!(shaper.counters.limited_steps, 1);
        let closer = [0.0, 0.0, 0.95, 0.0, 0.0, 0.0];
        assert_eq!(shaper.goals(&closer, now)[2], 1.0);
    }

    #[test]
    fn the_watchdog_holds_once_commands_go_stale_and_a_new_command_resumes() {
        let mut shaper = shaper(Some(100));
        let start = Instant::now();
        let present = [0.0; JOINT_COUNT];
        shaper.command(&command("shoulder_pan", 0.8), &present, start);
        let moving = [0.3, 0.0, 0.0, 0.0, 0.0, 0.0];
        assert!(shaper.goals(&moving, start + Duration::from_millis(50))[0] > 0.3);
        let later = start + Duration::from_millis(150);
        assert_eq!(shaper.goals(&moving, later)[0], 0.3);
        assert!(shaper.is_holding_for_watchdog());
        assert_eq!(shaper.counters.watchdog_holds, 1);
        shaper.goals(&moving, later + Duration::from_millis(100));
        assert_eq!(shaper.counters.watchdog_holds, 1);
        shaper.command(&command("shoulder_pan", 0.35), &moving, later);
        assert!(!shaper.is_holding_for_watchdog());
        assert!((shaper.goals(&moving, later)[0] - 0.35).abs() < 1e-12);
    }

    #[test]
    fn a_joint_pushed_outside_its_range_is_led_back_in() {
        let mut shaper = shaper(None);
        let outside = [1.3; JOINT_COUNT];
        let goals = shaper.goals(&outside, Instant::now());
        assert!(goals.iter().all(|goal| *goal <= 1.0));
    }
}
