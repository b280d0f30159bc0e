//! Teleop in step with a sim node started with `--lockstep --step-on-command`: every command the
//! node publishes advances the sim one control period, and the next tick waits until that
//! period's /joint_states, /cube/pose and /task/success are in. Time is the newest state's stamp (sim time). The source then
//! sees every period's state, whatever the machine's load: nothing is held for a period because
//! a process was descheduled, so a recording through the stack repeats for one seed.

use std::time::{Duration, Instant};

/// A command whose state has not come back after this long is given up on (a sim not in
/// --step-on-command, or one that refused the command): the next tick goes on without it.
pub const STEP_TIMEOUT: Duration = Duration::from_secs(5);

/// Wall time between ticks that step nothing (waiting for discovery or for the arm's first state).
pub const IDLE_TICK: Duration = Duration::from_millis(5);

/// What one look at the topics brought: how many messages of each topic the source reads, and
/// the newest /joint_states stamp.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Taken {
    pub joint_states: u32,
    pub cube_poses: u32,
    pub task_successes: u32,
    pub newest_stamp: Option<f64>,
}

/// Wall time the node waits after publishing an event that opens or closes an episode before it steps
/// on: the recorder takes the event on another thread than the periods' messages, and at the pace
/// of lockstep a late start would lose the episode's first periods.
pub const EVENT_PAUSE: Duration = Duration::from_millis(250);

/// When the next tick may run.
#[derive(Debug, Default)]
pub struct Lockstep {
    /// When the last step was asked for (a command, a reset), while some of its period's messages
    /// are not in: /joint_states, /cube/pose, /task/success (the sim publishes each once a period).
    awaiting: Option<(Instant, [bool; 3])>,
    /// Sim time of the newest /joint_states.
    newest: Option<f64>,
    /// Steps given up on ([`STEP_TIMEOUT`]).
    pub timeouts: u64,
}

/// What the node does now.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Gate {
    /// Tick, at this sim time (0 before the first state).
    Tick(f64),
    /// The step's messages are not all in yet: look again shortly.
    Wait,
    /// The step's messages did not all come within [`STEP_TIMEOUT`]: tick anyway.
    TimedOut(f64),
}

impl Lockstep {
    /// A command (or a reset) went out: the sim steps, and the next tick waits for its period's
    /// messages.
    pub fn stepped(&mut self, at: Instant) {
        self.awaiting = Some((at, [true; 3]));
    }

    /// Given what the last look at the topics took, whether the next tick may run.
    pub fn gate(&mut self, taken: Taken, now: Instant) -> Gate {
        if let Some(stamp) = taken.newest_stamp {
            self.newest = Some(self.newest.map_or(stamp, |newest| newest.max(stamp)));
        }
        let time = self.newest.unwrap_or(0.0);
        let Some((since, missing)) = &mut self.awaiting else {
            return Gate::Tick(time);
        };
        let counts = [taken.joint_states, taken.cube_poses, taken.task_successes];
        for (missing, count) in missing.iter_mut().zip(counts) {
            *missing &= count == 0;
        }
        if !missing.iter().any(|&missing| missing) {
            self.awaiting = None;
            Gate::Tick(time)
        } else if now.duration_since(*since) >= STEP_TIMEOUT {
            self.awaiting = None;
            self.timeouts += 1;
            Gate::TimedOut(time)
        } else {
            Gate::Wait
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn states(stamp: f64) -> Taken {
        Taken {
            joint_states: 1,
            newest_stamp: Some(stamp),
            ..Taken::default()
        }
    }

    const CUBE: Taken = Taken {
        joint_states: 0,
        cube_poses: 1,
        task_successes: 0,
        newest_stamp: None,
    };
    const SUCCESS: Taken = Taken {
        joint_states: 0,
        cube_poses: 0,
        task_successes: 1,
        newest_stamp: None,
    };

    #[test]
    fn a_tick_waits_for_every_message_of_the_period_its_command_leads_to() {
        let start = Instant::now();
        let mut lockstep = Lockstep::default();
        assert_eq!(lockstep.gate(Taken::default(), start), Gate::Tick(0.0));
        assert_eq!(lockstep.gate(states(1.0), start), Gate::Tick(1.0));
        lockstep.stepped(start);
        // Nothing new: no tick, however often it is asked.
        for _ in 0..3 {
            assert_eq!(lockstep.gate(Taken::default(), start), Gate::Wait);
        }
        // The state alone is not the period: the expert also reads the cube and the success.
        let period = 1.0 / 30.0;
        assert_eq!(lockstep.gate(states(1.0 + period), start), Gate::Wait);
        assert_eq!(lockstep.gate(SUCCESS, start), Gate::Wait);
        assert_eq!(lockstep.gate(CUBE, start), Gate::Tick(1.0 + period));
        // Ticks that step nothing go on without waiting.
        assert_eq!(
            lockstep.gate(Taken::default(), start),
            Gate::Tick(1.0 + period)
        );
        // All of a period's messages in one look.
        lockstep.stepped(start);
        let all = Taken {
            joint_states: 1,
            cube_poses: 1,
            task_successes: 1,
            newest_stamp: Some(1.0 + 2.0 * period),
        };
        assert_eq!(lockstep.gate(all, start), Gate::Tick(1.0 + 2.0 * period));
    }

    #[test]
    fn time_never_runs_backwards_on_a_late_older_state() {
        let start = Instant::now();
        let mut lockstep = Lockstep::default();
        lockstep.gate(states(2.0), start);
        assert_eq!(lockstep.gate(states(1.5), start), Gate::Tick(2.0));
    }

    #[test]
    fn a_step_whose_messages_never_all_come_is_given_up_after_the_timeout() {
        let start = Instant::now();
        let mut lockstep = Lockstep::default();
        lockstep.gate(states(3.0), start);
        lockstep.stepped(start);
        let early = start + STEP_TIMEOUT - Duration::from_millis(1);
        assert_eq!(lockstep.gate(states(3.1), early), Gate::Wait);
        assert_eq!(
            lockstep.gate(Taken::default(), start + STEP_TIMEOUT),
            Gate::TimedOut(3.1)
        );
        assert_eq!(lockstep.timeouts, 1);
        assert_eq!(
            lockstep.gate(Taken::default(), start + STEP_TIMEOUT),
            Gate::Tick(3.1)
        );
    }
}
