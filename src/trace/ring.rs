//! The hot path's side of the trace: the events the loop reports and the
//! wait-free ring it pushes them into.

use crate::injector::DropCause;

/// What the emulator reports about a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TraceEvent {
    Ingress {
        ingress_index: u64,
        sequence: Option<u32>,
        console_index: u64,
        send_ns: u64,
        ingress_ns: u64,
        /// `None` if scheduled.
        dropped: Option<DropCause>,
        release_sched_ns: u64,
        /// Time taken to decide the frame's fate.
        decision_ns: u64,
        /// Copies of it the queue took; a [`TraceEvent::Copy`] follows for each.
        copies: u8,
        /// Copies of it that a later stage or a full queue dropped.
        copies_dropped: u8,
        /// Whether it was queued with bits flipped.
        corrupted: bool,
    },
    /// The `copy`-th copy (from 1) of the frame `ingress_index`, queued for
    /// `release_sched_ns`.
    Copy { ingress_index: u64, copy: u8, release_sched_ns: u64, corrupted: bool },
    /// A release of the frame `ingress_index` (or of one of its copies)
    /// scheduled for `release_sched_ns`.
    Release { ingress_index: u64, release_sched_ns: u64, release_ns: u64 },
}

/// Ring capacity in events: at 100 kHz two events per frame, ~1.3 s of
/// events before the writer must have drained.
pub const RING_CAPACITY: usize = 1 << 18;

/// The hot path's end of the ring.
pub struct TraceSink {
    tx: rtrb::Producer<TraceEvent>,
    overflowed: u64,
}

impl TraceSink {
    /// Pushes an event; never blocks or allocates.
    #[inline]
    pub fn push(&mut self, ev: TraceEvent) {
        if self.tx.push(ev).is_err() {
            self.overflowed += 1;
        }
    }

    /// Events lost because the ring was full.
    pub fn overflowed(&self) -> u64 {
        self.overflowed
    }
}

/// A ring of [`RING_CAPACITY`] events, its pages resident: the loop's sink
/// and the writer's end.
pub(super) fn ring() -> (TraceSink, rtrb::Consumer<TraceEvent>) {
    let (mut tx, mut rx) = rtrb::RingBuffer::<TraceEvent>::new(RING_CAPACITY);
    // Write every slot once before the hot path starts, so the ring's pages
    // are resident: otherwise a fresh page is faulted in every few dozen
    // frames, on the hot thread, for the first pass through the ring.
    let blank = TraceEvent::Release { ingress_index: 0, release_sched_ns: 0, release_ns: 0 };
    while tx.push(blank).is_ok() {}
    while rx.pop().is_ok() {}
    (TraceSink { tx, overflowed: 0 }, rx)
}
