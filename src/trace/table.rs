//! The rows the writer holds: a frame's events joined into its row (and its
//! copies' rows) until its fate is final.

use super::ring::TraceEvent;
use crate::injector::DropCause;
use crate::metrics::LatencyHistogram;
use std::collections::VecDeque;
use std::sync::mpsc;

/// Rows the writer holds at most while their frames are queued (≈ 64 B
/// each: 16 MiB); a row older than that is written as it stands.
pub const MAX_PENDING_ROWS: usize = 1 << 18;

/// One row of the trace table.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Row {
    pub present: bool,
    pub sequence: Option<u32>,
    pub console_index: u64,
    pub send_ns: u64,
    pub ingress_ns: u64,
    pub dropped: Option<DropCause>,
    pub release_sched_ns: u64,
    pub release_ns: Option<u64>,
    /// Copies of it not yet released (their rows are in the writer's table
    /// of copies).
    pub copies_pending: u8,
    pub copies_dropped: u8,
    pub corrupted: bool,
}

impl Row {
    /// Its fate is final: dropped or released (or its ingress event was
    /// lost, and it will never be), and so is every copy's.
    fn complete(&self) -> bool {
        !self.present || ((self.dropped.is_some() || self.release_ns.is_some()) && self.copies_pending == 0)
    }
}

/// One copy's row: its frame's ingress index, its number, its schedule,
/// its release.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct CopyRow {
    pub ingress_index: u64,
    pub copy: u8,
    pub release_sched_ns: u64,
    pub release_ns: Option<u64>,
    pub corrupted: bool,
}

/// An observer of the trace's events, called by the writer thread (never
/// by the loop) as it drains the ring: the telemetry's interval
/// aggregation ([`crate::service::telemetry`]).
pub trait Tap: Send {
    /// A frame entered at `ingress_ns`; `dropped` if its fate was a drop.
    fn ingress(&mut self, ingress_ns: u64, dropped: bool);
    /// A frame was released at `release_ns` after `injected_ns` of injected
    /// delay, `lateness_ns` after its scheduled release.
    fn release(&mut self, release_ns: u64, injected_ns: u64, lateness_ns: u64);
    /// The writer's periodic wake-up (every few milliseconds).
    fn tick(&mut self);
}

/// The rows between the oldest incomplete one and the newest, and the
/// histograms of the current interval.
pub(super) struct Table {
    pub(super) base: u64,
    pub(super) rows: VecDeque<Row>,
    /// The copies' rows, in ingress order (then copy order); only runs
    /// with `duplicate` stages have any.
    pub(super) copies: VecDeque<CopyRow>,
    pub(super) decision: LatencyHistogram,
    pub(super) lateness: LatencyHistogram,
    tap: Option<Box<dyn Tap>>,
    taps: mpsc::Receiver<Box<dyn Tap>>,
}

impl Table {
    /// Room for `rows` rows and `copies` copy rows, reserved (pages become
    /// resident only as rows are stored); taps come through `taps`.
    pub(super) fn with_capacity(rows: usize, copies: usize, taps: mpsc::Receiver<Box<dyn Tap>>) -> Table {
        Table {
            base: 0,
            rows: VecDeque::with_capacity(rows),
            copies: VecDeque::with_capacity(copies),
            decision: LatencyHistogram::new(),
            lateness: LatencyHistogram::new(),
            tap: None,
            taps,
        }
    }

    /// Applies every event waiting in the ring, then wakes the tap.
    pub(super) fn take(&mut self, rx: &mut rtrb::Consumer<TraceEvent>) {
        while let Ok(ev) = rx.pop() {
            self.apply(ev);
        }
        self.tick();
    }

    /// Takes a tap if one was given, and wakes it.
    fn tick(&mut self) {
        if let Ok(t) = self.taps.try_recv() {
            self.tap = Some(t);
        }
        if let Some(t) = self.tap.as_mut() {
            t.tick();
        }
    }

    pub(super) fn apply(&mut self, ev: TraceEvent) {
        match ev {
            TraceEvent::Ingress {
                ingress_index,
                sequence,
                console_index,
                send_ns,
                ingress_ns,
                dropped,
                release_sched_ns,
                decision_ns,
                copies,
                copies_dropped,
                corrupted,
            } => {
                let Some(row) = self.row_mut(ingress_index, true) else { return };
                let release_ns = row.release_ns;
                *row = Row {
                    present: true,
                    sequence,
                    console_index,
                    send_ns,
                    ingress_ns,
                    dropped,
                    release_sched_ns,
                    release_ns,
                    copies_pending: copies,
                    copies_dropped,
                    corrupted,
                };
                self.decision.record(decision_ns);
                if let Some(t) = self.tap.as_mut() {
                    t.ingress(ingress_ns, dropped.is_some());
                }
            }
            TraceEvent::Copy { ingress_index, copy, release_sched_ns, corrupted } => {
                if ingress_index >= self.base {
                    self.copies.push_back(CopyRow { ingress_index, copy, release_sched_ns, release_ns: None, corrupted });
                }
            }
            TraceEvent::Release { ingress_index, release_sched_ns, release_ns } => self.release(ingress_index, release_sched_ns, release_ns),
        }
    }

    /// The row of `ingress_index`, if it is still held (with `grow`, made
    /// room for if it is new).
    fn row_mut(&mut self, ingress_index: u64, grow: bool) -> Option<&mut Row> {
        let at = ingress_index.checked_sub(self.base)? as usize;
        if grow && self.rows.len() <= at {
            self.rows.resize(at + 1, Row::default());
        }
        self.rows.get_mut(at)
    }

    /// A release of `ingress_index` scheduled for `sched_ns`: the frame's
    /// own if it is due then and not yet released, else its first
    /// unreleased copy due then, else its first unreleased copy (a FIFO
    /// queue may have moved a copy later than its stages asked).
    fn release(&mut self, ingress_index: u64, sched_ns: u64, release_ns: u64) {
        let Some(row) = self.row_mut(ingress_index, false) else { return };
        let own = !row.present || (row.dropped.is_none() && row.release_ns.is_none() && (row.release_sched_ns == sched_ns || row.copies_pending == 0));
        if own {
            row.release_ns = Some(release_ns);
            if row.present {
                let late_ns = release_ns.saturating_sub(row.release_sched_ns);
                let injected_ns = row.release_sched_ns.saturating_sub(row.ingress_ns);
                self.lateness.record(late_ns);
                if let Some(t) = self.tap.as_mut() {
                    t.release(release_ns, injected_ns, late_ns);
                }
            }
            return;
        }
        let ingress_ns = row.ingress_ns;
        let from = self.copies.partition_point(|c| c.ingress_index < ingress_index);
        let to = self.copies.partition_point(|c| c.ingress_index <= ingress_index);
        let unreleased = |c: &CopyRow| c.release_ns.is_none();
        let mine = self.copies.range(from..to);
        let Some(at) = mine.clone().position(|c| unreleased(c) && c.release_sched_ns == sched_ns).or_else(|| mine.clone().position(unreleased)) else {
            // The copy's own event was lost (a full ring): its frame's row
            // must still complete.
            if let Some(row) = self.row_mut(ingress_index, false) {
                row.copies_pending = row.copies_pending.saturating_sub(1);
            }
            return;
        };
        let copy = &mut self.copies[from + at];
        copy.release_ns = Some(release_ns);
        copy.release_sched_ns = sched_ns;
        self.lateness.record(release_ns.saturating_sub(sched_ns));
        if let Some(t) = self.tap.as_mut() {
            t.release(release_ns, sched_ns.saturating_sub(ingress_ns), release_ns.saturating_sub(sched_ns));
        }
        if let Some(row) = self.row_mut(ingress_index, false) {
            row.copies_pending = row.copies_pending.saturating_sub(1);
        }
    }

    /// Takes the rows that are complete (or, past the bound, the oldest),
    /// oldest first, each followed by its copies' rows, into `f`; with
    /// `all`, every row.
    pub(super) fn drain(&mut self, all: bool, mut f: impl FnMut(u64, &Row, Option<&CopyRow>, bool)) {
        while let Some(front) = self.rows.front() {
            let forced = self.rows.len() > MAX_PENDING_ROWS;
            if !(all || forced || front.complete()) {
                break;
            }
            let row = self.rows.pop_front().expect("a front row");
            let incomplete = forced && !row.complete();
            if row.present {
                f(self.base, &row, None, incomplete);
            }
            while self.copies.front().is_some_and(|c| c.ingress_index <= self.base) {
                let copy = self.copies.pop_front().expect("a front copy");
                if row.present && copy.ingress_index == self.base {
                    f(self.base, &row, Some(&copy), incomplete);
                }
            }
            self.base += 1;
        }
    }
}
