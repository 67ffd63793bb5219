//! The release queue: frames held by the injector until their scheduled
//! release time, with a fixed capacity chosen at start-up.
//!
//! Two orders (SPEC §3.4). `Fifo` is a ring: releases leave in the order they
//! were pushed, and a push whose time is earlier than the last one is held
//! until that one (`release = max(own, previous)`), as an ordered transport
//! does. `Reorder` is a binary min-heap on `(release_ns, ingress_index)` over
//! a slab of items: each frame leaves at its own time, ties in ingress order.
//! Neither allocates after construction: a push onto a full queue hands the
//! item back as [`Full`] so the caller records the fate.

use std::cmp::Reverse;
use std::collections::{BinaryHeap, VecDeque};

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

#[derive(Debug, Clone)]
enum Inner<T> {
    Fifo { ring: VecDeque<Released<T>>, last_release_ns: u64 },
    Reorder { heap: BinaryHeap<Reverse<(u64, u64, u32)>>, slab: Vec<T>, free: Vec<u32> },
}

/// A fixed-capacity release queue.
#[derive(Debug, Clone)]
pub struct ReleaseQueue<T> {
    inner: Inner<T>,
    capacity: usize,
}

/// The largest capacity a queue accepts (slab indices are `u32`).
pub const MAX_CAPACITY: usize = u32::MAX as usize;

impl<T: Copy + Default> ReleaseQueue<T> {
    /// A queue holding at most `capacity` frames (1..=[`MAX_CAPACITY`]); all
    /// memory is allocated here.
    pub fn new(order: QueueOrder, capacity: usize) -> Self {
        assert!((1..=MAX_CAPACITY).contains(&capacity), "release queue capacity {capacity} out of 1..={MAX_CAPACITY}");
        // Every slot is written once here, so the memory is resident before
        // the first frame: a fresh page touched on the hot path would cost a
        // page fault (microseconds, more in a VM) to the frame that lands on it.
        let inner = match order {
            QueueOrder::Fifo => {
                let mut ring = VecDeque::with_capacity(capacity);
                ring.resize(capacity, Released { release_ns: 0, ingress_index: 0, item: T::default() });
                ring.clear();
                Inner::Fifo { ring, last_release_ns: 0 }
            }
            QueueOrder::Reorder => Inner::Reorder {
                heap: {
                    let mut v = Vec::with_capacity(capacity);
                    v.resize(capacity, Reverse((0, 0, 0)));
                    v.clear();
                    BinaryHeap::from(v)
                },
                slab: vec![T::default(); capacity],
                // Popped from the end: slot 0 is used first.
                free: (0..capacity as u32).rev().collect(),
            },
        };
        ReleaseQueue { inner, capacity }
    }

    pub fn order(&self) -> QueueOrder {
        match self.inner {
            Inner::Fifo { .. } => QueueOrder::Fifo,
            Inner::Reorder { .. } => QueueOrder::Reorder,
        }
    }

    pub fn capacity(&self) -> usize {
        self.capacity
    }

    pub fn len(&self) -> usize {
        match &self.inner {
            Inner::Fifo { ring, .. } => ring.len(),
            Inner::Reorder { heap, .. } => heap.len(),
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
            Inner::Reorder { heap, slab, free } => {
                let Some(slot) = free.pop() else {
                    return Err(Full(item));
                };
                slab[slot as usize] = item;
                heap.push(Reverse((release_ns, ingress_index, slot)));
                Ok(release_ns)
            }
        }
    }

    /// The earliest scheduled release, if any frame is held.
    #[inline]
    pub fn next_release_ns(&self) -> Option<u64> {
        match &self.inner {
            Inner::Fifo { ring, .. } => ring.front().map(|r| r.release_ns),
            Inner::Reorder { heap, .. } => heap.peek().map(|Reverse((t, _, _))| *t),
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
            Inner::Reorder { heap, slab, free } => {
                let Reverse((release_ns, ingress_index, slot)) = heap.pop()?;
                free.push(slot);
                Some(Released { release_ns, ingress_index, item: slab[slot as usize] })
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
}
