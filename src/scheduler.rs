//! The release queue: frames held by the injector until their scheduled
//! release time, with a fixed capacity chosen at start-up.
//!
//! Two orders (docs/spec.md §3.4). `Fifo` is a ring: releases leave in the order they
//! were pushed, and a push whose time is earlier than the last one is held
//! until that one (`release = max(own, previous)`), as an ordered transport
//! does. `Reorder` leaves each frame at its own time, ties in ingress order:
//! exactly the order of `(release_ns, ingress_index)`.
//!
//! `Reorder` is a ladder queue (after Tang, Goh and Thng's, with one rung):
//! items in a slab (on cache-line boundaries when a whole number of lines,
//! as the emulator's 192-byte sample; the large arrays advised onto huge
//! pages), and each frame's key and slot, an entry of 24 bytes, in one of
//! three places:
//!
//! - the **front**, every frame due up to a bound, sorted by
//!   `(release_ns, ingress_index)`: a pop takes its first entry; a push due
//!   that early goes to its place (at an end, the usual case, or moving the
//!   shorter side by one);
//! - one **row** of at most 1 024 buckets (few enough that the ends of
//!   their bags stay in cache; one per 8 of the frames the row is built
//!   from, so a shallow queue's buckets hold several frames), each a fixed
//!   span of time (a power of two of nanoseconds) holding its entries in no
//!   order: a push is an append.
//!   When the front runs short, a pop moves the next occupied bucket to
//!   the front's end and sorts it: a counting pass by offset into
//!   sub-buckets of about one frame, then an insertion sort;
//! - the **far** bag, frames beyond the row, appended in no order. When the
//!   row is empty the front's next frames come from the far bag: the row is
//!   built again from it, spanning four times the far frames' mean reach
//!   past the front, so its frames spread over its buckets at any rate and
//!   delay; frames beyond stay far.
//!
//! A frame is written about four times (its push, into the row, into the
//! front, its pop), each time next to the frames before it, and never
//! found by following links through the queue; a pop prefetches the item
//! it will take 16 pops later, and moving a bucket to the front prefetches
//! the next one's chunks. What a deep queue costs beyond a shallow one is
//! the item's own trip through memory (the `floor` case of
//! `benches/queue.rs`) and the work on each frame's entry.
//!
//! Costs: a push appends or, due within the front, moves at most half the
//! front by one entry (the front usually holds 16 frames and the bucket
//! last moved into it); a pop sorts a bucket now and then (linear in its
//! size; by comparison, `n log n`, should many frames share one
//! nanosecond out of ingress order) and, when the row is empty, scans the
//! far bag once, and about three far frames in four join the row (no more
//! than a quarter of them reach four times their mean).
//!
//! A pop can leave the item in place ([`ReleaseQueue::pop_ref`],
//! [`ReleaseQueue::pop_due_ref`]): its slot is free again but not written
//! before the next push, which the borrow holds off, so a caller that copies
//! the item on (the emulator, into the publisher's loan) copies it once.
//!
//! Neither order allocates after construction: the reorder queue's slots,
//! entries and chunks are all reserved when it is built (the chunks of
//! every bag together need `capacity / 8` plus one a bag), and a push
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
/// hundred milliseconds) — and it costs about 4.5 GB with the emulator's
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

/// Issues a prefetch of the cache lines of `*p`: a hint, never a fault.
#[inline(always)]
fn prefetch<X>(p: *const X) {
    prefetch_hint::<{ HINT_KEEP }, X>(p)
}

#[cfg(target_arch = "x86_64")]
const HINT_KEEP: i32 = core::arch::x86_64::_MM_HINT_T0;
#[cfg(not(target_arch = "x86_64"))]
const HINT_KEEP: i32 = 0;
#[cfg(target_arch = "x86_64")]
const HINT_L2: i32 = core::arch::x86_64::_MM_HINT_T1;
#[cfg(not(target_arch = "x86_64"))]
const HINT_L2: i32 = 0;

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
// The reorder queue: a sorted front, a row of buckets, and the far frames.

/// One held frame's place in the order: its key, and the slot of its item.
#[derive(Debug, Clone, Copy, Default)]
struct Entry {
    release_ns: u64,
    ingress_index: u64,
    slot: u32,
}

impl Entry {
    #[inline(always)]
    fn key(&self) -> (u64, u64) {
        (self.release_ns, self.ingress_index)
    }
}

/// Entries in a chunk: 8 of 24 bytes, three cache lines.
const CHUNK: usize = 8;

#[derive(Debug, Clone, Copy, Default)]
#[repr(C, align(64))]
struct Chunk([Entry; CHUNK]);

/// Entries in no order, in a list of chunks: `len` entries, the last chunk
/// (`tail`) holding `len % CHUNK` of them (all `CHUNK` when that is 0).
#[derive(Debug, Clone, Copy)]
struct Bag {
    head: u32,
    tail: u32,
    len: u32,
}

impl Bag {
    const EMPTY: Bag = Bag { head: NIL, tail: NIL, len: 0 };
}

/// The chunks of every bag, and the free ones in a list through `next`.
/// A bag of `n` entries takes `⌈n / 8⌉` chunks, so `capacity / 8` plus one
/// a bag suffice whatever the entries' spread.
#[derive(Debug, Clone)]
struct Pool {
    chunks: Vec<Chunk>,
    next: Vec<u32>,
    free: u32,
}

impl Pool {
    fn new(n: usize) -> Self {
        let mut next = resident_vec(n, NIL);
        for (i, link) in next.iter_mut().enumerate().take(n - 1) {
            *link = i as u32 + 1;
        }
        Pool { chunks: resident_vec(n, Chunk::default()), next, free: 0 }
    }

    #[inline(always)]
    fn append(&mut self, bag: &mut Bag, e: Entry) {
        let k = bag.len as usize % CHUNK;
        if k == 0 {
            let c = self.free;
            debug_assert_ne!(c, NIL, "the pool holds a chunk for every bag");
            self.free = self.next[c as usize];
            self.next[c as usize] = NIL;
            if bag.tail == NIL {
                bag.head = c;
            } else {
                self.next[bag.tail as usize] = c;
            }
            bag.tail = c;
        }
        self.chunks[bag.tail as usize].0[k] = e;
        bag.len += 1;
    }

    /// Unlinks the first chunk of `bag`: its index and how many entries
    /// it holds; `None` when empty. The chunk stays as it is until
    /// [`Pool::free`] gives it back.
    #[inline(always)]
    fn take_chunk(&mut self, bag: &mut Bag) -> Option<(usize, usize)> {
        let c = bag.head;
        if c == NIL {
            return None;
        }
        let next = self.next[c as usize];
        if next != NIL {
            // The next chunk, cold since it was filled, arrives while this
            // one is used.
            prefetch(&self.chunks[next as usize]);
        }
        // Only the last chunk is part-filled: it holds what is left.
        let k = if next == NIL { bag.len as usize } else { CHUNK };
        bag.head = next;
        bag.len -= k as u32;
        if next == NIL {
            bag.tail = NIL;
        }
        Some((c as usize, k))
    }

    /// The chunks of `bag`, first to last, left in it: each one's index and
    /// how many entries it holds.
    #[inline(always)]
    fn chunks_of(&self, bag: &Bag) -> impl Iterator<Item = (usize, usize)> + '_ {
        // Only the last chunk is part-filled.
        let last = (bag.len as usize + CHUNK - 1) % CHUNK + 1;
        let mut c = bag.head;
        std::iter::from_fn(move || {
            if c == NIL {
                return None;
            }
            let at = c as usize;
            c = self.next[at];
            Some((at, if c == NIL { last } else { CHUNK }))
        })
    }

    /// Gives a taken chunk back.
    #[inline(always)]
    fn free(&mut self, c: usize) {
        self.next[c] = self.free;
        self.free = c as u32;
    }
}

/// The most buckets, and the fewest. A push appends to one of them at
/// random, so their bags' ends must stay in cache: 1 024 of them are about
/// 200 kB, where one per 8 frames (16 384 at depth 10^5) missed it on
/// nearly every push. A deep queue's buckets are larger instead: hundreds
/// of frames at depth 10^5, thousands at 10^6, sorted in linear time (see
/// [`Timeline::sort_bucket`]).
const MAX_BUCKETS: usize = 1 << 10;
const MIN_BUCKETS: usize = 64;
/// How many frames ahead of the first a pop prefetches the item of, and
/// how many the front keeps when more are held.
const AHEAD: usize = 16;
/// Free entries kept before the front's first, for frames pushed ahead of
/// it.
const MARGIN: usize = 64;
/// The largest bucket sorted by counting (see [`Timeline::sort_bucket`]);
/// a larger one, rare, is sorted by comparison.
const COUNTED: usize = 1 << 16;
/// At most `2^SUB_BITS` sub-buckets when a bucket is sorted.
const SUB_BITS: u32 = 14;

/// The buckets a capacity allocates: one per 8 frames, within the bounds
/// above. A row uses as many of them as the frames it is built from need.
fn bucket_count(capacity: usize) -> usize {
    (capacity.next_power_of_two() / 8).clamp(MIN_BUCKETS, MAX_BUCKETS)
}

/// The reorder queue (a ladder queue in the manner of Tang, Goh and Thng,
/// 2005, with one rung). Every held frame is an [`Entry`] in one of three
/// places, by its release time against the front's bound `front_max_ns`:
///
/// - the **front**: every frame due at or before `front_max_ns`, sorted by
///   `(release_ns, ingress_index)` in `entries[lo..hi]`. A pop takes
///   `entries[lo]`; a push due that early is put in its place (the
///   shorter side moved by one).
/// - the **buckets**: one row of `2^k` buckets (one per 8 frames it is
///   built from, at least [`MIN_BUCKETS`], at most the capacity's
///   [`bucket_count`]), `2^shift` ns each, from `row_start`; bags in no
///   order. When the front runs short a pop moves the next occupied
///   bucket into it and sorts it: its frames are then the earliest held,
///   and `front_max_ns` becomes the bucket's last nanosecond.
/// - the **far** bag: frames beyond the row. When the row is empty and the
///   front needs frames, the row is built again from the far bag: it starts
///   after the front and spans four times the far frames' mean reach, so
///   the frames spread over its buckets whatever the rate and delay; frames
///   beyond it stay far.
///
/// So a frame is written about four times (its push; to the row; to the
/// front; the pop), each time among neighbours in memory, and never found
/// by following links through the whole queue; the item, the one trip to
/// memory a deep queue cannot avoid, is prefetched [`AHEAD`] pops before it
/// is taken.
#[derive(Debug, Clone)]
struct Timeline<T> {
    items: Items<T>,
    /// Free item slots, a stack: a push takes the slot the last pop freed,
    /// still in cache.
    free: Vec<u32>,
    pool: Pool,
    entries: Vec<Entry>,
    lo: usize,
    hi: usize,
    front_max_ns: u64,
    buckets: Vec<Bag>,
    /// Bit per bucket: occupied; bit per word of `words`: non-zero.
    words: Vec<u64>,
    summary: Vec<u64>,
    mask: u64,
    shift: u32,
    /// The row's first bucket (absolute: `release_ns >> shift`) and its
    /// length (0: no row), the next bucket a pop may move to the front;
    /// frames in the row.
    row_start: u64,
    row_buckets: u64,
    next_bucket: u64,
    in_row: usize,
    far: Bag,
    far_sum_ns: u128,
    len: usize,
    /// A sub-bucket's count, then its next place, as a bucket is sorted.
    counts: Vec<u32>,
}

impl<T: Copy + Default> Timeline<T> {
    fn new(capacity: usize) -> Self {
        let count = bucket_count(capacity);
        let words = count / 64;
        let mut free = Vec::with_capacity(capacity);
        free.extend((0..capacity as u32).rev());
        Timeline {
            items: Items::new(capacity),
            free,
            pool: Pool::new(capacity.div_ceil(CHUNK) + count + 2),
            entries: resident_vec(2 * capacity + 2 * MARGIN, Entry::default()),
            lo: MARGIN,
            hi: MARGIN,
            front_max_ns: 0,
            buckets: vec![Bag::EMPTY; count],
            words: vec![0; words],
            summary: vec![0; words.div_ceil(64)],
            mask: count as u64 - 1,
            shift: 0,
            row_start: 0,
            row_buckets: 0,
            next_bucket: 0,
            in_row: 0,
            far: Bag::EMPTY,
            far_sum_ns: 0,
            len: 0,
            counts: vec![0; (1 << SUB_BITS.min(usize::BITS - capacity.leading_zeros())) + 1],
        }
    }

    #[inline]
    fn next_release_ns(&self) -> Option<u64> {
        (self.len > 0).then(|| self.entries[self.lo].release_ns)
    }

    #[inline]
    fn push(&mut self, release_ns: u64, ingress_index: u64, item: T) -> Result<u64, Full<T>> {
        let Some(slot) = self.free.pop() else { return Err(Full(item)) };
        self.items.set(slot, item);
        let e = Entry { release_ns, ingress_index, slot };
        self.len += 1;
        if self.len == 1 {
            // An empty queue starts over: the frame is the front, the row
            // empty until a pop builds it.
            (self.lo, self.hi, self.front_max_ns) = (MARGIN, MARGIN + 1, release_ns);
            self.entries[MARGIN] = e;
            self.row_buckets = 0;
            return Ok(release_ns);
        }
        if release_ns <= self.front_max_ns {
            self.insert_front(e);
        } else if (release_ns >> self.shift).wrapping_sub(self.row_start) < self.row_buckets {
            // Later than the front, so not before the row's next bucket.
            self.add_to_row(e);
        } else {
            self.far_sum_ns += release_ns as u128;
            self.pool.append(&mut self.far, e);
        }
        Ok(release_ns)
    }

    #[inline(always)]
    fn add_to_row(&mut self, e: Entry) {
        let i = ((e.release_ns >> self.shift) & self.mask) as usize;
        if self.buckets[i].len == 0 {
            let w = i >> 6;
            if self.words[w] == 0 {
                self.summary[w >> 6] |= 1 << (w & 63);
            }
            self.words[w] |= 1 << (i & 63);
        }
        self.pool.append(&mut self.buckets[i], e);
        self.in_row += 1;
    }

    /// Puts `e` into the sorted front: at an end (the usual case: the
    /// frame is the earliest, or due with the last), else in its place, the
    /// shorter side moved by one.
    #[inline]
    fn insert_front(&mut self, e: Entry) {
        let key = e.key();
        if self.lo == self.hi || key < self.entries[self.lo].key() {
            if self.lo == 0 {
                self.compact();
            }
            self.lo -= 1;
            self.entries[self.lo] = e;
        } else if self.entries[self.hi - 1].key() <= key {
            if self.hi == self.entries.len() {
                self.compact();
            }
            self.entries[self.hi] = e;
            self.hi += 1;
        } else {
            let at = self.lo + self.entries[self.lo..self.hi].partition_point(|x| x.key() <= key);
            if at - self.lo <= self.hi - at && self.lo > 0 {
                self.entries.copy_within(self.lo..at, self.lo - 1);
                self.lo -= 1;
                self.entries[at - 1] = e;
            } else {
                if self.hi == self.entries.len() {
                    self.compact();
                    return self.insert_front(e);
                }
                self.entries.copy_within(at..self.hi, at + 1);
                self.hi += 1;
                self.entries[at] = e;
            }
        }
    }

    /// Moves the front to `MARGIN`: room at both ends (it holds at most
    /// `capacity` of the `2 capacity + 2 MARGIN` entries).
    #[cold]
    fn compact(&mut self) {
        let n = self.hi - self.lo;
        self.entries.copy_within(self.lo..self.hi, MARGIN);
        (self.lo, self.hi) = (MARGIN, MARGIN + n);
    }

    /// Takes the earliest frame out; its slot is free again (the item stays
    /// in place until the next push).
    #[inline]
    fn pop(&mut self) -> Option<Entry> {
        if self.len == 0 {
            return None;
        }
        let e = self.entries[self.lo];
        self.lo += 1;
        self.len -= 1;
        self.free.push(e.slot);
        while self.hi - self.lo < AHEAD && (self.in_row > 0 || self.far.len > 0) {
            self.load_bucket();
        }
        if self.lo + AHEAD <= self.hi {
            prefetch(self.items.get(self.entries[self.lo + AHEAD - 1].slot));
        }
        Some(e)
    }

    /// Moves the next occupied bucket to the front's end, sorted (building
    /// the row from the far bag first if it is empty).
    #[inline(never)]
    fn load_bucket(&mut self) {
        if self.in_row == 0 {
            self.build_row();
        }
        let a = self.next_occupied(self.next_bucket);
        let i = (a & self.mask) as usize;
        let mut bag = std::mem::replace(&mut self.buckets[i], Bag::EMPTY);
        let w = i >> 6;
        self.words[w] &= !(1 << (i & 63));
        if self.words[w] == 0 {
            self.summary[w >> 6] &= !(1 << (w & 63));
        }
        self.in_row -= bag.len as usize;
        self.next_bucket = a.wrapping_add(1); // a = u64::MAX only when nothing can be later
        self.front_max_ns = (a << self.shift) | ((1u64 << self.shift) - 1);
        if self.lo == self.hi {
            (self.lo, self.hi) = (MARGIN, MARGIN);
        } else if self.hi + bag.len as usize > self.entries.len() || (self.lo > 8 * MARGIN && self.hi - self.lo <= MARGIN) {
            // Out of room, or a short front far from the start: back to it,
            // where its lines are still in cache.
            self.compact();
        }
        let start = self.hi;
        let n = bag.len as usize;
        if n > 1 && n <= COUNTED {
            self.sort_bucket(bag, a << self.shift);
        } else {
            while let Some((c, k)) = self.pool.take_chunk(&mut bag) {
                self.entries[self.hi..self.hi + k].copy_from_slice(&self.pool.chunks[c].0[..k]);
                self.pool.free(c);
                self.hi += k;
            }
            self.entries[start..self.hi].sort_unstable_by_key(Entry::key);
        }
        // Items the rolling prefetch in `pop` has passed already.
        for e in &self.entries[start..self.hi.min(self.lo + AHEAD)] {
            prefetch(self.items.get(e.slot));
        }
        if self.in_row > 0 {
            // The next bucket's chunks, cold since they were filled, arrive
            // while this one's frames are popped.
            let b = &self.buckets[(self.next_occupied(self.next_bucket) & self.mask) as usize];
            for (c, _) in self.pool.chunks_of(b) {
                prefetch_hint::<{ HINT_L2 }, _>(&self.pool.chunks[c]);
            }
        }
    }

    /// Moves `bag` (a bucket starting at `base_ns`, `2^shift` ns wide, at
    /// most [`COUNTED`] frames) to the front's end in order. A first pass
    /// counts its frames by sub-bucket (about one per frame, by offset in
    /// the bucket: at most [`SUB_BITS`] bits of it); a second moves each to
    /// its sub-bucket's next place, in bag order; an insertion sort then
    /// orders each sub-bucket by `(release_ns, ingress_index)`. Linear in
    /// the bucket, and no branch mispredicted per frame but the sub-buckets
    /// that hold more than one. Should many frames share a sub-bucket out of
    /// order (ties pushed against ingress order), the insertion sort gives
    /// up after `4 n` moves and the bucket is sorted by comparison.
    #[inline]
    fn sort_bucket(&mut self, mut bag: Bag, base_ns: u64) {
        let n = bag.len as usize;
        let bits = (usize::BITS - n.leading_zeros()).min(SUB_BITS).min(self.shift);
        let down = self.shift - bits;
        let counts = &mut self.counts[..(1 << bits) + 1];
        counts.fill(0);
        for (c, k) in self.pool.chunks_of(&bag) {
            let next = self.pool.next[c];
            if next != NIL {
                prefetch(&self.pool.chunks[next as usize]);
            }
            for e in &self.pool.chunks[c].0[..k] {
                counts[((e.release_ns - base_ns) >> down) as usize + 1] += 1;
            }
        }
        for d in 1..counts.len() {
            counts[d] += counts[d - 1];
        }
        let start = self.hi;
        let sorted = &mut self.entries[start..start + n];
        while let Some((c, k)) = self.pool.take_chunk(&mut bag) {
            for e in &self.pool.chunks[c].0[..k] {
                let d = ((e.release_ns - base_ns) >> down) as usize;
                sorted[counts[d] as usize] = *e;
                counts[d] += 1;
            }
            self.pool.free(c);
        }
        self.hi += n;
        let mut budget = 4 * n;
        for i in 1..n {
            let e = sorted[i];
            let key = e.key();
            if key < sorted[i - 1].key() {
                let mut at = i;
                while at > 0 && key < sorted[at - 1].key() {
                    sorted[at] = sorted[at - 1];
                    at -= 1;
                }
                sorted[at] = e;
                let moved = i - at;
                if moved > budget {
                    sorted.sort_unstable_by_key(Entry::key);
                    return;
                }
                budget -= moved;
            }
        }
    }

    /// Builds the row from the far bag (the row is empty): from the bucket
    /// after the front, four times the far frames' mean reach, buckets of a
    /// power-of-two width. Frames beyond it stay far (about three in four
    /// join the row: no more than a quarter of the frames reach four times
    /// the mean).
    #[cold]
    fn build_row(&mut self) {
        // One bucket per 8 frames to place, within the capacity's count: a
        // shallow queue's buckets then hold several frames each, where one
        // per 8 of the capacity would leave most pops moving a bucket of
        // one (a row's fixed cost for a single frame).
        let count = (self.far.len as usize / 8).next_power_of_two().clamp(MIN_BUCKETS, self.buckets.len()) as u64;
        self.mask = count - 1;
        let start_ns = self.front_max_ns + 1;
        let mean_reach = (self.far_sum_ns / self.far.len as u128) as u64 - start_ns;
        // Width 2^shift: the reach (twice the mean, and one more) in at most
        // half the buckets, so the row covers four times the mean.
        let span = mean_reach.saturating_mul(2).saturating_add(1);
        self.shift = (64 - (span / (count / 2)).leading_zeros()).min(63);
        (self.row_start, self.row_buckets) = (start_ns >> self.shift, count);
        self.next_bucket = self.row_start;
        let mut far = std::mem::replace(&mut self.far, Bag::EMPTY);
        self.far_sum_ns = 0;
        while let Some((c, k)) = self.pool.take_chunk(&mut far) {
            for x in 0..k {
                let e = self.pool.chunks[c].0[x];
                if (e.release_ns >> self.shift) - self.row_start < count {
                    self.add_to_row(e);
                } else {
                    self.far_sum_ns += e.release_ns as u128;
                    self.pool.append(&mut self.far, e);
                }
            }
            // Freed only now: the appends above must not take it.
            self.pool.free(c);
        }
    }

    /// The first occupied bucket at or after `from` (one is in the row).
    #[inline]
    fn next_occupied(&self, from: u64) -> u64 {
        let i = (from & self.mask) as usize;
        let (w, b) = (i >> 6, i & 63);
        let here = self.words[w] & (!0u64 << b);
        let j = if here != 0 {
            w << 6 | here.trailing_zeros() as usize
        } else {
            let n = (self.mask as usize + 1) >> 6;
            let v = next_set(&self.summary, if w + 1 == n { 0 } else { w + 1 });
            v << 6 | self.words[v].trailing_zeros() as usize
        };
        from + ((j as u64).wrapping_sub(i as u64) & self.mask)
    }

    /// The frame `e` names, its item read in place.
    #[inline]
    fn released(&self, e: Entry) -> Released<&T> {
        Released { release_ns: e.release_ns, ingress_index: e.ingress_index, item: self.items.get(e.slot) }
    }
}

/// The next set bit at or after `start` in `bits`, circularly.
#[inline]
fn next_set(bits: &[u64], start: usize) -> usize {
    let (w, b) = (start >> 6, start & 63);
    let here = bits[w] & (!0u64 << b);
    if here != 0 {
        return w << 6 | here.trailing_zeros() as usize;
    }
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
    /// `Reorder`, the item, its free slot's index and three entries (two in
    /// the front's room, one in a chunk; the buckets, at most 1 024, add
    /// about 200 bytes each, and the sort's counts up to 64 kB, left out of
    /// this figure).
    pub const fn bytes_per_frame(order: QueueOrder) -> usize {
        match order {
            QueueOrder::Fifo => size_of::<Released<T>>(),
            QueueOrder::Reorder => 3 * size_of::<Entry>() + size_of::<u32>() + Items::<T>::bytes(),
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
            Inner::Reorder(t) => pop_reorder(t),
        }
    }
}

/// The reorder queue's pop, kept out of line: inlined, its bucket loading
/// makes every caller's pop too large to inline, and the FIFO queue's pop
/// (the simulated-time checker's and an undelayed stream's) then pays a
/// call and its register saves per frame, due or not.
#[inline(never)]
fn pop_reorder<T: Copy + Default>(t: &mut Timeline<T>) -> Option<Released<&T>> {
    let e = t.pop()?;
    Some(t.released(e))
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
        // 4 294 967 295 frames of the emulator's 192-byte samples, each with
        // three 24-byte entries (front, twice; a chunk) and a free slot: 1.15 TB.
        let e = ReleaseQueue::<crate::sample::FrameSample>::try_new(QueueOrder::Reorder, u32::MAX as usize).unwrap_err();
        assert!(e.to_string().contains("would need 1.2 TB of memory (268 bytes a frame)"), "{e}");
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
