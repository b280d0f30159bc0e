//! Rate limiting for repeated warnings: a flood of bad commands must not flood the log.

use std::time::{Duration, Instant};

/// Lets one message through per `period`, counting what it held back in between.
#[derive(Debug)]
pub struct RateLimiter {
    period: Duration,
    last_emitted: Option<Instant>,
    suppressed: u64,
}

impl RateLimiter {
    pub fn new(period: Duration) -> Self {
        Self {
            period,
            last_emitted: None,
            suppressed: 0,
        }
    }

    /// `Some(n)` when a message may be emitted now, with `n` the number held back since the last
    /// one; `None` when this one should be held back.
    pub fn check(&mut self, now: Instant) -> Option<u64> {
        match self.last_emitted {
            Some(last) if now.duration_since(last) < self.period => {
                self.suppressed += 1;
                None
            }
            _ => {
                self.last_emitted = Some(now);
                Some(std::mem::take(&mut self.suppressed))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn emits_once_per_period_and_counts_the_rest() {
        let mut limiter = RateLimiter::new(Duration::from_secs(1));
        let start = Instant::now();
        assert_eq!(limiter.check(start), Some(0));
        for i in 1..=5 {
            assert_eq!(limiter.check(start + Duration::from_millis(100 * i)), None);
        }
        assert_eq!(limiter.check(start + Duration::from_millis(1000)), Some(5));
        assert_eq!(limiter.check(start + Duration::from_millis(1001)), None);
    }
}
