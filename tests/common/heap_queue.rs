//! The reorder queue as the project first had it: a binary min-heap
//! on `(release_ns, ingress_index, slot)` over a slab of items. Kept as the
//! baseline of `benches/queue.rs` and as a second reference in
//! `tests/release_queue/mod.rs` (identical release orders).

#![allow(dead_code)]

use std::cmp::Reverse;
use std::collections::BinaryHeap;

/// The project's first reorder queue: a binary min-heap on
/// `(release_ns, ingress_index, slot)` over a slab of items.
pub struct HeapQueue<T> {
    heap: BinaryHeap<Reverse<(u64, u64, u32)>>,
    slab: Vec<T>,
    free: Vec<u32>,
}

impl<T: Copy + Default> HeapQueue<T> {
    pub fn new(capacity: usize) -> Self {
        let mut v = Vec::with_capacity(capacity);
        v.resize(capacity, Reverse((0, 0, 0)));
        v.clear();
        HeapQueue { heap: BinaryHeap::from(v), slab: vec![T::default(); capacity], free: (0..capacity as u32).rev().collect() }
    }

    #[inline]
    pub fn push(&mut self, release_ns: u64, ingress_index: u64, item: T) -> Result<u64, T> {
        let Some(slot) = self.free.pop() else { return Err(item) };
        self.slab[slot as usize] = item;
        self.heap.push(Reverse((release_ns, ingress_index, slot)));
        Ok(release_ns)
    }

    #[inline]
    pub fn pop(&mut self) -> Option<(u64, u64, T)> {
        let Reverse((release_ns, ingress_index, slot)) = self.heap.pop()?;
        self.free.push(slot);
        Some((release_ns, ingress_index, self.slab[slot as usize]))
    }

    pub fn next_release_ns(&self) -> Option<u64> {
        self.heap.peek().map(|Reverse((t, _, _))| *t)
    }

    pub fn len(&self) -> usize {
        self.heap.len()
    }
}
