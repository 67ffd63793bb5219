//! The sans-IO injector core: a frame enters at `now` → its fate, and frames
//! leave the release queue when their time comes.
//!
//! Contract:
//! - Every frame that enters gets an ingress index (0, 1, 2, …) and exactly
//!   one fate: scheduled for release, or dropped with a [`DropCause`]. A
//!   scheduled frame is later either released ([`Injector::pop_due`]) or
//!   still held when the run ends ([`Injector::held`]). So at every moment
//!   `entered = dropped + released + held`, which [`Counts::balanced`] checks.
//! - Copies (`duplicate` stages, docs/spec.md §3.8) are counted apart: each
//!   copy a stage makes adds one to [`Counts::duplicated`] and then has a
//!   fate of its own (scheduled under its original's ingress index, or
//!   dropped by a later stage or for `queue_full`). The balance becomes
//!   `entered + duplicated = released + dropped + held`, the same as before
//!   for a run without duplication; `released` may exceed `entered` by at
//!   most the copies.
//! - Flips (`corrupt` stages, docs/spec.md §3.9): the injector is generic
//!   over the item, so it does not flip bits itself. [`Injector::ingress_with`]
//!   hands each scheduled item (the original and every copy) with its
//!   non-empty [`Flips`] to the caller's `apply` before queueing it; the
//!   emulator applies them to the frame's 124 bytes with
//!   [`crate::frame::flip_bits`]. [`Counts::corrupted`] counts the scheduled
//!   items that carried flips.
//! - No clock, I/O or allocation after construction: `now_ns` is passed in,
//!   the queue's capacity is fixed, and a frame that does not fit is a fate of
//!   its own ([`DropCause::QueueFull`]), never a silent loss.
//! - The timeline's phases are selected by the time since the first frame.

use crate::model::ModelKind;
use crate::scenario::{Decision, Flips, Scenario, Switched, Timeline};
use crate::scheduler::{CapacityError, QueueOrder, ReleaseQueue, Released};

/// Why an entering frame could not be decided at all.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Invalid {
    /// Its length is not the protocol's.
    WrongSize,
    /// Its checksum does not match its contents (when such frames are dropped).
    BadChecksum,
    /// Its control bits are none the sender may set (garbage, or a
    /// malformed end marker).
    BadFlags,
    /// Its payload is larger than the run's maximum (variable-size payloads).
    TooLarge,
}

impl Invalid {
    /// Every reason a frame is refused before the scenario.
    pub const ALL: [Invalid; 4] = [Invalid::WrongSize, Invalid::BadChecksum, Invalid::BadFlags, Invalid::TooLarge];

    /// The reason a report or a trace names `reason` by, if it is one of these.
    pub fn of_reason(reason: &str) -> Option<Invalid> {
        Invalid::ALL.into_iter().find(|i| i.name() == reason)
    }

    pub const fn name(self) -> &'static str {
        match self {
            Invalid::WrongSize => "wrong_size",
            Invalid::BadChecksum => "bad_checksum",
            Invalid::BadFlags => "bad_flags",
            Invalid::TooLarge => "too_large",
        }
    }
}

/// Why an injector could not be built.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum BuildError {
    /// The release queue's capacity is out of range; the message names the
    /// field and the memory it would need.
    #[error(transparent)]
    QueueCapacity(#[from] CapacityError),
}

/// Why a frame was dropped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DropCause {
    /// A stage of the scenario dropped it (indices from 0).
    Stage { phase: u16, stage: u16, kind: ModelKind },
    /// The release queue was full.
    QueueFull,
    /// The frame was malformed.
    Invalid(Invalid),
}

impl DropCause {
    /// The reason as reported: the model's name, `queue_full`, `wrong_size`
    /// or `bad_checksum`.
    pub fn reason(self) -> &'static str {
        match self {
            // `link_queue` for the link stages (`rate`, `trace`).
            DropCause::Stage { kind, .. } => kind.drop_reason(),
            DropCause::QueueFull => "queue_full",
            DropCause::Invalid(i) => i.name(),
        }
    }
}

/// A frame's fate at ingress.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fate {
    /// Held until `release_ns` (`delay_ns` after ingress).
    Scheduled { release_ns: u64, delay_ns: u64 },
    Dropped(DropCause),
}

/// What [`Injector::ingress`] returns.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Entered {
    pub ingress_index: u64,
    /// The original frame's fate.
    pub fate: Fate,
    /// Copies of it scheduled for release (under the same ingress index);
    /// 0 without `duplicate` stages.
    pub copies: u8,
    /// Whether the original was scheduled with bits to flip.
    pub corrupted: bool,
}

/// Running totals. Per-stage drops live in the scenario's stages.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Counts {
    pub entered: u64,
    pub released: u64,
    pub dropped_by_stage: u64,
    pub dropped_queue_full: u64,
    pub dropped_wrong_size: u64,
    pub dropped_bad_checksum: u64,
    pub dropped_bad_flags: u64,
    /// Payloads larger than the run's maximum.
    pub dropped_too_large: u64,
    pub held: u64,
    /// Copies made by `duplicate` stages (each then released, dropped or
    /// held like any frame).
    pub duplicated: u64,
    /// Scheduled frames (originals and copies) that carry bits to flip
    /// (`corrupt` stages). Not a fate: they are also counted as scheduled.
    pub corrupted: u64,
}

impl Counts {
    pub fn dropped(&self) -> u64 {
        self.dropped_by_stage + self.dropped_queue_full + self.dropped_wrong_size + self.dropped_bad_checksum + self.dropped_bad_flags + self.dropped_too_large
    }

    /// `entered + duplicated = released + dropped + held` (with no
    /// duplication: `entered = released + dropped + held`).
    pub fn balanced(&self) -> bool {
        self.entered + self.duplicated == self.released + self.dropped() + self.held
    }
}

/// The injector: a scenario and a release queue holding items of type `T`
/// (the shared-memory sample in the emulator, `()` in simulated time).
#[derive(Debug, Clone)]
pub struct Injector<T> {
    scenario: Scenario,
    queue: ReleaseQueue<T>,
    start_ns: Option<u64>,
    counts: Counts,
}

impl<T: Copy + Default> Injector<T> {
    /// The queue is a FIFO ring when no stage can reorder, else a ladder
    /// queue (see [`crate::scheduler`]); it holds at most `queue_capacity` frames
    /// (1..=[`crate::scheduler::MAX_CAPACITY`]), all allocated here.
    pub fn try_new(scenario: Scenario, queue_capacity: usize) -> Result<Self, BuildError> {
        let order = if scenario.may_reorder() { QueueOrder::Reorder } else { QueueOrder::Fifo };
        Self::try_with_order(scenario, queue_capacity, order)
    }

    /// [`Injector::try_new`] with the queue's order chosen by the caller: a
    /// run that may be switched to a scenario that reorders needs
    /// `Reorder` from the start.
    pub fn try_with_order(scenario: Scenario, queue_capacity: usize, order: QueueOrder) -> Result<Self, BuildError> {
        let queue = ReleaseQueue::try_new(order, queue_capacity)?;
        Ok(Injector { scenario, queue, start_ns: None, counts: Counts::default() })
    }

    /// [`Injector::try_new`] for a capacity already validated (a constant,
    /// or checked at start-up): an invalid one panics with the error's
    /// message. Input from a user goes through `try_new`.
    pub fn new(scenario: Scenario, queue_capacity: usize) -> Self {
        Self::try_new(scenario, queue_capacity).unwrap_or_else(|e| panic!("{e}"))
    }

    pub fn scenario(&self) -> &Scenario {
        &self.scenario
    }

    pub fn queue_order(&self) -> QueueOrder {
        self.queue.order()
    }

    pub fn queue_capacity(&self) -> usize {
        self.queue.capacity()
    }

    pub fn counts(&self) -> Counts {
        Counts { held: self.queue.len() as u64, ..self.counts }
    }

    /// Frames scheduled but not yet released.
    pub fn held(&self) -> usize {
        self.queue.len()
    }

    /// The ingress index the next frame will get.
    pub fn next_ingress_index(&self) -> u64 {
        self.counts.entered
    }

    /// The run's start: the first frame's ingress time.
    pub fn start_ns(&self) -> Option<u64> {
        self.start_ns
    }

    fn enter(&mut self, now_ns: u64) -> (u64, u64) {
        let start = *self.start_ns.get_or_insert(now_ns);
        let index = self.counts.entered;
        self.counts.entered += 1;
        (index, now_ns.saturating_sub(start))
    }

    /// A frame enters at `now_ns`: decide it, and queue it if it survives.
    /// Bits a `corrupt` stage asked to flip are not applied (the item is
    /// opaque here); use [`Injector::ingress_with`] to apply them.
    #[inline]
    pub fn ingress(&mut self, now_ns: u64, item: T) -> Entered {
        self.ingress_with(now_ns, item, |_, _| {})
    }

    /// [`Injector::ingress`], calling `apply(&mut item, flips)` for the
    /// original and each copy that is about to be queued with bits to flip
    /// (never for one without). Each copy starts from the item as it entered.
    #[inline]
    pub fn ingress_with(&mut self, now_ns: u64, item: T, apply: impl FnMut(&mut T, &Flips)) -> Entered {
        self.ingress_len_with(now_ns, item, None, apply)
    }

    /// [`Injector::ingress_with`] for a payload of `len` bytes when given:
    /// the link stages (`rate`, `trace`) cut that size into packets
    /// ([`Scenario::decide_len`]) instead of their configured payload.
    #[inline]
    pub fn ingress_len_with(&mut self, now_ns: u64, item: T, len: Option<u64>, mut apply: impl FnMut(&mut T, &Flips)) -> Entered {
        let (ingress_index, offset_ns) = self.enter(now_ns);
        let decision = match len {
            Some(len) => self.scenario.decide_len(offset_ns, now_ns, len),
            None => self.scenario.decide(offset_ns, now_ns),
        };
        let mut corrupted = false;
        let fate = match decision {
            Decision::Drop { phase, stage } => {
                self.counts.dropped_by_stage += 1;
                let kind = self.scenario.stage(phase, stage).kind();
                Fate::Dropped(DropCause::Stage { phase, stage, kind })
            }
            Decision::Pass { delay_ns } => {
                // Read in place: a copy of the `Flips` (34 bytes) per frame
                // costs more than the check.
                let flips = self.scenario.flips();
                let flipped = !flips.is_empty();
                let mut own = item;
                if flipped {
                    apply(&mut own, flips);
                }
                match self.queue.push(now_ns.saturating_add(delay_ns), ingress_index, own) {
                    Ok(release_ns) => {
                        if flipped {
                            self.counts.corrupted += 1;
                            corrupted = true;
                        }
                        Fate::Scheduled { release_ns, delay_ns: release_ns - now_ns }
                    }
                    Err(_) => {
                        self.counts.dropped_queue_full += 1;
                        self.scenario.dropped_after_pipeline(None);
                        Fate::Dropped(DropCause::QueueFull)
                    }
                }
            }
        };
        let copies = self.scenario.copies();
        let mut scheduled = 0u8;
        if copies.made() > 0 {
            self.counts.duplicated += copies.made();
            self.counts.dropped_by_stage += copies.dropped();
            // The copies the queue refused, one bit each (at most
            // MAX_COPIES = 15), told to the scenario once the copies are
            // no longer borrowed.
            let mut refused = 0u16;
            for (k, (&delay_ns, flips)) in copies.delays_ns().iter().zip(copies.flips()).enumerate() {
                let mut copy = item;
                if !flips.is_empty() {
                    apply(&mut copy, flips);
                }
                match self.queue.push(now_ns.saturating_add(delay_ns), ingress_index, copy) {
                    Ok(_) => {
                        scheduled += 1;
                        self.counts.corrupted += u64::from(!flips.is_empty());
                    }
                    Err(_) => {
                        self.counts.dropped_queue_full += 1;
                        refused |= 1 << k;
                    }
                }
            }
            while refused != 0 {
                self.scenario.dropped_after_pipeline(Some(refused.trailing_zeros() as usize));
                refused &= refused - 1;
            }
        }
        Entered { ingress_index, fate, copies: scheduled, corrupted }
    }

    /// A malformed frame enters at `now_ns`: it gets an ingress index and is
    /// dropped for `why`, without reaching the scenario.
    pub fn reject(&mut self, now_ns: u64, why: Invalid) -> Entered {
        let (ingress_index, _) = self.enter(now_ns);
        match why {
            Invalid::WrongSize => self.counts.dropped_wrong_size += 1,
            Invalid::BadChecksum => self.counts.dropped_bad_checksum += 1,
            Invalid::BadFlags => self.counts.dropped_bad_flags += 1,
            Invalid::TooLarge => self.counts.dropped_too_large += 1,
        }
        Entered { ingress_index, fate: Fate::Dropped(DropCause::Invalid(why)), copies: 0, corrupted: false }
    }

    /// Switches the scenario (see [`crate::scenario::Timeline`]): from
    /// `at_ns` (ns from the run's first frame), or from `now_ns` when
    /// `at_ns` is `None` or already past, `timeline`'s phases replace the
    /// rest of the run's timeline. Frames already queued keep their release
    /// times. Allocates nothing; refused (the timeline handed back) when the
    /// run has no room left for the phases.
    pub fn switch(&mut self, now_ns: u64, at_ns: Option<u64>, timeline: Timeline) -> Result<Switched, Timeline> {
        let now_offset_ns = self.start_ns.map_or(0, |s| now_ns.saturating_sub(s));
        let from_ns = at_ns.map_or(now_offset_ns, |at| at.max(now_offset_ns));
        self.scenario.splice(from_ns, self.start_ns.is_some(), timeline)
    }

    /// Makes room for `extra` phases to be switched in without allocating.
    pub fn reserve_phases(&mut self, extra: usize) {
        self.scenario.reserve_phases(extra);
    }

    /// Pauses all faults (every frame passes at once, no stage draws) or
    /// resumes them.
    pub fn set_paused(&mut self, paused: bool) {
        self.scenario.set_paused(paused);
    }

    /// The earliest scheduled release, if any frame is held.
    #[inline]
    pub fn next_release_ns(&self) -> Option<u64> {
        self.queue.next_release_ns()
    }

    /// Takes the next frame due at `now_ns`.
    #[inline]
    pub fn pop_due(&mut self, now_ns: u64) -> Option<Released<T>> {
        let r = self.queue.pop_due(now_ns)?;
        self.counts.released += 1;
        Some(r)
    }

    /// [`pop_due`](Self::pop_due), the item read in place in the queue
    /// ([`ReleaseQueue::pop_due_ref`]): a caller that copies it on copies
    /// it once.
    #[inline]
    pub fn pop_due_ref(&mut self, now_ns: u64) -> Option<Released<&T>> {
        let r = self.queue.pop_due_ref(now_ns)?;
        self.counts.released += 1;
        Some(r)
    }

    /// Drop counts by reason (model name, `queue_full`, `wrong_size`,
    /// `bad_checksum`), zero counts omitted, in a stable order.
    pub fn drops_by_reason(&self) -> Vec<(&'static str, u64)> {
        let mut out: Vec<(&'static str, u64)> = Vec::new();
        for kind in ModelKind::ALL {
            let n: u64 = self
                .scenario
                .phases()
                .iter()
                .flat_map(|p| p.stages())
                .filter(|s| s.kind() == kind)
                .map(|s| s.dropped())
                .sum();
            if n > 0 {
                // Both link stages report as `link_queue`: one entry.
                match out.iter_mut().find(|(name, _)| *name == kind.drop_reason()) {
                    Some((_, total)) => *total += n,
                    None => out.push((kind.drop_reason(), n)),
                }
            }
        }
        for (name, n) in [
            ("queue_full", self.counts.dropped_queue_full),
            ("wrong_size", self.counts.dropped_wrong_size),
            ("bad_checksum", self.counts.dropped_bad_checksum),
            ("bad_flags", self.counts.dropped_bad_flags),
            ("too_large", self.counts.dropped_too_large),
        ] {
            if n > 0 {
                out.push((name, n));
            }
        }
        out
    }
}

#[cfg(test)]
mod tests;
