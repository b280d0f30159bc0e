//! Capture instants as ROS stamps. A V4L2 buffer carries the instant its first byte was captured
//! on CLOCK_MONOTONIC (flag V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC); ROS stamps are on the system
//! clock. The two are read together, and the stamp is the system time that many nanoseconds
//! before now, so a frame that waited in a queue keeps the instant it was taken.

use std::time::Duration;

/// One reading of both clocks, taken together (the monotonic one just before the system one).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ClockPair {
    pub monotonic: Duration,
    /// Since the Unix epoch.
    pub system: Duration,
}

impl ClockPair {
    /// Both clocks read together: the system clock between two monotonic readings, of three
    /// tries the one with the two monotonic readings closest together (a thread preempted between
    /// the readings would otherwise shift the stamps of a frame by the preemption).
    pub fn read(monotonic: impl Fn() -> Duration, system: impl Fn() -> Duration) -> Self {
        let try_once = || {
            let before = monotonic();
            let system = system();
            let window = monotonic().saturating_sub(before);
            let pair = Self {
                monotonic: before + window / 2,
                system,
            };
            (window, pair)
        };
        let first = try_once();
        let second = try_once();
        let third = try_once();
        [second, third]
            .into_iter()
            .fold(
                first,
                |best, next| if next.0 < best.0 { next } else { best },
            )
            .1
    }
}

/// The system-clock instant (since the Unix epoch) of `captured` on the monotonic clock, or
/// `None` when the capture lies after the reading (a device clock that is not the monotonic
/// one: the caller stamps the frame with the reading then, and counts it).
pub fn system_time_of(captured: Duration, now: ClockPair) -> Option<Duration> {
    let age = now.monotonic.checked_sub(captured)?;
    now.system.checked_sub(age)
}

/// How late a frame is: from its capture to `now`, on the monotonic clock.
pub fn latency(captured: Duration, now_monotonic: Duration) -> Option<Duration> {
    now_monotonic.checked_sub(captured)
}

#[cfg(test)]
mod tests {
    use super::*;

    const NOW: ClockPair = ClockPair {
        monotonic: Duration::from_secs(5_000),
        system: Duration::from_secs(1_795_000_000),
    };

    #[test]
    fn a_frame_keeps_the_instant_it_was_captured() {
        let captured = NOW.monotonic - Duration::from_millis(33);
        assert_eq!(
            system_time_of(captured, NOW),
            Some(NOW.system - Duration::from_millis(33))
        );
        assert_eq!(
            latency(captured, NOW.monotonic),
            Some(Duration::from_millis(33))
        );
    }

    #[test]
    fn the_reading_with_the_narrowest_window_is_kept() {
        use std::cell::Cell;
        // Monotonic readings: a preempted first try (5 ms between its readings), then a quick one.
        let readings = [0_u64, 5_000, 6_000, 6_010, 7_000, 7_100];
        let index = Cell::new(0);
        let monotonic = || {
            let at = readings[index.get()];
            index.set(index.get() + 1);
            Duration::from_micros(at)
        };
        let system = || Duration::from_micros(1_000_000 + readings[index.get()]);
        let pair = ClockPair::read(monotonic, system);
        assert_eq!(pair.monotonic, Duration::from_micros(6_005));
        assert_eq!(pair.system, Duration::from_micros(1_006_010));
    }

    #[test]
    fn a_capture_after_the_reading_is_not_mapped() {
        let future = NOW.monotonic + Duration::from_micros(1);
        assert_eq!(system_time_of(future, NOW), None);
        assert_eq!(latency(future, NOW.monotonic), None);
        assert_eq!(system_time_of(NOW.monotonic, NOW), Some(NOW.system));
    }
}
