//! Loss detection: every DDS writer numbers its samples, so a jump in one writer's sequence numbers
//! is a sample that never reached the recorder. Pure logic.

use std::collections::HashMap;

/// Last sequence number seen per (topic, writer).
#[derive(Debug, Default)]
pub struct GapTracker {
    last: HashMap<(usize, [u8; 16]), i64>,
}

impl GapTracker {
    /// Records sample `sequence` of `writer` on `topic`; returns how many samples before it were
    /// missed (0 for the first sample of a writer: what came before the recorder joined is not a
    /// loss).
    pub fn observe(&mut self, topic: usize, writer: [u8; 16], sequence: i64) -> u64 {
        let previous = self.last.insert((topic, writer), sequence);
        match previous {
            Some(last) if sequence > last + 1 => (sequence - last - 1) as u64,
            // A repeat or an older sample (a writer that restarted numbering): not a loss.
            Some(last) if sequence <= last => {
                self.last.insert((topic, writer), sequence.max(last));
                0
            }
            _ => 0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn jumps_in_one_writers_numbers_are_losses() {
        let mut tracker = GapTracker::default();
        let (a, b) = ([1; 16], [2; 16]);
        assert_eq!(tracker.observe(0, a, 5), 0);
        assert_eq!(tracker.observe(0, a, 6), 0);
        assert_eq!(tracker.observe(0, a, 9), 2);
        assert_eq!(
            tracker.observe(0, b, 1),
            0,
            "another writer counts on its own"
        );
        assert_eq!(tracker.observe(1, a, 100), 0, "and so does another topic");
        assert_eq!(tracker.observe(0, a, 9), 0);
        assert_eq!(tracker.observe(0, a, 10), 0);
    }
}
