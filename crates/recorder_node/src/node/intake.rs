//! The arithmetic of taking samples in: DDS timestamps in ns, a topic's log times that never step
//! back, each reader's history depth, and the count of lost messages until the writer has it.
//! Pure logic.

/// Reader history depth: enough for bursts while the receive thread is busy. Images are large,
/// so their readers keep fewer.
pub const DEPTH: usize = 1000;
const IMAGE_DEPTH: usize = 64;

/// The history depth of a reader of `type_name`.
pub fn reader_depth(type_name: &str) -> usize {
    if type_name.contains("Image") {
        IMAGE_DEPTH
    } else {
        DEPTH
    }
}

/// ns since the epoch of a DDS timestamp's ticks (seconds in the high 32 bits, 2^-32 s in the low).
pub fn ns_from_ticks(ticks: u64) -> u64 {
    (ticks >> 32) * 1_000_000_000 + (((ticks & 0xFFFF_FFFF) * 1_000_000_000) >> 32)
}

/// One topic's log times: RustDDS's receive instants can step back by microseconds when samples
/// arrive reordered, and a topic's log times must not.
#[derive(Debug, Default)]
pub struct LogClock {
    last_ns: u64,
}

impl LogClock {
    /// The log time of a sample received at `received_ns`.
    pub fn stamp(&mut self, received_ns: u64) -> u64 {
        self.last_ns = received_ns.max(self.last_ns);
        self.last_ns
    }
}

/// Messages lost (sequence gaps, a full queue) in all, and those the writer has not been told of
/// yet (it is told without waiting, so a report may not fit in its queue).
#[derive(Debug, Default)]
pub struct Losses {
    pub total: u64,
    unreported: u64,
}

impl Losses {
    /// Counts `lost` more and offers everything not yet reported to `report` (false: it did not
    /// fit; it is offered again with the next loss).
    pub fn add(&mut self, lost: u64, report: impl FnOnce(u64) -> bool) {
        self.total += lost;
        self.unreported += lost;
        if report(self.unreported) {
            self.unreported = 0;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dds_ticks_are_fractions_of_a_second_in_the_low_word() {
        assert_eq!(ns_from_ticks(0), 0);
        assert_eq!(ns_from_ticks(3 << 32), 3_000_000_000);
        assert_eq!(ns_from_ticks((1 << 32) | (1 << 31)), 1_500_000_000);
        assert_eq!(ns_from_ticks(u64::from(u32::MAX)), 999_999_999);
    }

    #[test]
    fn log_times_never_step_back() {
        let mut clock = LogClock::default();
        assert_eq!(clock.stamp(100), 100);
        assert_eq!(
            clock.stamp(90),
            100,
            "a reordered sample keeps the last time"
        );
        assert_eq!(clock.stamp(120), 120);
    }

    #[test]
    fn images_get_shallower_histories() {
        assert_eq!(reader_depth("sensor_msgs/msg/Image"), IMAGE_DEPTH);
        assert_eq!(reader_depth("sensor_msgs/msg/CompressedImage"), IMAGE_DEPTH);
        assert_eq!(reader_depth("sensor_msgs/msg/JointState"), DEPTH);
    }

    #[test]
    fn a_loss_report_that_does_not_fit_is_carried_into_the_next() {
        let mut losses = Losses::default();
        let mut told = Vec::new();
        losses.add(2, |count| {
            told.push(count);
            false
        });
        losses.add(3, |count| {
            told.push(count);
            true
        });
        losses.add(1, |count| {
            told.push(count);
            true
        });
        assert_eq!(told, [2, 5, 1]);
        assert_eq!(losses.total, 6);
    }
}
