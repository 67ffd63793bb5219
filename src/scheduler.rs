//! The release queue: frames held by the injector until their scheduled
//! release time, with a fixed capacity chosen at start-up.
//!
//! Two orders (docs/spec.md §3.4). `Fifo` is a ring: releases leave in the order they
//! were pushed, and a push whose time is earlier than the last one is held
//! until that one (`release = max(own, previous)`), as an ordered transport
//! does. `Reorder` leaves each frame at its own time, ties in ingress order:
//! exactly the order of `(release_ns, ingress_index)`.
//!
//! `Reorder` keeps its frames in a slab (node and item at one index; links
//! are `u32` indices; items on cache-line boundaries when a whole number of
//! lines, as the emulator's 192-byte sample, and the large arrays advised
//! onto huge pages, so that a deep queue's pops, scattered over the slab,
//! neither straddle lines nor miss the TLB) and each frame in one of two
//! structures, both in
//! exact `(release_ns, ingress_index)` order; the earliest frame is the
//! earlier of their two first ones, so which one holds a frame changes its
//! cost, never the order.
//!
//! - The **calendar** holds nearly every frame: one level of `2^k` buckets
//!   (`2^k` twice the power of two at or above the capacity), each `2^s` ns
//!   wide.
//!   A push puts a frame at the front of its bucket's list (a bag); a pop
//!   takes the head of the first bucket, which is kept in exact order (a
//!   bag is sorted when it becomes the first: a few frames), and finds the
//!   next occupied bucket in a two-level bitmap. The bucket width is chosen
//!   whenever the calendar runs empty, from how far ahead of the earliest
//!   frame the pushes reached since the last choice: the window spans the
//!   stream's delay spread (rate × delay frames over `2^k` buckets), so a
//!   bucket holds about one frame at any depth, and a frame is moved once
//!   in and once out, whatever the depth. Pops prefetch the node and item
//!   of the first frame of each bucket up to 32 ahead, and of the second of
//!   those up to 12 ahead (its place is known once the first is in cache):
//!   at depth those lines were last touched at the frame's push, long out
//!   of cache. A pop prefetches the next frame's item once more, from
//!   whichever cache still holds it.
//! - A hierarchical **timing wheel** takes what the calendar does not: a
//!   frame outside its window (the first frames of a stream, before the
//!   width fits; a frame due before everything held; an outlier far ahead)
//!   or deeper than `WALK_MAX` (8) frames into the first bucket. Eleven levels of 64
//!   slots each split a time into 6-bit digits; a frame sits at the level of
//!   the highest digit in which its release time differs from the wheel's
//!   cursor, in the slot named by that digit. Level 0 therefore holds exact
//!   times, and higher slots are bags moved down a level (cascaded) when
//!   level 0 runs empty; a frame is moved at most once per level. A frame
//!   earlier than the cursor waits in a short sorted list (at most 32) that
//!   is merged into the wheel when full. The wheel's frames move into the
//!   calendar, a few per push, once its window covers them.
//!
//! A push walks at most 8 frames of the first bucket (or 32 of the wheel's
//! early list); a pop scans bitmap words and sorts the next bucket; the
//! wheel's cascades move a frame at most once per level.
//!
//! A pop can leave the item in place ([`ReleaseQueue::pop_ref`],
//! [`ReleaseQueue::pop_due_ref`]): its slot is free again but not written
//! before the next push, which the borrow holds off, so a caller that copies
//! the item on (the emulator, into the publisher's loan) copies it once.
//!
//! Neither order allocates after construction: the reorder queue's frames
//! live in a slab whose free slots and lists are intrusive `u32` links, and a push
//! onto a full queue hands the item back as [`Full`] so the caller records
//! the fate. The capacity is bounded by [`MAX_CAPACITY`]; a larger one is a
//! [`CapacityError`] that names the memory it would take.

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

/// The end of a list (and of the free list); never a slab index, because
/// the capacity is at most [`MAX_CAPACITY`] < `u32::MAX`.
const NIL: u32 = u32::MAX;

/// A frame's place in the queue; its item lives at the same index of the
/// item slab, which only a push and a pop touch.
#[derive(Debug, Clone, Copy)]
struct Node {
    release_ns: u64,
    ingress_index: u64,
    /// The next frame in the same list, or the next free node.
    next: u32,
}

impl Node {
    #[inline]
    fn key(&self) -> (u64, u64) {
        (self.release_ns, self.ingress_index)
    }
}

/// Issues a prefetch of the cache lines of `*p`: a hint, never a fault.
#[inline(always)]
fn prefetch<X>(p: *const X) {
    prefetch_hint::<{ HINT_KEEP }, X>(p)
}

/// [`prefetch`] for data read once (an item at its pop): brought close to
/// the core without displacing what stays in use from the outer caches.
#[inline(always)]
fn prefetch_once<X>(p: *const X) {
    prefetch_hint::<{ HINT_ONCE }, X>(p)
}

#[cfg(target_arch = "x86_64")]
const HINT_KEEP: i32 = core::arch::x86_64::_MM_HINT_T0;
#[cfg(target_arch = "x86_64")]
const HINT_ONCE: i32 = core::arch::x86_64::_MM_HINT_NTA;
#[cfg(not(target_arch = "x86_64"))]
const HINT_KEEP: i32 = 0;
#[cfg(not(target_arch = "x86_64"))]
const HINT_ONCE: i32 = 0;

#[inline(always)]
fn prefetch_hint<const HINT: i32, X>(p: *const X) {
    #[cfg(target_arch = "x86_64")]
    {
        let bytes = p.cast::<i8>();
        let mut off = 0;
        while off < size_of::<X>() {
            // SAFETY: prefetching has no effect on memory and cannot fault,
            // whatever the address; SSE is part of the x86_64 baseline.
            unsafe { core::arch::x86_64::_mm_prefetch::<HINT>(bytes.wrapping_add(off)) };
            off += 64;
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = p;
}

/// A vector of `len` copies of `value`, every page written here: a fresh
/// page touched on the hot path would cost a page fault (microseconds, more
/// in a VM) to the frame on it. On Linux a region of 2 MiB or more is first
/// advised to be backed by huge pages: a deep queue's frames are read in
/// release order, i.e. scattered over the whole region, and with 4 KiB
/// pages nearly every pop would also miss the TLB (a page walk) at depth.
/// The advice is a hint: where huge pages are off, nothing changes but the
/// TLB misses.
fn resident_vec<X: Clone>(len: usize, value: X) -> Vec<X> {
    let mut v: Vec<X> = Vec::with_capacity(len);
    advise_huge_pages(v.as_mut_ptr().cast::<u8>(), len * size_of::<X>());
    v.resize(len, value);
    v
}

#[cfg(target_os = "linux")]
fn advise_huge_pages(start: *mut u8, bytes: usize) {
    const HUGE: usize = 2 << 20;
    let from = (start as usize).next_multiple_of(HUGE);
    let to = (start as usize + bytes) / HUGE * HUGE;
    if to > from {
        // SAFETY: the range lies inside an allocation this function's caller
        // owns and has not yet written; the advice changes how its pages are
        // backed, never their contents, and a refusal is harmless.
        unsafe { libc::madvise(from as *mut libc::c_void, to - from, libc::MADV_HUGEPAGE) };
    }
}

#[cfg(not(target_os = "linux"))]
fn advise_huge_pages(_start: *mut u8, _bytes: usize) {}

/// An item on cache-line boundaries: the emulator's 192-byte sample then
/// spans 3 lines, not 4 (a large allocation starts 16 bytes past a page).
#[derive(Debug, Clone, Copy, Default)]
#[repr(C, align(64))]
struct Lined<T>(T);

/// The reorder queue's items, at their frames' slab indices: on cache-line
/// boundaries when their size is a multiple of a line, packed otherwise
/// (an 8-byte item or a `()` would waste most of a line). Only one of the
/// two vectors is used, chosen at compile time.
#[derive(Debug, Clone)]
struct Items<T> {
    packed: Vec<T>,
    lined: Vec<Lined<T>>,
}

impl<T: Copy + Default> Items<T> {
    const LINED: bool = size_of::<T>() >= 64 && size_of::<T>() % 64 == 0;

    fn new(capacity: usize) -> Self {
        if Self::LINED {
            Items { packed: Vec::new(), lined: resident_vec(capacity, Lined(T::default())) }
        } else {
            Items { packed: resident_vec(capacity, T::default()), lined: Vec::new() }
        }
    }

    /// The memory an item takes in the store.
    const fn bytes() -> usize {
        if Self::LINED {
            size_of::<Lined<T>>()
        } else {
            size_of::<T>()
        }
    }

    #[inline(always)]
    fn get(&self, n: u32) -> &T {
        if Self::LINED {
            &self.lined[n as usize].0
        } else {
            &self.packed[n as usize]
        }
    }

    #[inline(always)]
    fn set(&mut self, n: u32, item: T) {
        if Self::LINED {
            self.lined[n as usize].0 = item;
        } else {
            self.packed[n as usize] = item;
        }
    }
}

// ---------------------------------------------------------------------------
// The calendar: where nearly every frame lives.

/// The most frames a push walks past in a calendar bucket before it leaves
/// the frame to the wheel: it bounds a push's cost whatever the times.
const WALK_MAX: u32 = 8;
/// How far ahead of the earliest frame, in buckets, pops prefetch the
/// first frame of a bucket, and the second (whose place is known only once
/// the first is in cache).
const AHEAD_BUCKETS: u64 = 32;
const NEAR_BUCKETS: u64 = 12;
/// Frames moved from the wheel into the calendar at each push while the
/// wheel holds frames the calendar's window covers.
const MIGRATE_PER_PUSH: usize = 2;

/// One level of `2^bits` buckets of `2^shift` ns each: a frame due at `t`
/// is in bucket `t >> shift` (absolute), stored at index `bucket & mask`.
/// The first bucket's list is in `(release_ns, ingress_index)` order; any
/// other is a bag, pushed at its front and put in order when it becomes the
/// first, so a push touches no other frame.
///
/// Invariants: every frame's bucket is in `first..=hi`, and `hi - first ≤
/// mask`, so the circular indices of held frames never collide and buckets
/// in index order from `first` are in time order; `first` holds the
/// earliest frame, whose release is `first_ns`. The bucket width is chosen
/// only when the calendar is empty, from how far ahead of the earliest frame
/// pushes reached on average since it was last chosen, so a window spans
/// the delay spread of the stream and a bucket holds a few frames.
#[derive(Debug, Clone)]
struct Calendar {
    heads: Vec<u32>,
    /// Bit per bucket: occupied.
    words: Vec<u64>,
    /// Bit per word of `words`: non-zero.
    summary: Vec<u64>,
    bits: u32,
    mask: u64,
    shift: u32,
    first: u64,
    first_ns: u64,
    hi: u64,
    len: usize,
    /// Sum and count of how far ahead of the earliest frame pushes reached
    /// since the width was chosen.
    reach_sum_ns: u64,
    reach_count: u64,
    /// Pushes refused for a deep bucket, and taken, since then; too many
    /// refusals close the calendar to pushes until it drains and starts over.
    refusals: u64,
    taken: u64,
    closed: bool,
    /// The prefetch cursors: the last buckets whose first frame (`ahead`)
    /// and second frame (`near`) were prefetched.
    ahead: u64,
    near: u64,
}

/// The number of calendar buckets for a capacity: twice the power of two
/// at or above it (at least 64). The window spans twice the pushes' mean
/// reach, which is about the span of the frames held (a push is mostly the
/// latest frame), so a full queue fills at most half the buckets: about one
/// frame a bucket, whose place is known from the bucket's head alone and
/// can be prefetched well before it is taken. The heads cost at most 16
/// bytes a frame of capacity (4 bytes a bucket).
fn calendar_bits(capacity: usize) -> u32 {
    (capacity.max(1).next_power_of_two().trailing_zeros() + 1).max(6)
}

/// The next set bit at or after `start` in `bits`, circularly.
#[inline]
fn next_set(bits: &[u64], start: usize) -> usize {
    let (w, b) = (start >> 6, start & 63);
    let here = bits[w] & (!0u64 << b);
    if here != 0 {
        return w << 6 | here.trailing_zeros() as usize;
    }
    // Round the ring once; the last word looked at is `w` again, for the
    // bits below `b`.
    let n = bits.len();
    let mut i = w;
    for _ in 0..n {
        i = if i + 1 == n { 0 } else { i + 1 };
        if bits[i] != 0 {
            return i << 6 | bits[i].trailing_zeros() as usize;
        }
    }
    unreachable!("next_set on an empty bitmap")
}

impl Calendar {
    fn new(capacity: usize) -> Self {
        let bits = calendar_bits(capacity);
        let buckets = 1usize << bits;
        let words = buckets / 64;
        Calendar {
            heads: resident_vec(buckets, NIL),
            words: vec![0; words],
            summary: vec![0; words.div_ceil(64)],
            bits,
            mask: buckets as u64 - 1,
            // Until a stream has shown its spread: a window of about 1 ms.
            shift: 20u32.saturating_sub(bits),
            first: 0,
            first_ns: 0,
            hi: 0,
            len: 0,
            reach_sum_ns: 0,
            reach_count: 0,
            refusals: 0,
            taken: 0,
            closed: false,
            ahead: 0,
            near: 0,
        }
    }

    #[inline]
    fn head(&self) -> u32 {
        self.heads[(self.first & self.mask) as usize]
    }

    #[inline]
    fn mark(&mut self, idx: usize) {
        let w = idx >> 6;
        if self.words[w] == 0 {
            self.summary[w >> 6] |= 1 << (w & 63);
        }
        self.words[w] |= 1 << (idx & 63);
    }

    #[inline]
    fn unmark(&mut self, idx: usize) {
        let w = idx >> 6;
        self.words[w] &= !(1 << (idx & 63));
        if self.words[w] == 0 {
            self.summary[w >> 6] &= !(1 << (w & 63));
        }
    }

    /// The first occupied bucket at or after `from`; one must be within
    /// `from..from + 2^bits`.
    #[inline]
    fn next_occupied(&self, from: u64) -> u64 {
        let i = (from & self.mask) as usize;
        let (w, b) = (i >> 6, i & 63);
        let here = self.words[w] & (!0u64 << b);
        let j = if here != 0 {
            w << 6 | here.trailing_zeros() as usize
        } else {
            let n = self.words.len();
            let v = next_set(&self.summary, if w + 1 == n { 0 } else { w + 1 });
            v << 6 | self.words[v].trailing_zeros() as usize
        };
        from + ((j as u64).wrapping_sub(i as u64) & self.mask)
    }

    /// An empty calendar starts over at `release_ns`, with buckets as wide
    /// as the pushes since the last start ask: the window spans twice their
    /// mean reach (rounded up to a power of two). Not their largest reach:
    /// a delay law's tail (the largest of N exponential delays is ln N
    /// means) would widen every bucket for a few frames, which the wheel
    /// holds as well until the window reaches them.
    fn rebase(&mut self, release_ns: u64) {
        if self.reach_count > 0 {
            let want_ns = (self.reach_sum_ns / self.reach_count).saturating_mul(2);
            self.shift = 64 - (want_ns >> self.bits).leading_zeros();
        }
        (self.reach_sum_ns, self.reach_count, self.refusals, self.taken, self.closed) = (0, 0, 0, 0, false);
        let a = release_ns >> self.shift;
        (self.first, self.hi, self.ahead, self.near) = (a, a, a, a);
    }

    /// Puts node `n` into its bucket; `false` (nothing changed) when it
    /// falls outside the window or deeper into a bucket than [`WALK_MAX`],
    /// or the calendar is closed.
    #[inline]
    fn insert(&mut self, nodes: &mut [Node], n: u32) -> bool {
        let key = nodes[n as usize].key();
        if self.len == 0 {
            self.rebase(key.0);
        } else {
            if key.0 > self.first_ns {
                self.reach_sum_ns = self.reach_sum_ns.saturating_add(key.0 - self.first_ns);
                self.reach_count += 1;
            }
            if self.closed {
                return false;
            }
        }
        let a = key.0 >> self.shift;
        let fits = if a < self.first { self.hi - a <= self.mask } else { a - self.first <= self.mask };
        if !fits {
            self.refuse();
            return false;
        }
        let idx = (a & self.mask) as usize;
        let head = self.heads[idx];
        if a != self.first || self.len == 0 || head == NIL || key < nodes[head as usize].key() {
            // Any bucket but the first is a bag: the front touches no other
            // frame (it is put in order when it becomes the first).
            nodes[n as usize].next = head;
            self.heads[idx] = n;
            if head == NIL {
                self.mark(idx);
            }
        } else {
            let mut prev = head;
            let mut walked = 0;
            loop {
                let next = nodes[prev as usize].next;
                if next == NIL || nodes[next as usize].key() > key {
                    break;
                }
                walked += 1;
                if walked == WALK_MAX {
                    self.refuse();
                    return false;
                }
                prev = next;
            }
            nodes[n as usize].next = nodes[prev as usize].next;
            nodes[prev as usize].next = n;
        }
        self.len += 1;
        self.taken += 1;
        if self.len == 1 || a <= self.first {
            self.first = a;
            self.first_ns = nodes[self.heads[idx] as usize].release_ns;
        }
        self.hi = self.hi.max(a);
        true
    }

    /// A push refused: outside the window (buckets too narrow for the
    /// stream's spread; the width chosen from its first frames, or its
    /// delays grew) or deep in the first bucket (too wide: its delays
    /// shrank). Past one refusal in 16 pushes, the calendar takes no more
    /// until it drains, and then starts over with a width from the pushes
    /// seen meanwhile.
    #[cold]
    fn refuse(&mut self) {
        self.refusals += 1;
        if self.refusals > 64 && self.refusals * 16 > self.taken {
            self.closed = true;
        }
    }

    /// Takes the earliest frame out (the calendar holds one).
    #[inline]
    fn remove_first(&mut self, nodes: &mut [Node]) -> u32 {
        let idx = (self.first & self.mask) as usize;
        let n = self.heads[idx];
        let next = nodes[n as usize].next;
        self.heads[idx] = next;
        self.len -= 1;
        if next == NIL {
            self.unmark(idx);
            if self.len > 0 {
                self.first = self.next_occupied(self.first + 1);
                self.sort_first(nodes);
            }
        }
        if self.len > 0 {
            self.first_ns = nodes[self.head() as usize].release_ns;
        }
        n
    }

    /// Puts the first bucket, a bag until now, in `(release_ns,
    /// ingress_index)` order: an insertion sort that takes the bag from its
    /// front, i.e. latest push first, so frames pushed in order (the usual
    /// case) each go to the front at once. A few frames, as the width is
    /// chosen; quadratic only in a bucket that gathered many frames in mixed
    /// order.
    #[inline]
    fn sort_first(&mut self, nodes: &mut [Node]) {
        let idx = (self.first & self.mask) as usize;
        let mut n = self.heads[idx];
        let mut sorted = NIL;
        while n != NIL {
            let next = nodes[n as usize].next;
            let key = nodes[n as usize].key();
            if sorted == NIL || key < nodes[sorted as usize].key() {
                nodes[n as usize].next = sorted;
                sorted = n;
            } else {
                let mut prev = sorted;
                loop {
                    let after = nodes[prev as usize].next;
                    if after == NIL || nodes[after as usize].key() > key {
                        break;
                    }
                    prev = after;
                }
                nodes[n as usize].next = nodes[prev as usize].next;
                nodes[prev as usize].next = n;
            }
            n = next;
        }
        self.heads[idx] = sorted;
    }

    /// The next occupied bucket after `cursor` (or after the first, if
    /// the cursor is behind it) within `dist` buckets of the first and not
    /// past `hi`.
    #[inline]
    fn next_within(&self, cursor: u64, dist: u64) -> Option<u64> {
        let from = cursor.max(self.first).saturating_add(1);
        let end = self.hi.min(self.first.saturating_add(dist));
        if self.len == 0 || from > end {
            return None;
        }
        let a = self.next_occupied(from);
        (a <= end).then_some(a)
    }
}

// ---------------------------------------------------------------------------
// The wheel: frames outside the calendar's window.

/// Bits of the release time per wheel level, and slots per level.
const LEVEL_BITS: u32 = 6;
const SLOTS: usize = 1 << LEVEL_BITS;
const SLOT_MASK: u64 = SLOTS as u64 - 1;
/// ⌈64 / 6⌉: the top level holds the last 4 bits.
const LEVELS: usize = 64_usize.div_ceil(LEVEL_BITS as usize);

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
/// (see [`Wheel::insert`]): it bounds a sorted insertion's walk.
const EARLY_MAX: u32 = 32;

/// A hierarchical timing wheel over the slab's nodes, and a short sorted
/// list of frames earlier than the wheel's cursor.
///
/// Invariants: every frame in the early list is due before `cursor_ns`,
/// and the list is in `(release_ns, ingress_index)` order; every frame in
/// the wheel is due at or after `cursor_ns`; a frame at
/// level `L` agrees with the cursor in every digit above `L` and its digit
/// `L` is its slot, later than the cursor's (at level 0, not earlier); each
/// level-0 slot is in ingress order; level 0 is non-empty whenever a frame
/// is held outside the early list, so it holds the earliest one there.
#[derive(Debug, Clone)]
struct Wheel {
    levels: [Level; LEVELS],
    cursor_ns: u64,
    /// Frames held, in the wheel and in the early list.
    len: usize,
    early_head: u32,
    early_tail: u32,
    early_len: u32,
}

impl Wheel {
    fn new() -> Self {
        Wheel { levels: [Level::EMPTY; LEVELS], cursor_ns: 0, len: 0, early_head: NIL, early_tail: NIL, early_len: 0 }
    }

    /// The earliest frame (the wheel holds one).
    #[inline]
    fn first(&self) -> u32 {
        if self.early_head != NIL {
            return self.early_head;
        }
        self.levels[0].head[self.levels[0].occupied.trailing_zeros() as usize]
    }

    #[inline]
    fn next_release_ns(&self, nodes: &[Node]) -> u64 {
        if self.early_head != NIL {
            return nodes[self.early_head as usize].release_ns;
        }
        (self.cursor_ns & !SLOT_MASK) | self.levels[0].occupied.trailing_zeros() as u64
    }

    /// Holds node `n`, whose time and ingress index are set.
    fn insert(&mut self, nodes: &mut [Node], n: u32) {
        let release_ns = nodes[n as usize].release_ns;
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
            self.early_insert(nodes, n);
            if self.early_len == EARLY_MAX {
                self.merge_early(nodes);
            }
            return;
        }
        self.place(nodes, n);
    }

    /// Takes the earliest frame out (the wheel holds one).
    fn remove_first(&mut self, nodes: &mut [Node]) -> u32 {
        self.len -= 1;
        if self.early_head != NIL {
            let n = self.early_head;
            self.early_head = nodes[n as usize].next;
            if self.early_head == NIL {
                self.early_tail = NIL;
            }
            self.early_len -= 1;
            return n;
        }
        let level0 = &mut self.levels[0];
        let slot = level0.occupied.trailing_zeros() as usize;
        let n = level0.head[slot];
        let node = nodes[n as usize];
        level0.head[slot] = node.next;
        if node.next == NIL {
            level0.tail[slot] = NIL;
            level0.occupied &= !(1 << slot);
        }
        // Every frame left is due at or after this one.
        self.cursor_ns = node.release_ns;
        if self.levels[0].occupied == 0 && self.len > 0 {
            debug_assert_eq!(self.early_len, 0);
            self.refill(nodes);
        }
        n
    }

    /// Puts node `n` into its slot relative to the cursor.
    #[inline]
    fn place(&mut self, nodes: &mut [Node], n: u32) {
        let Node { release_ns, ingress_index, .. } = nodes[n as usize];
        let level = level_for(self.cursor_ns, release_ns);
        let slot = digit(release_ns, level);
        let lv = &mut self.levels[level];
        let head = lv.head[slot];
        if head == NIL {
            nodes[n as usize].next = NIL;
            lv.head[slot] = n;
            lv.tail[slot] = n;
            lv.occupied |= 1 << slot;
            return;
        }
        if level > 0 {
            // A bag: the front is cheapest (it touches no other node).
            nodes[n as usize].next = head;
            lv.head[slot] = n;
            return;
        }
        // Level 0: one release time per slot, kept in ingress order. Frames
        // come in ingress order (append) or, cascaded from a bag, often in
        // reverse (prepend); anything else walks the ties.
        let tail = lv.tail[slot];
        if nodes[tail as usize].ingress_index <= ingress_index {
            nodes[tail as usize].next = n;
            nodes[n as usize].next = NIL;
            lv.tail[slot] = n;
        } else if ingress_index < nodes[head as usize].ingress_index {
            nodes[n as usize].next = head;
            lv.head[slot] = n;
        } else {
            let mut prev = head;
            loop {
                let next = nodes[prev as usize].next;
                if nodes[next as usize].ingress_index > ingress_index {
                    nodes[n as usize].next = next;
                    nodes[prev as usize].next = n;
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
    fn refill(&mut self, nodes: &mut [Node]) {
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
            self.cursor_ns = if single { nodes[n as usize].release_ns } else { slot_start_ns(self.cursor_ns, level, slot) };
            while n != NIL {
                let next = nodes[n as usize].next;
                self.place(nodes, n);
                n = next;
            }
        }
    }

    /// Puts node `n` into the early list, in `(release_ns, ingress_index)`
    /// order: appended or prepended when it belongs at an end (the usual
    /// case), else after a walk of at most `EARLY_MAX` frames.
    fn early_insert(&mut self, nodes: &mut [Node], n: u32) {
        let k = nodes[n as usize].key();
        self.early_len += 1;
        if self.early_head == NIL {
            nodes[n as usize].next = NIL;
            self.early_head = n;
            self.early_tail = n;
        } else if nodes[self.early_tail as usize].key() <= k {
            nodes[n as usize].next = NIL;
            nodes[self.early_tail as usize].next = n;
            self.early_tail = n;
        } else if k < nodes[self.early_head as usize].key() {
            nodes[n as usize].next = self.early_head;
            self.early_head = n;
        } else {
            let mut prev = self.early_head;
            loop {
                let next = nodes[prev as usize].next;
                if nodes[next as usize].key() > k {
                    nodes[n as usize].next = next;
                    nodes[prev as usize].next = n;
                    break;
                }
                prev = next;
            }
        }
    }

    /// Moves the early list into the wheel: the cursor goes back to its
    /// first frame, and every frame is placed relative to it.
    #[cold]
    fn merge_early(&mut self, nodes: &mut [Node]) {
        let mut n = self.early_head;
        self.rewind(nodes, nodes[n as usize].release_ns);
        (self.early_head, self.early_tail, self.early_len) = (NIL, NIL, 0);
        while n != NIL {
            let next = nodes[n as usize].next;
            self.place(nodes, n);
            n = next;
        }
    }

    /// Moves the cursor back to `release_ns`, earlier than it and so than
    /// every frame held (a new earliest frame). Frames below the highest
    /// digit in which the two times differ all share the cursor's digit
    /// there, so they become one bag in that slot: list splices, one per
    /// occupied slot, no frame is moved on its own.
    #[cold]
    fn rewind(&mut self, nodes: &mut [Node], release_ns: u64) {
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
                        nodes[t as usize].next = head;
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

// ---------------------------------------------------------------------------
// The reorder queue: a slab, the calendar and the wheel.

/// The reorder queue: frames in a slab (nodes and items at the same index,
/// free slots in an intrusive list), each held either by the calendar or,
/// when outside its window, by the wheel. Both keep `(release_ns,
/// ingress_index)` order, so the earliest frame is the earlier of their two
/// first frames; which structure holds a frame changes only its cost.
#[derive(Debug, Clone)]
struct Timeline<T> {
    nodes: Vec<Node>,
    items: Items<T>,
    free: u32,
    /// Frames held, in both.
    len: usize,
    calendar: Calendar,
    wheel: Wheel,
    /// The last frame the calendar refused to take from the wheel.
    refused: u32,
}

impl<T: Copy + Default> Timeline<T> {
    fn new(capacity: usize) -> Self {
        // Every node and item is written here (`resident_vec`), so the memory
        // is resident before the first frame.
        let mut nodes = resident_vec(capacity, Node { release_ns: 0, ingress_index: 0, next: NIL });
        for (i, node) in nodes.iter_mut().enumerate().take(capacity - 1) {
            node.next = i as u32 + 1;
        }
        Timeline { nodes, items: Items::new(capacity), free: 0, len: 0, calendar: Calendar::new(capacity), wheel: Wheel::new(), refused: NIL }
    }

    #[inline]
    fn next_release_ns(&self) -> Option<u64> {
        match (self.calendar.len, self.wheel.len) {
            (0, 0) => None,
            (_, 0) => Some(self.calendar.first_ns),
            (0, _) => Some(self.wheel.next_release_ns(&self.nodes)),
            _ => Some(self.calendar.first_ns.min(self.wheel.next_release_ns(&self.nodes))),
        }
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
        self.items.set(n, item);
        self.len += 1;
        if !self.calendar.insert(&mut self.nodes, n) {
            self.wheel.insert(&mut self.nodes, n);
        }
        if self.wheel.len > 0 && self.calendar.len > 0 {
            self.migrate();
        }
        Ok(release_ns)
    }

    /// Moves the wheel's earliest frames into the calendar while its window
    /// covers them: after the calendar starts over with wider buckets, the
    /// frames that did not fit the old window join it, a few per push. A
    /// frame the calendar refused (its bucket too deep) is not offered again
    /// while it is the wheel's first.
    fn migrate(&mut self) {
        for _ in 0..MIGRATE_PER_PUSH {
            if self.wheel.len == 0 {
                return;
            }
            let n = self.wheel.first();
            if n == self.refused || self.calendar.closed {
                return;
            }
            let a = self.nodes[n as usize].release_ns >> self.calendar.shift;
            let c = &self.calendar;
            if if a < c.first { c.hi - a > c.mask } else { a - c.first > c.mask } {
                return;
            }
            let n = self.wheel.remove_first(&mut self.nodes);
            if !self.calendar.insert(&mut self.nodes, n) {
                self.wheel.insert(&mut self.nodes, n);
                self.refused = n;
                return;
            }
        }
    }

    /// Takes the earliest frame out: its slab index, free again (its item
    /// stays in place until the next push).
    #[inline]
    fn pop(&mut self) -> Option<u32> {
        let n = if self.wheel.len == 0 {
            if self.calendar.len == 0 {
                return None;
            }
            self.pop_calendar()
        } else if self.calendar.len == 0 || self.nodes[self.wheel.first() as usize].key() < self.nodes[self.calendar.head() as usize].key() {
            self.wheel.remove_first(&mut self.nodes)
        } else {
            self.pop_calendar()
        };
        self.nodes[n as usize].next = self.free;
        self.free = n;
        self.len -= 1;
        Some(n)
    }

    /// The frame at slab index `n`, its item read in place.
    #[inline]
    fn released(&self, n: u32) -> Released<&T> {
        let node = &self.nodes[n as usize];
        Released { release_ns: node.release_ns, ingress_index: node.ingress_index, item: self.items.get(n) }
    }

    /// The calendar's earliest frame. What the following pops take is
    /// prefetched: the item of the new first frame (the next pop's, if the
    /// wheel holds none earlier), and, a few buckets on, the node and item
    /// of the first frame of the next occupied bucket and of the second of
    /// the one after the `near` cursor, so that at depth their lines (cold
    /// since their push) arrive before they are taken. One bucket per
    /// cursor and pop: a pop takes at most one bucket's frame, so the
    /// cursors keep their distance.
    #[inline]
    fn pop_calendar(&mut self) -> u32 {
        let n = self.calendar.remove_first(&mut self.nodes);
        let c = &mut self.calendar;
        if c.len > 0 {
            // Prefetched once already, a few buckets back; at depth the line
            // is often gone again by now (the streaming items evict it), and
            // from the outer caches it arrives within the caller's turn.
            prefetch(self.items.get(c.head()));
        }
        match c.next_within(c.ahead, AHEAD_BUCKETS) {
            Some(a) => {
                c.ahead = a;
                let m = c.heads[(a & c.mask) as usize];
                prefetch(&self.nodes[m as usize]);
                prefetch_once(self.items.get(m));
            }
            None => c.ahead = c.ahead.max(c.first.saturating_add(AHEAD_BUCKETS)).min(c.hi),
        }
        match c.next_within(c.near, NEAR_BUCKETS) {
            Some(a) => {
                c.near = a;
                let m = self.nodes[c.heads[(a & c.mask) as usize] as usize].next;
                if m != NIL {
                    prefetch(&self.nodes[m as usize]);
                    prefetch_once(self.items.get(m));
                }
            }
            None => c.near = c.near.max(c.first.saturating_add(NEAR_BUCKETS)).min(c.hi),
        }
        n
    }
}

/// The FIFO order: frames in a ring, in push order. A pop leaves the
/// frame in its slot (free again) until a push wraps round to it, so it can
/// be read in place.
#[derive(Debug, Clone)]
struct Ring<T> {
    slots: Vec<Released<T>>,
    head: usize,
    len: usize,
    last_release_ns: u64,
}

impl<T: Copy + Default> Ring<T> {
    fn new(capacity: usize) -> Self {
        let slots = resident_vec(capacity, Released { release_ns: 0, ingress_index: 0, item: T::default() });
        Ring { slots, head: 0, len: 0, last_release_ns: 0 }
    }

    #[inline]
    fn push(&mut self, release_ns: u64, ingress_index: u64, item: T) -> Result<u64, Full<T>> {
        let capacity = self.slots.len();
        if self.len == capacity {
            return Err(Full(item));
        }
        let release_ns = release_ns.max(self.last_release_ns);
        self.last_release_ns = release_ns;
        let at = self.head + self.len;
        self.slots[if at >= capacity { at - capacity } else { at }] = Released { release_ns, ingress_index, item };
        self.len += 1;
        Ok(release_ns)
    }

    /// Takes the first frame out: its slot.
    #[inline]
    fn pop(&mut self) -> Option<usize> {
        if self.len == 0 {
            return None;
        }
        let at = self.head;
        self.head = if at + 1 == self.slots.len() { 0 } else { at + 1 };
        self.len -= 1;
        Some(at)
    }

    #[inline]
    fn released(&self, at: usize) -> Released<&T> {
        let r = &self.slots[at];
        Released { release_ns: r.release_ns, ingress_index: r.ingress_index, item: &r.item }
    }
}

#[derive(Debug, Clone)]
enum Inner<T> {
    Fifo(Ring<T>),
    Reorder(Box<Timeline<T>>),
}

/// A fixed-capacity release queue.
#[derive(Debug, Clone)]
pub struct ReleaseQueue<T> {
    inner: Inner<T>,
    capacity: usize,
}

impl<T: Copy + Default> ReleaseQueue<T> {
    /// The memory one frame of capacity takes in a queue of this order: for
    /// `Reorder`, the slab's node and item (the calendar's bucket heads and
    /// bitmaps add at most 16.5 bytes a frame, left out of this figure).
    pub const fn bytes_per_frame(order: QueueOrder) -> usize {
        match order {
            QueueOrder::Fifo => size_of::<Released<T>>(),
            QueueOrder::Reorder => size_of::<Node>() + Items::<T>::bytes(),
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
            QueueOrder::Fifo => Inner::Fifo(Ring::new(capacity)),
            QueueOrder::Reorder => Inner::Reorder(Box::new(Timeline::new(capacity))),
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
            Inner::Fifo(ring) => ring.len,
            Inner::Reorder(t) => t.len,
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
            Inner::Fifo(ring) => ring.push(release_ns, ingress_index, item),
            Inner::Reorder(t) => t.push(release_ns, ingress_index, item),
        }
    }

    /// The earliest scheduled release, if any frame is held; constant time.
    #[inline]
    pub fn next_release_ns(&self) -> Option<u64> {
        match &self.inner {
            Inner::Fifo(ring) => (ring.len > 0).then(|| ring.slots[ring.head].release_ns),
            Inner::Reorder(t) => t.next_release_ns(),
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
        self.pop_ref().map(|r| Released { release_ns: r.release_ns, ingress_index: r.ingress_index, item: *r.item })
    }

    /// [`pop_due`](Self::pop_due), the item read in place: it stays in the
    /// queue's memory, free again, until the next push (which the borrow
    /// holds off), so a caller that copies it on (the emulator, into the
    /// publisher's loan) copies it once, not twice.
    #[inline]
    pub fn pop_due_ref(&mut self, now_ns: u64) -> Option<Released<&T>> {
        match self.next_release_ns() {
            Some(t) if t <= now_ns => self.pop_ref(),
            _ => None,
        }
    }

    /// [`pop`](Self::pop), the item read in place (see
    /// [`pop_due_ref`](Self::pop_due_ref)).
    #[inline]
    pub fn pop_ref(&mut self) -> Option<Released<&T>> {
        match &mut self.inner {
            Inner::Fifo(ring) => {
                let at = ring.pop()?;
                Some(ring.released(at))
            }
            Inner::Reorder(t) => {
                let n = t.pop()?;
                Some(t.released(n))
            }
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
