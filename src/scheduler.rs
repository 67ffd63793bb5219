//! The release queue: frames held by the injector until their scheduled
//! release time, with a fixed capacity chosen at start-up.
//!
//! Two orders (docs/spec.md §3.4). `Fifo` is a ring: releases leave in the order they
//! were pushed, and a push whose time is earlier than the last one is held
//! until that one (`release = max(own, previous)`), as an ordered transport
//! does. `Reorder` leaves each frame at its own time, ties in ingress order:
//! exactly the order of `(release_ns, ingress_index)`.
//!
//! `Reorder` is a hierarchical timing wheel over the whole `u64` range of
//! nanoseconds, so its cost does not grow with the number of frames held
//! (a binary heap's does, by a cache miss per level once it outgrows the
//! cache). Eleven levels of 64 slots each split a time into 6-bit digits; a
//! frame sits at the level of the highest digit in which its release time
//! differs from the wheel's cursor, in the slot named by that digit. Level 0
//! therefore holds exact times, one per slot, and its slots are kept in
//! ingress order; higher slots are unordered bags that are moved down a level
//! (cascaded) when level 0 runs empty. A frame is moved at most once per
//! level, whatever the depth. A bitmap of occupied slots per level finds the
//! earliest one in a few instructions, and because level 0 always holds the
//! earliest frame, [`ReleaseQueue::next_release_ns`] is one bit scan.
//!
//! The cursor never passes the earliest frame held. A push earlier than the
//! cursor (never the case while time moves forward: the injector pushes at
//! `now + delay` and releases at most up to `now`) gathers the lower levels
//! into one slot and moves the cursor back, a bounded number of list splices.
//!
//! Neither order allocates after construction: the wheel's frames live in a
//! slab whose free slots and slot lists are intrusive `u32` links, and a push
//! onto a full queue hands the item back as [`Full`] so the caller records
//! the fate. The capacity is bounded by [`MAX_CAPACITY`]; a larger one is a
//! [`CapacityError`] that names the memory it would take.

use std::collections::VecDeque;

/// The order a queue releases in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum QueueOrder {
    Fifo,
    Reorder,
}

/// A frame that did not fit: the queue held `capacity` frames already.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Full<T>(pub T);

/// One frame leaving the queue.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Released<T> {
    pub release_ns: u64,
    pub ingress_index: u64,
    pub item: T,
}

/// The largest capacity a queue accepts: 2^24 = 16 777 216 frames.
///
/// That holds 16 s of frames at 1 000 000 frames/s, or 56 s at 300 000 —
/// far beyond any delay a scenario models (the deepest preset holds a few
/// hundred milliseconds) — and it costs about 3.6 GB with the emulator's
/// 192-byte samples, which a lab machine can spare. Beyond it, a typing slip
/// (an extra digit) would silently reserve and touch tens of gigabytes.
pub const MAX_CAPACITY: usize = 1 << 24;

/// Why a queue could not be built: its capacity, from the scenario's
/// `queue_capacity` or the services' `--queue-capacity`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum CapacityError {
    /// A queue must hold at least one frame.
    #[error("queue_capacity (--queue-capacity) must be at least 1 frame")]
    Zero,
    /// More than [`MAX_CAPACITY`] frames.
    #[error(
        "queue_capacity (--queue-capacity) of {capacity} frames would need {} of memory ({bytes_per_frame} bytes a frame); at most {max} frames (2^24, {}) are accepted",
        human_bytes(*.bytes_needed),
        human_bytes(MAX_CAPACITY as u128 * *.bytes_per_frame as u128),
        max = MAX_CAPACITY
    )]
    TooLarge { capacity: usize, bytes_per_frame: usize, bytes_needed: u128 },
}

/// `68.7 GB`, `3.2 MB`: decimal units, as memory is quoted to people.
fn human_bytes(bytes: u128) -> String {
    let units = ["B", "kB", "MB", "GB", "TB", "PB", "EB"];
    let mut value = bytes as f64;
    let mut unit = 0;
    while value >= 1000.0 && unit + 1 < units.len() {
        value /= 1000.0;
        unit += 1;
    }
    if unit == 0 {
        format!("{bytes} B")
    } else {
        format!("{value:.1} {}", units[unit])
    }
}

/// Bits of the release time per wheel level, and slots per level.
const LEVEL_BITS: u32 = 6;
const SLOTS: usize = 1 << LEVEL_BITS;
const SLOT_MASK: u64 = SLOTS as u64 - 1;
/// ⌈64 / 6⌉: the top level holds the last 4 bits.
const LEVELS: usize = 64_usize.div_ceil(LEVEL_BITS as usize);
/// The end of a list (and of the free list); never a slab index, because
/// the capacity is at most [`MAX_CAPACITY`] < `u32::MAX`.
const NIL: u32 = u32::MAX;

/// A frame's place in the wheel; its item lives at the same index of the
/// item slab, which only a push and a pop touch.
#[derive(Debug, Clone, Copy)]
struct Node {
    release_ns: u64,
    ingress_index: u64,
    /// The next frame in the same slot, or the next free node.
    next: u32,
}

#[derive(Debug, Clone)]
struct Level {
    /// Bit `s` set ⇔ slot `s` holds a frame.
    occupied: u64,
    head: [u32; SLOTS],
    tail: [u32; SLOTS],
}

impl Level {
    const EMPTY: Level = Level { occupied: 0, head: [NIL; SLOTS], tail: [NIL; SLOTS] };
}

/// The level at which a frame due at `release_ns` sits while the cursor is
/// at `cursor_ns`: that of the highest 6-bit digit in which they differ.
#[inline]
fn level_for(cursor_ns: u64, release_ns: u64) -> usize {
    let masked = (cursor_ns ^ release_ns) | SLOT_MASK;
    ((63 - masked.leading_zeros()) / LEVEL_BITS) as usize
}

#[inline]
fn digit(t_ns: u64, level: usize) -> usize {
    ((t_ns >> (LEVEL_BITS as usize * level)) & SLOT_MASK) as usize
}

/// The first nanosecond of `slot` at `level`, in the cursor's window.
#[inline]
fn slot_start_ns(cursor_ns: u64, level: usize, slot: usize) -> u64 {
    let shift = LEVEL_BITS as usize * level;
    let window = shift + LEVEL_BITS as usize;
    let above = if window >= 64 { 0 } else { cursor_ns >> window << window };
    above | ((slot as u64) << shift)
}

/// The most frames the early list holds before it is merged into the wheel
/// (see [`Wheel::push`]): it bounds a sorted insertion's walk.
const EARLY_MAX: u32 = 32;

/// The reorder queue: a hierarchical timing wheel over a slab, and a short
/// sorted list of frames earlier than the wheel's cursor.
///
/// Invariants: every frame in the early list is due before `cursor_ns`,
/// and the list is in `(release_ns, ingress_index)` order; every frame in
/// the wheel is due at or after `cursor_ns`; a frame at
/// level `L` agrees with the cursor in every digit above `L` and its digit
/// `L` is its slot, later than the cursor's (at level 0, not earlier); each
/// level-0 slot is in ingress order; level 0 is non-empty whenever a frame
/// is held, so it holds the earliest one.
#[derive(Debug, Clone)]
struct Wheel<T> {
    levels: [Level; LEVELS],
    cursor_ns: u64,
    nodes: Vec<Node>,
    items: Vec<T>,
    free: u32,
    /// Frames held, in the wheel and in the early list.
    len: usize,
    early_head: u32,
    early_tail: u32,
    early_len: u32,
}

impl<T: Copy + Default> Wheel<T> {
    fn new(capacity: usize) -> Self {
        // Every node and item is written here, so the memory is resident
        // before the first frame: a fresh page touched on the hot path would
        // cost a page fault (microseconds, more in a VM) to the frame on it.
        let nodes = (0..capacity)
            .map(|i| Node { release_ns: 0, ingress_index: 0, next: if i + 1 < capacity { i as u32 + 1 } else { NIL } })
            .collect();
        Wheel { levels: [Level::EMPTY; LEVELS], cursor_ns: 0, nodes, items: vec![T::default(); capacity], free: 0, len: 0, early_head: NIL, early_tail: NIL, early_len: 0 }
    }

    #[inline]
    fn next_release_ns(&self) -> Option<u64> {
        if self.early_head != NIL {
            return Some(self.nodes[self.early_head as usize].release_ns);
        }
        (self.len > 0).then(|| (self.cursor_ns & !SLOT_MASK) | self.levels[0].occupied.trailing_zeros() as u64)
    }

    #[inline]
    fn push(&mut self, release_ns: u64, ingress_index: u64, item: T) -> Result<u64, Full<T>> {
        let n = self.free;
        if n == NIL {
            return Err(Full(item));
        }
        let node = &mut self.nodes[n as usize];
        self.free = node.next;
        *node = Node { release_ns, ingress_index, next: NIL };
        self.items[n as usize] = item;
        self.len += 1;
        if self.len == 1 {
            self.cursor_ns = release_ns;
        } else if release_ns < self.cursor_ns {
            // Earlier than every frame in the wheel: a new earliest frame.
            // Moving the cursor back would undo the cascading of the frames
            // near it (a deep queue whose pushes often become the earliest
            // would move its frames up and down again and again), so such
            // frames wait in a short sorted list; only when it is full is
            // it merged into the wheel, once per `EARLY_MAX` frames.
            self.early_insert(n);
            if self.early_len == EARLY_MAX {
                self.merge_early();
            }
            return Ok(release_ns);
        }
        self.place(n);
        Ok(release_ns)
    }

    #[inline]
    fn pop(&mut self) -> Option<Released<T>> {
        if self.len == 0 {
            return None;
        }
        if self.early_head != NIL {
            let n = self.early_head;
            let node = self.nodes[n as usize];
            self.early_head = node.next;
            if node.next == NIL {
                self.early_tail = NIL;
            }
            self.early_len -= 1;
            self.nodes[n as usize].next = self.free;
            self.free = n;
            self.len -= 1;
            return Some(Released { release_ns: node.release_ns, ingress_index: node.ingress_index, item: self.items[n as usize] });
        }
        let level0 = &mut self.levels[0];
        let slot = level0.occupied.trailing_zeros() as usize;
        let n = level0.head[slot];
        let node = self.nodes[n as usize];
        level0.head[slot] = node.next;
        if node.next == NIL {
            level0.tail[slot] = NIL;
            level0.occupied &= !(1 << slot);
        }
        self.nodes[n as usize].next = self.free;
        self.free = n;
        self.len -= 1;
        // Every frame left is due at or after this one.
        self.cursor_ns = node.release_ns;
        if self.levels[0].occupied == 0 && self.len > 0 {
            debug_assert_eq!(self.early_len, 0);
            self.refill();
        }
        Some(Released { release_ns: node.release_ns, ingress_index: node.ingress_index, item: self.items[n as usize] })
    }

    /// Puts node `n` into its slot relative to the cursor.
    #[inline]
    fn place(&mut self, n: u32) {
        let Node { release_ns, ingress_index, .. } = self.nodes[n as usize];
        let level = level_for(self.cursor_ns, release_ns);
        let slot = digit(release_ns, level);
        let lv = &mut self.levels[level];
        let head = lv.head[slot];
        if head == NIL {
            self.nodes[n as usize].next = NIL;
            lv.head[slot] = n;
            lv.tail[slot] = n;
            lv.occupied |= 1 << slot;
            return;
        }
        if level > 0 {
            // A bag: the front is cheapest (it touches no other node).
            self.nodes[n as usize].next = head;
            lv.head[slot] = n;
            return;
        }
        // Level 0: one release time per slot, kept in ingress order. Frames
        // come in ingress order (append) or, cascaded from a bag, often in
        // reverse (prepend); anything else walks the ties.
        let tail = lv.tail[slot];
        if self.nodes[tail as usize].ingress_index <= ingress_index {
            self.nodes[tail as usize].next = n;
            self.nodes[n as usize].next = NIL;
            lv.tail[slot] = n;
        } else if ingress_index < self.nodes[head as usize].ingress_index {
            self.nodes[n as usize].next = head;
            lv.head[slot] = n;
        } else {
            let mut prev = head;
            loop {
                let next = self.nodes[prev as usize].next;
                if self.nodes[next as usize].ingress_index > ingress_index {
                    self.nodes[n as usize].next = next;
                    self.nodes[prev as usize].next = n;
                    break;
                }
                prev = next;
            }
        }
    }

    /// Level 0 ran empty with frames held: moves the earliest occupied slot
    /// of the lowest occupied level down, until level 0 holds a frame. The
    /// cursor moves to that slot's first nanosecond, not past any frame.
    #[cold]
    fn refill(&mut self) {
        while self.levels[0].occupied == 0 {
            let level = (1..LEVELS).find(|&l| self.levels[l].occupied != 0).expect("a held frame is in some level");
            let lv = &mut self.levels[level];
            let slot = lv.occupied.trailing_zeros() as usize;
            let mut n = lv.head[slot];
            let single = n == lv.tail[slot];
            lv.head[slot] = NIL;
            lv.tail[slot] = NIL;
            lv.occupied &= !(1 << slot);
            // A lone frame is the earliest one: the cursor goes straight to
            // it, and it to level 0, rather than down one level at a time.
            self.cursor_ns = if single { self.nodes[n as usize].release_ns } else { slot_start_ns(self.cursor_ns, level, slot) };
            while n != NIL {
                let next = self.nodes[n as usize].next;
                self.place(n);
                n = next;
            }
        }
    }

    /// Puts node `n` into the early list, in `(release_ns, ingress_index)`
    /// order: appended or prepended when it belongs at an end (the usual
    /// case), else after a walk of at most `EARLY_MAX` frames.
    fn early_insert(&mut self, n: u32) {
        let key = |q: &Self, m: u32| (q.nodes[m as usize].release_ns, q.nodes[m as usize].ingress_index);
        let k = key(self, n);
        self.early_len += 1;
        if self.early_head == NIL {
            self.nodes[n as usize].next = NIL;
            self.early_head = n;
            self.early_tail = n;
        } else if key(self, self.early_tail) <= k {
            self.nodes[n as usize].next = NIL;
            self.nodes[self.early_tail as usize].next = n;
            self.early_tail = n;
        } else if k < key(self, self.early_head) {
            self.nodes[n as usize].next = self.early_head;
            self.early_head = n;
        } else {
            let mut prev = self.early_head;
            loop {
                let next = self.nodes[prev as usize].next;
                if key(self, next) > k {
                    self.nodes[n as usize].next = next;
                    self.nodes[prev as usize].next = n;
                    break;
                }
                prev = next;
            }
        }
    }

    /// Moves the early list into the wheel: the cursor goes back to its
    /// first frame, and every frame is placed relative to it.
    #[cold]
    fn merge_early(&mut self) {
        let mut n = self.early_head;
        self.rewind(self.nodes[n as usize].release_ns);
        (self.early_head, self.early_tail, self.early_len) = (NIL, NIL, 0);
        while n != NIL {
            let next = self.nodes[n as usize].next;
            self.place(n);
            n = next;
        }
    }

    /// Moves the cursor back to `release_ns`, earlier than it and so than
    /// every frame held (a new earliest frame). Frames below the highest
    /// digit in which the two times differ all share the cursor's digit
    /// there, so they become one bag in that slot: list splices, one per
    /// occupied slot, no frame is moved on its own.
    #[cold]
    fn rewind(&mut self, release_ns: u64) {
        let top = level_for(self.cursor_ns, release_ns);
        if top > 0 {
            let (mut head, mut tail) = (NIL, NIL);
            for level in 0..top {
                let lv = &mut self.levels[level];
                let mut occupied = lv.occupied;
                lv.occupied = 0;
                while occupied != 0 {
                    let slot = occupied.trailing_zeros() as usize;
                    occupied &= occupied - 1;
                    let (h, t) = (lv.head[slot], lv.tail[slot]);
                    lv.head[slot] = NIL;
                    lv.tail[slot] = NIL;
                    if head == NIL {
                        tail = t;
                    } else {
                        self.nodes[t as usize].next = head;
                    }
                    head = h;
                }
            }
            if head != NIL {
                // The cursor is later than `release_ns` in digit `top`, so
                // the bag is still ahead of the new cursor; the slot was empty
                // because frames at level `top` are later than the cursor there.
                let slot = digit(self.cursor_ns, top);
                let lv = &mut self.levels[top];
                debug_assert_eq!(lv.head[slot], NIL);
                lv.head[slot] = head;
                lv.tail[slot] = tail;
                lv.occupied |= 1 << slot;
            }
        }
        self.cursor_ns = release_ns;
    }
}

#[derive(Debug, Clone)]
enum Inner<T> {
    Fifo { ring: VecDeque<Released<T>>, last_release_ns: u64 },
    Reorder(Box<Wheel<T>>),
}

/// A fixed-capacity release queue.
#[derive(Debug, Clone)]
pub struct ReleaseQueue<T> {
    inner: Inner<T>,
    capacity: usize,
}

impl<T: Copy + Default> ReleaseQueue<T> {
    /// The memory one frame of capacity takes in a queue of this order.
    pub const fn bytes_per_frame(order: QueueOrder) -> usize {
        match order {
            QueueOrder::Fifo => size_of::<Released<T>>(),
            QueueOrder::Reorder => size_of::<Node>() + size_of::<T>(),
        }
    }

    /// Whether a queue of `capacity` frames may be built, without building
    /// it: the error [`try_new`](Self::try_new) would give.
    pub fn check_capacity(order: QueueOrder, capacity: usize) -> Result<(), CapacityError> {
        if capacity == 0 {
            return Err(CapacityError::Zero);
        }
        if capacity > MAX_CAPACITY {
            let bytes_per_frame = Self::bytes_per_frame(order);
            return Err(CapacityError::TooLarge { capacity, bytes_per_frame, bytes_needed: capacity as u128 * bytes_per_frame as u128 });
        }
        Ok(())
    }

    /// A queue holding at most `capacity` frames (1..=[`MAX_CAPACITY`]); all
    /// memory is allocated and written here.
    pub fn try_new(order: QueueOrder, capacity: usize) -> Result<Self, CapacityError> {
        Self::check_capacity(order, capacity)?;
        let inner = match order {
            QueueOrder::Fifo => {
                let mut ring = VecDeque::with_capacity(capacity);
                ring.resize(capacity, Released { release_ns: 0, ingress_index: 0, item: T::default() });
                ring.clear();
                Inner::Fifo { ring, last_release_ns: 0 }
            }
            QueueOrder::Reorder => Inner::Reorder(Box::new(Wheel::new(capacity))),
        };
        Ok(ReleaseQueue { inner, capacity })
    }

    /// [`ReleaseQueue::try_new`] for a capacity already validated (a
    /// constant, or checked at start-up): an invalid one is a broken
    /// invariant and panics with the error's message.
    pub fn new(order: QueueOrder, capacity: usize) -> Self {
        Self::try_new(order, capacity).unwrap_or_else(|e| panic!("{e}"))
    }

    pub fn order(&self) -> QueueOrder {
        match self.inner {
            Inner::Fifo { .. } => QueueOrder::Fifo,
            Inner::Reorder(_) => QueueOrder::Reorder,
        }
    }

    pub fn capacity(&self) -> usize {
        self.capacity
    }

    pub fn len(&self) -> usize {
        match &self.inner {
            Inner::Fifo { ring, .. } => ring.len(),
            Inner::Reorder(wheel) => wheel.len,
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Queues `item` for `release_ns` and returns the release time it will
    /// actually get (later than asked only in a `Fifo` queue, behind an
    /// earlier frame).
    #[inline]
    pub fn push(&mut self, release_ns: u64, ingress_index: u64, item: T) -> Result<u64, Full<T>> {
        match &mut self.inner {
            Inner::Fifo { ring, last_release_ns } => {
                if ring.len() == self.capacity {
                    return Err(Full(item));
                }
                let release_ns = release_ns.max(*last_release_ns);
                *last_release_ns = release_ns;
                ring.push_back(Released { release_ns, ingress_index, item });
                Ok(release_ns)
            }
            Inner::Reorder(wheel) => wheel.push(release_ns, ingress_index, item),
        }
    }

    /// The earliest scheduled release, if any frame is held; constant time.
    #[inline]
    pub fn next_release_ns(&self) -> Option<u64> {
        match &self.inner {
            Inner::Fifo { ring, .. } => ring.front().map(|r| r.release_ns),
            Inner::Reorder(wheel) => wheel.next_release_ns(),
        }
    }

    /// Takes the next frame whose release time is `≤ now_ns`.
    #[inline]
    pub fn pop_due(&mut self, now_ns: u64) -> Option<Released<T>> {
        match self.next_release_ns() {
            Some(t) if t <= now_ns => self.pop(),
            _ => None,
        }
    }

    /// Takes the next frame regardless of its time (shutdown, draining).
    #[inline]
    pub fn pop(&mut self) -> Option<Released<T>> {
        match &mut self.inner {
            Inner::Fifo { ring, .. } => ring.pop_front(),
            Inner::Reorder(wheel) => wheel.pop(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reorder_releases_by_time_then_ingress() {
        let mut q = ReleaseQueue::<u32>::new(QueueOrder::Reorder, 8);
        for (i, t) in [50u64, 10, 30, 10, 20].iter().enumerate() {
            assert_eq!(q.push(*t, i as u64, i as u32 * 100), Ok(*t));
        }
        assert_eq!(q.next_release_ns(), Some(10));
        assert_eq!(q.pop_due(9), None);
        let order: Vec<_> = std::iter::from_fn(|| q.pop_due(100)).map(|r| (r.release_ns, r.ingress_index, r.item)).collect();
        assert_eq!(order, vec![(10, 1, 100), (10, 3, 300), (20, 4, 400), (30, 2, 200), (50, 0, 0)]);
        assert!(q.is_empty());
    }

    #[test]
    fn fifo_holds_a_frame_behind_the_previous_one() {
        let mut q = ReleaseQueue::<()>::new(QueueOrder::Fifo, 4);
        assert_eq!(q.push(100, 0, ()), Ok(100));
        assert_eq!(q.push(40, 1, ()), Ok(100));
        assert_eq!(q.push(150, 2, ()), Ok(150));
        let got: Vec<_> = std::iter::from_fn(|| q.pop_due(1000)).map(|r| (r.release_ns, r.ingress_index)).collect();
        assert_eq!(got, vec![(100, 0), (100, 1), (150, 2)]);
    }

    #[test]
    fn full_queue_hands_the_item_back_and_recovers() {
        for order in [QueueOrder::Fifo, QueueOrder::Reorder] {
            let mut q = ReleaseQueue::<u8>::new(order, 2);
            q.push(1, 0, 1).unwrap();
            q.push(2, 1, 2).unwrap();
            assert_eq!(q.push(3, 2, 3), Err(Full(3)), "{order:?}");
            assert_eq!(q.pop().map(|r| r.item), Some(1));
            assert_eq!(q.push(3, 2, 3), Ok(3));
            assert_eq!(q.len(), 2);
        }
    }

    #[test]
    fn slab_slots_are_reused_without_mixing_items() {
        let mut q = ReleaseQueue::<u64>::new(QueueOrder::Reorder, 3);
        let mut next = 0u64;
        let mut out = Vec::new();
        for round in 0..100u64 {
            while q.len() < 3 {
                // Pseudo-random release times; the item records its ingress index.
                let t = (next * 7919 + round) % 101;
                q.push(t, next, next).unwrap();
                next += 1;
            }
            let r = q.pop().unwrap();
            assert_eq!(r.item, r.ingress_index);
            out.push(r);
        }
        assert_eq!(out.len(), 100);
    }

    #[test]
    fn a_capacity_out_of_range_is_an_error_naming_the_field_and_the_memory() {
        assert_eq!(ReleaseQueue::<u8>::try_new(QueueOrder::Fifo, 0).unwrap_err(), CapacityError::Zero);
        for capacity in [MAX_CAPACITY + 1, u32::MAX as usize, (1usize << 32) + 1, usize::MAX] {
            for order in [QueueOrder::Fifo, QueueOrder::Reorder] {
                let e = ReleaseQueue::<crate::sample::FrameSample>::try_new(order, capacity).unwrap_err();
                let per_frame = ReleaseQueue::<crate::sample::FrameSample>::bytes_per_frame(order);
                assert_eq!(e, CapacityError::TooLarge { capacity, bytes_per_frame: per_frame, bytes_needed: capacity as u128 * per_frame as u128 });
                let text = e.to_string();
                for part in ["queue_capacity", "--queue-capacity", &capacity.to_string(), "16777216", "bytes a frame"] {
                    assert!(text.contains(part), "{part:?} missing from: {text}");
                }
            }
        }
        // 4 294 967 295 frames of the emulator's 192-byte samples in a wheel
        // (24-byte node each): 927.7 GB.
        let e = ReleaseQueue::<crate::sample::FrameSample>::try_new(QueueOrder::Reorder, u32::MAX as usize).unwrap_err();
        assert!(e.to_string().contains("would need 927.7 GB of memory (216 bytes a frame)"), "{e}");
    }

    #[test]
    fn extreme_times_and_a_push_before_the_cursor() {
        let mut q = ReleaseQueue::<u8>::new(QueueOrder::Reorder, 8);
        q.push(u64::MAX, 0, 1).unwrap();
        q.push(0, 1, 2).unwrap();
        q.push(u64::MAX, 2, 3).unwrap();
        q.push(1 << 40, 3, 4).unwrap();
        assert_eq!(q.pop().map(|r| r.item), Some(2));
        // The cursor went up to 2^40's slot; this one is earlier.
        assert_eq!(q.next_release_ns(), Some(1 << 40));
        q.push(70, 4, 5).unwrap();
        assert_eq!(q.next_release_ns(), Some(70));
        assert_eq!(q.pop_due(69), None);
        let got: Vec<_> = std::iter::from_fn(|| q.pop_due(u64::MAX)).map(|r| (r.release_ns, r.item)).collect();
        assert_eq!(got, vec![(70, 5), (1 << 40, 4), (u64::MAX, 1), (u64::MAX, 3)]);
    }
}
