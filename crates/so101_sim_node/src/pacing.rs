//! How simulated time relates to wall time: real time times a speed factor, as fast as possible, or
//! lockstep (only when a client asks for a step).

use std::time::{Duration, Instant};

#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TimeMode {
    /// Sim time runs `speed` times as fast as wall time.
    Scaled { speed: f64 },
    /// No waiting: as many steps per second as the CPU gives.
    Max,
    /// One control period per /sim/step call.
    Lockstep,
}

/// Slowest and fastest speed factors `--speed` accepts (beyond them, use lockstep or "max").
const MIN_SPEED: f64 = 1e-3;
const MAX_SPEED: f64 = 1e6;

/// Parses `--speed`: a factor from [`MIN_SPEED`] to [`MAX_SPEED`], or "max".
pub fn parse_speed(text: &str) -> Result<TimeMode, String> {
    if text.eq_ignore_ascii_case("max") {
        return Ok(TimeMode::Max);
    }
    match text.parse::<f64>() {
        Ok(speed) if (MIN_SPEED..=MAX_SPEED).contains(&speed) => Ok(TimeMode::Scaled { speed }),
        _ => Err(format!(
            "{text:?} is neither a factor from {MIN_SPEED} to {MAX_SPEED} nor \"max\""
        )),
    }
}

/// When falling behind by more than this, the pacer stops trying to catch up (a stall of the
/// machine should not be followed by a burst of fast-forwarded physics).
const MAX_LAG: Duration = Duration::from_millis(200);

/// Decides how long to wait before simulating the next control period.
#[derive(Debug)]
pub struct Pacer {
    speed: Option<f64>,
    anchor_wall: Instant,
    anchor_sim: f64,
    /// Times the pacer gave up catching up.
    pub resyncs: u64,
}

impl Pacer {
    /// `speed` is `None` for "as fast as possible".
    pub fn new(speed: Option<f64>, sim_time: f64, now: Instant) -> Self {
        Self {
            speed,
            anchor_wall: now,
            anchor_sim: sim_time,
            resyncs: 0,
        }
    }

    /// Sim time `sim_time` is now: pacing starts over from here (after a deliberate pause).
    pub fn restart(&mut self, sim_time: f64, now: Instant) {
        self.anchor_wall = now;
        self.anchor_sim = sim_time;
    }

    /// How long to sleep before the period that ends at `sim_time` may run (its state is published
    /// when the wall clock reaches its end).
    pub fn wait_before(&mut self, sim_time: f64, now: Instant) -> Duration {
        let Some(speed) = self.speed else {
            return Duration::ZERO;
        };
        let due = self.anchor_wall
            + Duration::from_secs_f64(((sim_time - self.anchor_sim) / speed).max(0.0));
        if due >= now {
            return due - now;
        }
        if now - due > MAX_LAG {
            self.resyncs += 1;
            self.anchor_wall = now;
            self.anchor_sim = sim_time;
        }
        Duration::ZERO
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_speed_factors_and_max() {
        assert_eq!(parse_speed("max"), Ok(TimeMode::Max));
        assert_eq!(parse_speed("2.5"), Ok(TimeMode::Scaled { speed: 2.5 }));
        for bad in ["0", "-1", "nan", "inf", "fast", "1e-300", "1e300"] {
            assert!(parse_speed(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn real_time_waits_for_the_wall_clock() {
        let start = Instant::now();
        let mut pacer = Pacer::new(Some(1.0), 0.0, start);
        assert_eq!(pacer.wait_before(0.0, start), Duration::ZERO);
        assert_eq!(pacer.wait_before(0.01, start), Duration::from_millis(10));
        assert_eq!(
            pacer.wait_before(0.01, start + Duration::from_millis(4)),
            Duration::from_millis(6)
        );
    }

    #[test]
    fn speed_factor_divides_the_wait() {
        let start = Instant::now();
        let mut pacer = Pacer::new(Some(4.0), 1.0, start);
        assert_eq!(pacer.wait_before(1.04, start), Duration::from_millis(10));
        let mut max = Pacer::new(None, 0.0, start);
        assert_eq!(max.wait_before(100.0, start), Duration::ZERO);
    }

    #[test]
    fn a_long_stall_resyncs_instead_of_bursting() {
        let start = Instant::now();
        let mut pacer = Pacer::new(Some(1.0), 0.0, start);
        let late = start + Duration::from_secs(2);
        assert_eq!(pacer.wait_before(0.01, late), Duration::ZERO);
        assert_eq!(pacer.resyncs, 1);
        // After the resync the next period is due one period later, not immediately.
        assert_eq!(pacer.wait_before(0.02, late), Duration::from_millis(10));
    }
}
