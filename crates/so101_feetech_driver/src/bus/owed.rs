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
/// The STS3215 control table ends here; a tagged read must stay inside it.
const TABLE_END: u16 = 256;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Owed {
    id: u8,
    /// Data bytes of the missed answer (0 for a PING or WRITE acknowledgement).
    len: usize,
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
            self.entries.retain(|owed| (owed.id, owed.len) != (id, len));
            self.entries.push(Owed {
                id,
                len,
                since: now,
            });
        }
        if self.entries.len() > CAPACITY {
            let excess = self.entries.len() - CAPACITY;
            self.entries.drain(..excess);
        }
    }

    /// A reply from `id` with `len` data bytes arrived that no request is waiting for: whether it
    /// was owed (then it is settled).
    pub fn settle(&mut self, id: u8, len: usize) -> bool {
        match self
            .entries
            .iter()
            .position(|owed| (owed.id, owed.len) == (id, len))
        {
            Some(index) => {
                self.entries.remove(index);
                true
            }
            None => false,
        }
    }

    /// Whether any of `ids` owes an answer with `len` data bytes.
    pub fn any_of(&mut self, ids: &[u8], len: usize, now: Instant) -> bool {
        self.expire(now);
        self.entries
            .iter()
            .any(|owed| owed.len == len && ids.contains(&owed.id))
    }

    /// How many bytes a read of `length` at `address` from `ids` should ask for, so that no owed
    /// answer has that length: `length` itself unless one does.
    pub fn distinct_length(&self, address: u8, length: u8, ids: &[u8]) -> u8 {
        (0..=MAX_TAG)
            .map(|tag| length.saturating_add(tag))
            .filter(|asked| u16::from(address) + u16::from(*asked) <= TABLE_END)
            .find(|asked| {
                !self
                    .entries
                    .iter()
                    .any(|owed| owed.len == usize::from(*asked) && ids.contains(&owed.id))
            })
            .unwrap_or(length)
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
        assert_eq!(owed.distinct_length(56, 2, &[1, 2]), 2);
        owed.add(&[2], 2, now);
        assert_eq!(owed.distinct_length(56, 2, &[1, 2]), 3);
        assert_eq!(owed.distinct_length(56, 2, &[1]), 2, "only servo 2 owes");
        owed.add(&[1], 3, now);
        assert_eq!(owed.distinct_length(56, 2, &[1, 2]), 4);
        assert_eq!(
            owed.distinct_length(254, 2, &[2]),
            2,
            "no tag past the end of the table"
        );
    }

    #[test]
    fn an_owed_answer_is_settled_once_and_expires() {
        let now = Instant::now();
        let mut owed = OwedReplies::default();
        owed.add(&[4], 0, now);
        assert!(owed.any_of(&[3, 4], 0, now));
        assert!(!owed.any_of(&[4], 2, now));
        assert!(owed.settle(4, 0));
        assert!(!owed.settle(4, 0), "settled once");
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
