//! What goal each servo gets in a cycle: the commanded target, clamped into the calibrated range,
//! at most `max_step` away from where the joint is now (LeRobot's max_relative_target) and from
//! the previous goal, and held in place when commands stop coming (a crashed teleop must not leave
//! the arm chasing an old target). Which readings may be the base of a goal at all
//! ([`ReadingFilter`]), and when torque may come on ([`torque_on_refusal`]). Pure logic; the
//! control loop feeds it measured positions and the clock.

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
    /// Goals held at the previous one because no goal was within `max_step` of both the joint
    /// and its range (the joint was pushed far outside its range with torque on).
    pub held_out_of_range: u64,
    /// Readings that jumped further than a servo can move in the time since the last one.
    pub implausible_readings: u64,
}

pub struct GoalShaper {
    config: SafetyConfig,
    limits: [JointLimit; JOINT_COUNT],
    /// Where the arm should go; `None` until the first hold or command.
    targets: Option<JointPositions>,
    /// The goals last written; `None` until the first, and after torque was off.
    last_goals: Option<JointPositions>,
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
            last_goals: None,
            last_command: None,
            holding_for_watchdog: false,
            counters: SafetyCounters::default(),
        }
    }

    pub fn max_step(&self) -> f64 {
        self.config.max_step
    }

    /// New limits from the next goal on (a parameter set while the node runs).
    pub fn set_config(&mut self, config: SafetyConfig) {
        self.config = config;
    }

    pub fn config(&self) -> SafetyConfig {
        self.config
    }

    /// Makes the present position the target (after connecting, enabling torque, reconnecting);
    /// the servos' goals are being set to it, so it is also the previous goal.
    pub fn hold(&mut self, present: &JointPositions) {
        self.targets = Some(self.clamped(present));
        self.last_goals = Some(*present);
    }

    /// Torque went off: the servos' goals are no longer the ones written.
    pub fn release(&mut self) {
        self.last_goals = None;
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
        let step = self.config.max_step;
        let previous = self.last_goals.unwrap_or(*present);
        let goals = std::array::from_fn(|joint| {
            let target = targets[joint];
            let near_present = (present[joint] - step, present[joint] + step);
            let near_previous = (previous[joint] - step, previous[joint] + step);
            let range = (self.limits[joint].min, self.limits[joint].max);
            // Where the joint is wins over where the previous goal was: when the two are further
            // apart than two steps (a hand pushed the joint), the goal is the step towards it.
            let mut allowed = intersect(near_present, near_previous)
                .unwrap_or_else(|| towards(near_present, previous[joint]));
            allowed = match intersect(allowed, range) {
                Some(allowed) => allowed,
                None => {
                    // Outside the range by more than a step: no goal is both safe and in range
                    // (the servo clamps goals to its limits), so the goal stays where it was.
                    self.counters.held_out_of_range += 1;
                    (previous[joint], previous[joint])
                }
            };
            let goal = target.clamp(allowed.0, allowed.1);
            if goal != target {
                self.counters.limited_steps += 1;
            }
            goal
        });
        self.last_goals = Some(goals);
        goals
    }

    pub fn is_holding_for_watchdog(&self) -> bool {
        self.holding_for_watchdog
    }

    fn clamped(&self, positions: &JointPositions) -> JointPositions {
        std::array::from_fn(|joint| self.limits[joint].clamp(positions[joint]))
    }
}

/// The overlap of two closed intervals.
fn intersect(a: (f64, f64), b: (f64, f64)) -> Option<(f64, f64)> {
    let (low, high) = (a.0.max(b.0), a.1.min(b.1));
    (low <= high).then_some((low, high))
}

/// The end of `interval` nearest to `value`, as a one-point interval.
fn towards(interval: (f64, f64), value: f64) -> (f64, f64) {
    let end = value.clamp(interval.0, interval.1);
    (end, end)
}

/// Why torque must not come on with the joints where they are, if it must not: a joint further
/// outside its calibrated range than one step would be pulled back in one jump, because the servo
/// clamps every goal (the holding one too) to its position limits.
pub fn torque_on_refusal(
    present: &JointPositions,
    limits: &[JointLimit; JOINT_COUNT],
    max_step: f64,
) -> Option<String> {
    let outside: Vec<String> = (0..JOINT_COUNT)
        .filter_map(|joint| {
            let limit = limits[joint];
            let below = limit.min - present[joint];
            let above = present[joint] - limit.max;
            let (distance, side) = if below > above {
                (below, "below")
            } else {
                (above, "above")
            };
            (distance > max_step).then(|| {
                format!(
                    "{} is {distance:.3} rad {side} its calibrated range",
                    so101_core::robot::JOINT_NAMES[joint]
                )
            })
        })
        .collect();
    (!outside.is_empty()).then(|| {
        format!(
            "torque refused: {} (more than --max-step {max_step} rad): the servo would jump back into range. Move the joint into its range by hand (or recalibrate), then call /torque_enable true",
            outside.join(", ")
        )
    })
}

/// Fastest a joint can really move (rad/s): the STS3215 turns ~0.15 s/60 deg unloaded at 12 V
/// (~7 rad/s); a hand back-driving a limp joint stays below this too.
pub const MAX_JOINT_SPEED: f64 = 20.0;
/// Allowance on top of the speed bound for quantisation and reading jitter (rad, ~20 ticks).
const READING_MARGIN: f64 = 0.03;

/// Whether a reading can be the base of a goal: a joint that moved further since the last
/// accepted reading than any joint can move in that time was misread (a flipped bit that still
/// passed the checksum, a glitch). Two consecutive readings that agree are believed, though: the
/// jump was real (the arm moved while the bus was down).
#[derive(Debug, Default)]
pub struct ReadingFilter {
    accepted: Option<(JointPositions, Instant)>,
    suspect: Option<(JointPositions, Instant)>,
}

impl ReadingFilter {
    /// `Ok` when `reading` may be used; `Err` names the joint that jumped.
    pub fn check(&mut self, reading: &JointPositions, now: Instant) -> Result<(), String> {
        let Some((accepted, at)) = self.accepted else {
            self.accept(reading, now);
            return Ok(());
        };
        let jump = match implausible_jump(&accepted, at, reading, now) {
            None => {
                self.accept(reading, now);
                return Ok(());
            }
            Some(jump) => jump,
        };
        if let Some((suspect, suspect_at)) = self.suspect {
            if implausible_jump(&suspect, suspect_at, reading, now).is_none() {
                self.accept(reading, now);
                return Ok(());
            }
        }
        self.suspect = Some((*reading, now));
        Err(jump)
    }

    /// Forgets the history (after a reconnect the arm may be anywhere).
    pub fn reset(&mut self) {
        self.accepted = None;
        self.suspect = None;
    }

    fn accept(&mut self, reading: &JointPositions, now: Instant) {
        self.accepted = Some((*reading, now));
        self.suspect = None;
    }
}

fn implausible_jump(
    before: &JointPositions,
    then: Instant,
    after: &JointPositions,
    now: Instant,
) -> Option<String> {
    let bound = MAX_JOINT_SPEED * now.duration_since(then).as_secs_f64() + READING_MARGIN;
    (0..JOINT_COUNT).find_map(|joint| {
        let jump = (after[joint] - before[joint]).abs();
        (jump > bound).then(|| {
            format!(
                "{} read {:.3} rad from {:.3} rad: a jump no servo makes in that time; not used",
                so101_core::robot::JOINT_NAMES[joint],
                after[joint],
                before[joint]
            )
        })
    })
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
        let closer = [0.0, 0.0, 0.15, 0.0, 0.0, 0.0];
        assert!((shaper.goals(&closer, now)[2] - 0.2).abs() < 1e-12);
        let closer = [0.0, 0.0, 0.95, 0.0, 0.0, 0.0];
        // Pushed ahead of the previous goal (0.2): within a step of the joint, as near the
        // previous goal as that allows.
        assert!((shaper.goals(&closer, now)[2] - 0.85).abs() < 1e-12);
        assert_eq!(shaper.goals(&closer, now)[2], 0.95);
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
    fn a_joint_just_outside_its_range_is_led_back_in_within_one_step() {
        let mut shaper = shaper(None);
        let outside = [1.05; JOINT_COUNT];
        let goals = shaper.goals(&outside, Instant::now());
        assert!(goals.iter().all(|goal| (*goal - 1.0).abs() < 1e-12));
    }

    #[test]
    fn a_joint_far_outside_its_range_is_never_pulled_back_in_one_jump() {
        // The regression: 70 ticks (0.107 rad) below the range with a 0.1 rad step went straight
        // to the range's edge.
        let mut shaper = shaper(None);
        let mut present = [0.0; JOINT_COUNT];
        present[1] = -1.107;
        let now = Instant::now();
        shaper.hold(&present);
        for _ in 0..3 {
            let goals = shaper.goals(&present, now);
            assert!((goals[1] - present[1]).abs() <= 0.1 + 1e-12, "{goals:?}");
        }
        assert!(shaper.counters.held_out_of_range > 0);
    }

    #[test]
    fn every_goal_is_within_a_step_of_the_joint_and_of_the_previous_goal() {
        let mut shaper = shaper(None);
        let now = Instant::now();
        let mut present = [0.0; JOINT_COUNT];
        shaper.command(&command("elbow_flex", 1.0), &present, now);
        let mut previous = shaper.goals(&present, now);
        // The joint reads as having moved back (sagging, a push): the goal follows at most one
        // step from each.
        for reading in [0.05, -0.05, 0.3, -0.2, 0.0] {
            present[2] = reading;
            let goals = shaper.goals(&present, now);
            assert!((goals[2] - present[2]).abs() <= 0.1 + 1e-12);
            if (present[2] - previous[2]).abs() <= 0.2 {
                assert!((goals[2] - previous[2]).abs() <= 0.1 + 1e-12);
            }
            previous = goals;
        }
    }

    #[test]
    fn torque_on_is_refused_for_a_joint_more_than_a_step_outside_its_range() {
        let limits = [JointLimit::new(-1.0, 1.0); JOINT_COUNT];
        let mut present = [0.0; JOINT_COUNT];
        assert!(torque_on_refusal(&present, &limits, 0.05).is_none());
        present[1] = -1.04;
        assert!(torque_on_refusal(&present, &limits, 0.05).is_none());
        present[1] = -1.107;
        let refusal = torque_on_refusal(&present, &limits, 0.05).unwrap();
        assert!(
            refusal.contains("shoulder_lift is 0.107 rad below"),
            "{refusal}"
        );
    }

    #[test]
    fn a_single_implausible_reading_is_refused_and_a_confirmed_jump_believed() {
        let mut filter = ReadingFilter::default();
        let start = Instant::now();
        let cycle = Duration::from_millis(5);
        let calm = [0.0; JOINT_COUNT];
        assert!(filter.check(&calm, start).is_ok());
        let mut moved = calm;
        moved[0] = 0.08; // 16 rad/s over 5 ms: fast but possible
        assert!(filter.check(&moved, start + cycle).is_ok());
        let mut glitch = moved;
        glitch[3] = 1.5;
        assert!(filter.check(&glitch, start + cycle * 2).is_err());
        assert!(
            filter.check(&moved, start + cycle * 3).is_ok(),
            "back to normal"
        );
        // After a long silence the arm may be elsewhere, and two agreeing readings say so.
        let mut elsewhere = moved;
        elsewhere[2] = 1.0;
        assert!(filter.check(&elsewhere, start + cycle * 4).is_err());
        assert!(filter.check(&elsewhere, start + cycle * 5).is_ok());
    }
}
