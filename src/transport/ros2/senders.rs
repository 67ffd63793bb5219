//! The publishers a reader has heard from, by their DDS sequence numbers:
//! what they say they sent, and the messages missing before the reader.
//! A fixed table: nothing allocates per message.

/// Most publishers whose sequence numbers a channel follows; messages of
/// further ones are relayed and counted as `writers_untracked`.
pub const WRITERS_TRACKED: usize = 16;

/// The publishers a channel has heard from: their GUIDs, the first and
/// last sequence numbers seen. A fixed table: no allocation per message.
#[derive(Debug, Clone)]
pub struct Senders {
    guid: [[u8; 16]; WRITERS_TRACKED],
    first: [i64; WRITERS_TRACKED],
    last: [i64; WRITERS_TRACKED],
    len: usize,
    /// The entry of the last message, looked at first.
    hint: usize,
}

impl Senders {
    /// An empty table.
    pub fn new() -> Senders {
        Senders { guid: [[0; 16]; WRITERS_TRACKED], first: [0; WRITERS_TRACKED], last: [0; WRITERS_TRACKED], len: 0, hint: 0 }
    }

    /// Message `sequence` of `guid` came: the messages missing before it,
    /// or `None` where the table is full.
    #[inline]
    pub fn saw(&mut self, guid: [u8; 16], sequence: i64) -> Option<u64> {
        let k = if self.len > 0 && self.guid[self.hint] == guid {
            self.hint
        } else if let Some(k) = self.guid[..self.len].iter().position(|g| *g == guid) {
            k
        } else if self.len < WRITERS_TRACKED {
            let k = self.len;
            self.len += 1;
            self.guid[k] = guid;
            self.first[k] = sequence;
            self.last[k] = sequence - 1;
            k
        } else {
            return None;
        };
        self.hint = k;
        let missing = (sequence - self.last[k] - 1).max(0) as u64;
        self.last[k] = self.last[k].max(sequence);
        Some(missing)
    }

    /// Whether no publisher has been heard from.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// What the publishers say they sent: their last sequence numbers.
    pub fn sent(&self) -> u64 {
        self.last[..self.len].iter().map(|&l| l.max(0) as u64).sum()
    }

    /// What they sent before the emulator first heard from each (a
    /// publisher that started first, on a volatile topic).
    pub fn before_first(&self) -> u64 {
        self.first[..self.len].iter().map(|&f| (f - 1).max(0) as u64).sum()
    }
}

impl Default for Senders {
    fn default() -> Senders {
        Senders::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn publishers_sequences_give_what_they_sent_and_what_was_lost_before_ingress() {
        let mut s = Senders::new();
        let (a, b) = ([1u8; 16], [2u8; 16]);
        assert_eq!(s.saw(a, 1), Some(0));
        assert_eq!(s.saw(a, 2), Some(0));
        assert_eq!(s.saw(a, 5), Some(2), "3 and 4 missing");
        // A publisher heard from its 10th message on.
        assert_eq!(s.saw(b, 10), Some(0));
        assert_eq!(s.saw(b, 11), Some(0));
        // An old message (DDS does not repeat them; if it did, it is no gap).
        assert_eq!(s.saw(a, 4), Some(0));
        assert_eq!((s.sent(), s.before_first()), (5 + 11, 9));
        for k in 0..(WRITERS_TRACKED - 2) {
            assert_eq!(s.saw([10 + k as u8; 16], 1), Some(0));
        }
        assert_eq!(s.saw([99; 16], 1), None, "the table is full");
        assert_eq!(s.saw(a, 6), Some(0), "known ones are still followed");
    }
}
