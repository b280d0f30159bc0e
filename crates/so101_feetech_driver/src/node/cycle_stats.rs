//! Timing of the control loop: how many cycles ran, how late each started against its schedule
//! (jitter), and the time between starts. Users of this arm know loops that silently run below the
//! requested rate; these numbers make it visible in /diagnostics and in the exit summary.

use std::time::{Duration, Instant};

/// Samples kept for percentiles (a 10-minute run at 1 kHz); later cycles are still counted.
const MAX_SAMPLES: usize = 600_000;

#[derive(Debug)]
pub struct CycleStats {
    started: Instant,
    cycles: u64,
    lateness_us: Vec<u32>,
    periods_us: Vec<u32>,
    last_start: Option<Instant>,
    /// Cycles that started more than a whole period late (the schedule was reset).
    pub overruns: u64,
    window: (Instant, u64),
    recent_rate: f64,
    /// Lateness of the cycles of the current window, and the p99 of the last full one: what
    /// /diagnostics shows without sorting the whole history on the control thread.
    window_lateness_us: Vec<u32>,
    recent_lateness_p99_us: u32,
}

/// What the exit summary and the benchmark report.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct CycleSummary {
    pub cycles: u64,
    pub seconds: f64,
    pub cycles_per_second: f64,
    pub lateness_p50_us: u32,
    pub lateness_p99_us: u32,
    pub lateness_max_us: u32,
    pub period_p50_us: u32,
    pub period_p99_us: u32,
    pub overruns: u64,
}

impl CycleStats {
    pub fn new(now: Instant) -> Self {
        Self {
            started: now,
            cycles: 0,
            lateness_us: Vec::new(),
            periods_us: Vec::new(),
            last_start: None,
            overruns: 0,
            window: (now, 0),
            recent_rate: 0.0,
            window_lateness_us: Vec::new(),
            recent_lateness_p99_us: 0,
        }
    }

    /// Records a cycle that started at `now` and was due at `scheduled` (none when running flat out).
    pub fn record_start(&mut self, now: Instant, scheduled: Option<Instant>) {
        self.cycles += 1;
        let lateness = scheduled.map(|due| micros(now.saturating_duration_since(due)));
        if let Some(lateness) = lateness {
            self.window_lateness_us.push(lateness);
        }
        if self.lateness_us.len() < MAX_SAMPLES {
            if let Some(lateness) = lateness {
                self.lateness_us.push(lateness);
            }
            if let Some(last) = self.last_start {
                self.periods_us.push(micros(now.duration_since(last)));
            }
        }
        self.last_start = Some(now);
        let (window_start, window_cycles) = self.window;
        let elapsed = now.duration_since(window_start);
        if elapsed >= Duration::from_secs(1) {
            self.recent_rate = (self.cycles - window_cycles) as f64 / elapsed.as_secs_f64();
            self.window = (now, self.cycles);
            self.window_lateness_us.sort_unstable();
            self.recent_lateness_p99_us = percentile(&self.window_lateness_us, 0.99);
            self.window_lateness_us.clear();
        }
    }

    /// Cycles per second over the last second or so.
    pub fn recent_rate(&self) -> f64 {
        self.recent_rate
    }

    /// p99 of the cycle start lateness over the last second or so.
    pub fn recent_lateness_p99_us(&self) -> u32 {
        self.recent_lateness_p99_us
    }

    pub fn cycles(&self) -> u64 {
        self.cycles
    }

    pub fn summary(&self, now: Instant) -> CycleSummary {
        let seconds = now.duration_since(self.started).as_secs_f64();
        let mut lateness = self.lateness_us.clone();
        let mut periods = self.periods_us.clone();
        lateness.sort_unstable();
        periods.sort_unstable();
        CycleSummary {
            cycles: self.cycles,
            seconds,
            cycles_per_second: if seconds > 0.0 {
                self.cycles as f64 / seconds
            } else {
                0.0
            },
            lateness_p50_us: percentile(&lateness, 0.50),
            lateness_p99_us: percentile(&lateness, 0.99),
            lateness_max_us: lateness.last().copied().unwrap_or(0),
            period_p50_us: percentile(&periods, 0.50),
            period_p99_us: percentile(&periods, 0.99),
            overruns: self.overruns,
        }
    }
}

fn micros(duration: Duration) -> u32 {
    u32::try_from(duration.as_micros()).unwrap_or(u32::MAX)
}

/// Nearest-rank percentile of sorted samples (0 when there are none).
pub fn percentile(sorted: &[u32], fraction: f64) -> u32 {
    if sorted.is_empty() {
        return 0;
    }
    let rank = (fraction * sorted.len() as f64).ceil() as usize;
    sorted[rank.clamp(1, sorted.len()) - 1]
}

/// The fixed-rate schedule: cycle k is due at start + k * period. A cycle that starts more than a
/// period late resets the schedule instead of bursting to catch up.
#[derive(Debug)]
pub struct Schedule {
    period: Duration,
    next_due: Instant,
}

impl Schedule {
    pub fn new(period: Duration, now: Instant) -> Self {
        Self {
            period,
            next_due: now,
        }
    }

    pub fn next_due(&self) -> Instant {
        self.next_due
    }

    /// Called when the due cycle starts at `now`; returns whether it overran (and was re-timed).
    pub fn advance(&mut self, now: Instant) -> bool {
        self.next_due += self.period;
        if now > self.next_due {
            self.next_due = now + self.period;
            return true;
        }
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_use_nearest_rank() {
        let samples: Vec<u32> = (1..=100).collect();
        assert_eq!(percentile(&samples, 0.5), 50);
        assert_eq!(percentile(&samples, 0.99), 99);
        assert_eq!(percentile(&samples, 1.0), 100);
        assert_eq!(percentile(&[], 0.5), 0);
    }

    #[test]
    fn lateness_and_rate_are_measured_against_the_schedule() {
        let start = Instant::now();
        let mut stats = CycleStats::new(start);
        for k in 0..200u64 {
            let due = start + Duration::from_millis(5 * k);
            stats.record_start(due + Duration::from_micros(k % 10), Some(due));
        }
        let summary = stats.summary(start + Duration::from_secs(1));
        assert_eq!(summary.cycles, 200);
        assert!((summary.cycles_per_second - 200.0).abs() < 1e-9);
        assert_eq!(summary.lateness_max_us, 9);
        // Lateness 0..9 us in turn: most periods are 5001 us, one in ten 4991 us.
        assert_eq!(summary.period_p50_us, 5001);
        assert_eq!(summary.lateness_p50_us, 4);
    }

    #[test]
    fn an_overrun_retimes_the_schedule_instead_of_bursting() {
        let start = Instant::now();
        let mut schedule = Schedule::new(Duration::from_millis(5), start);
        assert!(!schedule.advance(start));
        assert_eq!(schedule.next_due(), start + Duration::from_millis(5));
        let late = start + Duration::from_millis(23);
        assert!(schedule.advance(late));
        assert_eq!(schedule.next_due(), late + Duration::from_millis(5));
    }
}
