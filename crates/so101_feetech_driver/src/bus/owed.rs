//! Answers that servos still owe: a request timed out, so its reply may yet arrive, late, in the
//! middle of a later transaction. Pure bookkeeping; the bus consults it to keep such a reply from
//! being taken as the answer to the next request.

use std::time::{Duration, Instant};

/// How long a missed answer is expected at the most. A reply later than this is not waited for;
/// the length tag still keeps it apart from reads for as long as the entry lives.
const OWED_FOR: Duration = Duration::from_secs(1);
/// Extra bytes a read may ask for to stand apart from owed replies (the extra bytes are dropped).
const MAX_TAG: u8 = 3;
/// Entries kept at the most (a bus that answers nothing must not grow the list without bound).
const CAPACITY: usize = 64;
/// The STS3215's control table ends here (Maximum_Acceleration, 85, is its last register); a
/// tagged read must stay inside it.
const TABLE_END: u16 = 86;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Owed {
    id: u8,
    /// Data bytes of the missed answer (0 for a PING or WRITE acknowledgement).
    len: usize,
    /// How many such answers are owed (one per attempt that went unanswered).
    count: u32,
    since: Instant,
}

#[derive(Debug, Default)]
pub struct OwedReplies {
    entries: Vec<Owed>,
}

impl OwedReplies {
    /// Records that each of `ids` missed an answer with `len` data bytes.
    pub fn add(&mut self, ids: &[u8], len: usize, now: Instant) {
        self.expire(now);
        for &id in ids {
            match self
                .entries
                .iter_mut()
                .find(|owed| (owed.id, owed.len) == (id, len))
            {
                Some(owed) => {
                    owed.count += 1;
                    owed.since = now;
                }
                None => self.entries.push(Owed {
                    id,
                    len,
                    count: 1,
                    since: now,
                }),
            }
        }
        if self.entries.len() > CAPACITY {
            let excess = self.entries.len() - CAPACITY;
            self.entries.drain(..excess);
        }
    }

    /// A reply from `id` with `len` data bytes arrived that no request is waiting for: whether it
    /// was owed (then one of them is settled).
    pub fn settle(&mut self, id: u8, len: usize) -> bool {
        let Some(index) = self
            .entries
            .iter()
            .position(|owed| (owed.id, owed.len) == (id, len))
        else {
            return false;
        };
        self.entries[index].count -= 1;
        if self.entries[index].count == 0 {
            self.entries.remove(index);
        }
        true
    }

    /// Whether any of `ids` owes an answer with `len` data bytes.
    pub fn any_of(&mut self, ids: &[u8], len: usize, now: Instant) -> bool {
        self.expire(now);
        self.entries
            .iter()
            .any(|owed| owed.len == len && ids.contains(&owed.id))
    }

    /// How many bytes a read of `length` at `address` from `ids` should ask for, so that no owed
    /// answer has that length: `length` itself unless one does; `None` when every length within
    /// reach is owed (the owed answers must be waited out first).
    pub fn distinct_length(&self, address: u8, length: u8, ids: &[u8]) -> Option<u8> {
        (0..=MAX_TAG)
            .map(|tag| length.saturating_add(tag))
            .filter(|asked| *asked == length || u16::from(address) + u16::from(*asked) <= TABLE_END)
            .find(|asked| {
                !self
                    .entries
                    .iter()
                    .any(|owed| owed.len == usize::from(*asked) && ids.contains(&owed.id))
            })
    }

    /// Gives up on every answer `ids` owe (waited out: taken as lost).
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    pub fn forget(&mut self, ids: &[u8]) {
        self.entries.retain(|owed| !ids.contains(&owed.id));
    }

    fn expire(&mut self, now: Instant) {
        self.entries
            .retain(|owed| now.duration_since(owed.since) < OWED_FOR);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_read_asks_for_a_length_no_owed_answer_has() {
        let now = Instant::now();
        let mut owed = OwedReplies::default();
        assert_eq!(owed.distinct_length(56, 2, &[1, 2]), Some(2));
        owed.add(&[2], 2, now);
        assert_eq!(owed.distinct_length(56, 2, &[1, 2]), Some(3));
        assert_eq!(
            owed.distinct_length(56, 2, &[1]),
            Some(2),
            "only servo 2 owes"
        );
        owed.add(&[1], 3, now);
        assert_eq!(owed.distinct_length(56, 2, &[1, 2]), Some(4));
        owed.add(&[2], 1, now);
        assert_eq!(
            owed.distinct_length(85, 1, &[2]),
            None,
            "no tag past the end of the table"
        );
        owed.forget(&[2]);
        assert_eq!(owed.distinct_length(85, 1, &[2]), Some(1));
    }

    #[test]
    fn every_unanswered_attempt_owes_one_answer_settled_once() {
        let now = Instant::now();
        let mut owed = OwedReplies::default();
        owed.add(&[4], 0, now);
        owed.add(&[4], 0, now);
        assert!(owed.any_of(&[3, 4], 0, now));
        assert!(!owed.any_of(&[4], 2, now));
        assert!(owed.settle(4, 0));
        assert!(owed.settle(4, 0), "two attempts went unanswered");
        assert!(!owed.settle(4, 0), "each answer settled once");
        owed.add(&[4], 2, now);
        assert!(!owed.any_of(&[4], 2, now + OWED_FOR));
    }

    #[test]
    fn the_list_is_bounded() {
        let now = Instant::now();
        let mut owed = OwedReplies::default();
        for len in 0..200 {
            owed.add(&[1], len, now);
        }
        assert_eq!(owed.entries.len(), CAPACITY);
    }
}
