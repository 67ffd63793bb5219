//! The release queue against reference models.
//!
//! - Property tests: random sequences of pushes, pops and due-pops (ties,
//!   times near `u64::MAX`, times far apart, pushes earlier than frames
//!   already released, a full queue) against a list sorted by
//!   `(release_ns, ingress_index)` (or, for `Fifo`, a plain list with the
//!   ordered-transport rule); every step compares results, length and the
//!   next release time.
//! - Identical releases: the DLM-2 delays of a real scenario, pushed and
//!   released in time as the emulator does, give the same sequence from the
//!   queue as from a binary heap.


use crate::common::heap_queue::HeapQueue;
use netfi::scenario::{self, Decision, Scenario};
use netfi::scheduler::{Full, QueueOrder, ReleaseQueue, Released};
use proptest::prelude::*;

#[derive(Debug, Clone)]
enum Op {
    /// Push at `base + offset` (see [`Base`]); `ingress` from a counter
    /// unless `ingress_random` is given.
    Push { base: Base, offset_ns: u64, ingress_random: Option<u64> },
    Pop,
    /// Pop everything due at `base + offset`.
    PopDue { base: Base, offset_ns: u64 },
    /// Time moves: `now += step`.
    Advance { step_ns: u64 },
}

/// Where a time is taken from: the simulated clock (as the injector does),
/// zero, or just below `u64::MAX`.
#[derive(Debug, Clone, Copy)]
enum Base {
    Now,
    Zero,
    Top,
}

fn offset() -> impl Strategy<Value = u64> {
    prop_oneof![
        // Ties and neighbours within one level-0 slot.
        3 => 0u64..4,
        3 => 0u64..200,
        // One level up and further, across digit boundaries.
        2 => 0u64..70_000,
        // DLM-like delays (up to seconds).
        2 => 0u64..2_000_000_000,
        // Anywhere: far beyond any row of buckets.
        1 => any::<u64>(),
    ]
}

fn op() -> impl Strategy<Value = Op> {
    let base = prop_oneof![6 => Just(Base::Now), 1 => Just(Base::Zero), 1 => Just(Base::Top)];
    prop_oneof![
        5 => (base.clone(), offset(), proptest::option::weighted(0.2, any::<u64>()))
            .prop_map(|(base, offset_ns, ingress_random)| Op::Push { base, offset_ns, ingress_random }),
        3 => Just(Op::Pop),
        2 => (base, offset()).prop_map(|(base, offset_ns)| Op::PopDue { base, offset_ns }),
        2 => offset().prop_map(|step_ns| Op::Advance { step_ns }),
    ]
}

fn time(base: Base, offset_ns: u64, now_ns: u64) -> u64 {
    match base {
        Base::Now => now_ns.saturating_add(offset_ns),
        Base::Zero => offset_ns,
        Base::Top => u64::MAX - offset_ns % 1_000,
    }
}

/// The reference: held frames as `(release_ns, ingress_index, item)`.
#[derive(Default)]
struct Model {
    held: Vec<(u64, u64, u64)>,
    last_release_ns: u64,
}

impl Model {
    /// The index of the next frame out.
    fn next(&self, order: QueueOrder) -> Option<usize> {
        match order {
            QueueOrder::Fifo => (!self.held.is_empty()).then_some(0),
            QueueOrder::Reorder => (0..self.held.len()).min_by_key(|&i| (self.held[i].0, self.held[i].1)),
        }
    }
}

fn check(order: QueueOrder, capacity: usize, ops: &[Op]) -> Result<(), TestCaseError> {
    let mut q = ReleaseQueue::<u64>::new(order, capacity);
    let mut model = Model::default();
    let mut now_ns = 0u64;
    let mut counter = 0u64;
    let take = |model: &mut Model, got: Option<Released<u64>>| -> Result<(), TestCaseError> {
        match model.next(order) {
            None => prop_assert_eq!(got, None),
            Some(i) => {
                let got = got.ok_or_else(|| TestCaseError::fail("the queue is empty, the model is not"))?;
                let (t, ingress, _) = model.held[i];
                prop_assert_eq!((got.release_ns, got.ingress_index), (t, ingress));
                // Equal (release, ingress) pairs (random ingress indices may
                // repeat) leave in either order: remove the one returned.
                let j = model.held.iter().position(|&h| h == (t, ingress, got.item));
                let j = j.ok_or_else(|| TestCaseError::fail(format!("item {} not held at ({t}, {ingress})", got.item)))?;
                model.held.remove(j);
            }
        }
        Ok(())
    };
    for (step, op) in ops.iter().enumerate() {
        match *op {
            Op::Push { base, offset_ns, ingress_random } => {
                let t = time(base, offset_ns, now_ns);
                let ingress = ingress_random.unwrap_or(counter);
                counter += 1;
                let item = step as u64;
                let got = q.push(t, ingress, item);
                if model.held.len() == capacity {
                    prop_assert_eq!(got, Err(Full(item)));
                } else {
                    let t = match order {
                        QueueOrder::Fifo => t.max(model.last_release_ns),
                        QueueOrder::Reorder => t,
                    };
                    model.last_release_ns = t;
                    prop_assert_eq!(got, Ok(t));
                    model.held.push((t, ingress, item));
                }
            }
            Op::Pop => take(&mut model, q.pop())?,
            Op::PopDue { base, offset_ns } => {
                let due_ns = time(base, offset_ns, now_ns);
                loop {
                    let due = model.next(order).is_some_and(|i| model.held[i].0 <= due_ns);
                    let got = q.pop_due(due_ns);
                    if !due {
                        prop_assert_eq!(got, None);
                        break;
                    }
                    take(&mut model, got)?;
                }
            }
            Op::Advance { step_ns } => now_ns = now_ns.saturating_add(step_ns % 10_000_000_000),
        }
        prop_assert_eq!(q.len(), model.held.len());
        prop_assert_eq!(q.next_release_ns(), model.next(order).map(|i| model.held[i].0), "after step {}: {:?}", step, op);
    }
    // Draining gives the rest in order.
    while !model.held.is_empty() {
        take(&mut model, q.pop())?;
    }
    prop_assert_eq!(q.pop(), None);
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 512, ..ProptestConfig::default() })]

    #[test]
    fn reorder_matches_the_sorted_model(capacity in 1usize..40, ops in proptest::collection::vec(op(), 0..300)) {
        check(QueueOrder::Reorder, capacity, &ops)?;
    }

    #[test]
    fn reorder_with_room_matches_the_sorted_model(ops in proptest::collection::vec(op(), 0..600)) {
        check(QueueOrder::Reorder, 1000, &ops)?;
    }

    /// Pushes and pops in short runs, the pushes' times before everything
    /// held, at the present, or far ahead, on a queue first filled deep
    /// enough that the row holds frames: a frame just pushed leaves in
    /// order and counts in the next release time, wherever it lands (a new
    /// earliest frame, a tie, the front, the row or past it), also when
    /// the frames just pushed are the only ones held.
    #[test]
    fn reorder_with_frames_just_pushed_matches_the_sorted_model(
        fill in 0usize..300,
        runs in proptest::collection::vec((proptest::collection::vec(staged_push(), 0..7), 0usize..7, any::<bool>()), 0..80),
    ) {
        check(QueueOrder::Reorder, 2000, &runs_of(fill, &runs))?;
    }

    #[test]
    fn fifo_matches_the_ordered_model(capacity in 1usize..40, ops in proptest::collection::vec(op(), 0..300)) {
        check(QueueOrder::Fifo, capacity, &ops)?;
    }
}

/// A push's time relative to what a queue of [`runs_of`] holds: before
/// every frame (its fill starts at 10 ms), a tie with the fill's first
/// frame, near the present, or far ahead.
fn staged_push() -> impl Strategy<Value = Op> {
    prop_oneof![
        3 => (0u64..10_000_000).prop_map(|offset_ns| Op::Push { base: Base::Zero, offset_ns, ingress_random: None }),
        1 => Just(Op::Push { base: Base::Zero, offset_ns: 10_000_000, ingress_random: None }),
        3 => (0u64..5_000).prop_map(|offset_ns| Op::Push { base: Base::Now, offset_ns, ingress_random: None }),
        2 => (0u64..400_000_000).prop_map(|offset_ns| Op::Push { base: Base::Now, offset_ns, ingress_random: None }),
    ]
}

/// `fill` frames 10 ms and more ahead (a delay spread of about 5 ms), then
/// each run: its pushes, `pops` pops, and a due-pop at the present when
/// the flag is set; time moves 3 µs a run.
fn runs_of(fill: usize, runs: &[(Vec<Op>, usize, bool)]) -> Vec<Op> {
    let mut ops: Vec<Op> = (0..fill as u64)
        .map(|i| Op::Push { base: Base::Zero, offset_ns: 10_000_000 + netfi::scenario::splitmix64(i) % 5_000_000, ingress_random: None })
        .collect();
    for (pushes, pops, due) in runs {
        ops.extend(pushes.iter().cloned());
        ops.extend(std::iter::repeat_n(Op::Pop, *pops));
        if *due {
            ops.push(Op::PopDue { base: Base::Now, offset_ns: 0 });
        }
        ops.push(Op::Advance { step_ns: 3_000 });
    }
    ops
}

/// A frame just pushed, due before every frame a deep queue holds, leaves
/// first and its time is the next release time; a tie with the earliest
/// frame leaves in ingress order; frames pushed into an empty queue leave
/// in order.
#[test]
fn frames_just_pushed_leave_in_order() {
    let mut q = ReleaseQueue::<u64>::new(QueueOrder::Reorder, 1 << 12);
    for i in 0..1000u64 {
        q.push(1_000_000 + netfi::scenario::splitmix64(i) % 1_000_000, i, i).unwrap();
    }
    q.push(500, 1000, 1000).unwrap();
    assert_eq!(q.next_release_ns(), Some(500));
    assert_eq!(q.pop_due(499), None);
    assert_eq!(q.pop_due(500).map(|r| (r.release_ns, r.item)), Some((500, 1000)));
    // A tie with the earliest frame held: ingress order decides.
    let first = q.next_release_ns().unwrap();
    q.push(first, 1001, 1001).unwrap();
    let r = q.pop().unwrap();
    assert!(r.release_ns == first && r.ingress_index < 1000, "{r:?}");
    let r = q.pop().unwrap();
    assert_eq!((r.release_ns, r.ingress_index), (first, 1001));
    while q.pop().is_some() {}
    for (i, t) in [30u64, 10, 20].into_iter().enumerate() {
        q.push(t, i as u64, i as u64).unwrap();
    }
    assert_eq!(q.next_release_ns(), Some(10));
    let got: Vec<u64> = std::iter::from_fn(|| q.pop_due(u64::MAX)).map(|r| r.release_ns).collect();
    assert_eq!(got, vec![10, 20, 30]);
    assert_eq!(q.next_release_ns(), None);
}

/// Many frames on one nanosecond, pushed in shuffled ingress order and
/// cascaded from higher levels: they leave in ingress order.
#[test]
fn ties_leave_in_ingress_order_whatever_the_push_order() {
    // 4 000 and 10 000 ties fill one bucket: counted into one sub-bucket,
    // where the insertion sort gives up and sorts them by comparison;
    // 70 000, more than a bucket is counted for, sorted by comparison.
    for ties in [4_000u64, 10_000, 70_000] {
        let mut q = ReleaseQueue::<u64>::new(QueueOrder::Reorder, 131_072);
        let t = 5_000_000_000u64;
        q.push(1, 0, 0).unwrap(); // keeps the front low, so the ties sit in one later bucket
        let mut ingress: Vec<u64> = (0..ties).map(|i| netfi::scenario::splitmix64(i) % 1_000_000).collect();
        for (i, &g) in ingress.iter().enumerate() {
            q.push(t, g, i as u64).unwrap();
        }
        assert_eq!(q.pop().map(|r| r.release_ns), Some(1));
        ingress.sort();
        let got: Vec<u64> = std::iter::from_fn(|| q.pop_due(t)).map(|r| r.ingress_index).collect();
        let first_wrong = got.iter().zip(&ingress).position(|(g, w)| g != w);
        assert_eq!((got.len(), first_wrong), (ingress.len(), None), "{ties} ties: length, and the first frame out of ingress order");
    }
}

/// Pushes and due-pops in simulated time, as the emulator's loop makes them,
/// through the queue and through the binary heap: the same releases.
fn same_as_the_heap(scenario_text: &str, spacing_ns: u64, frames: u64, seed: u64) -> u64 {
    let spec = scenario::parse_str(scenario_text, "queue.toml", "queue").unwrap();
    let mut sc = Scenario::new(&spec, seed).unwrap();
    let capacity = 1 << 18;
    let mut queue = ReleaseQueue::<u64>::new(QueueOrder::Reorder, capacity);
    let mut heap = HeapQueue::<u64>::new(capacity);
    let mut released = 0u64;
    let mut release = |now: u64, queue: &mut ReleaseQueue<u64>, heap: &mut HeapQueue<u64>| {
        assert_eq!(queue.next_release_ns(), heap.next_release_ns(), "at {now} ns");
        while let Some(r) = queue.pop_due(now) {
            let (t, ingress, item) = heap.pop().expect("the heap holds as many");
            assert_eq!((r.release_ns, r.ingress_index, r.item), (t, ingress, item), "release {released}");
            assert!(t <= now);
            released += 1;
        }
        assert!(heap.next_release_ns().is_none_or(|t| t > now));
    };
    for i in 0..frames {
        let now = i * spacing_ns;
        release(now, &mut queue, &mut heap);
        if let Decision::Pass { delay_ns } = sc.decide(now, now) {
            let t = now + delay_ns;
            assert_eq!(queue.push(t, i, i), heap.push(t, i, i).map_err(Full));
        }
    }
    release(u64::MAX, &mut queue, &mut heap);
    assert!(queue.is_empty() && heap.len() == 0);
    released
}

#[test]
fn dlm2_releases_are_the_heaps_at_1_khz_and_300_khz() {
    let text = "[[stage]]\npreset = \"PLM-2\"\n[[stage]]\npreset = \"DLM-2\"\n";
    assert!(same_as_the_heap(text, 1_000_000, 200_000, 11) > 100_000);
    assert!(same_as_the_heap(text, 3_333, 400_000, 12) > 200_000);
    // Phases and a uniform jitter wide enough to reorder often.
    let phases = "[[phase]]\npreset = \"DLM-3\"\n[[phase]]\nstart_s = 60\n[[phase.stage]]\nmodel = \"delay\"\nmin_ms = 1\ndist = \"uniform\"\njitter_ms = 40\n";
    assert!(same_as_the_heap(phases, 1_000_000, 150_000, 13) > 100_000);
}

/// A fast stream whose delay spread shrinks a thousandfold, then bursts on
/// one release time: the row's width, chosen from the wide phase, no
/// longer fits; the releases are still the heap's.
#[test]
fn releases_are_the_heaps_when_the_spread_changes() {
    let text = "[[phase]]\n[[phase.stage]]\nmodel = \"delay\"\nmin_ms = 1\ndist = \"uniform\"\njitter_ms = 200\n\
                [[phase]]\nstart_s = 1.5\n[[phase.stage]]\nmodel = \"delay\"\nmin_ms = 0.01\ndist = \"uniform\"\njitter_ms = 0.2\n\
                [[phase]]\nstart_s = 3\npreset = \"CLM-2\"\n";
    assert!(same_as_the_heap(text, 10_000, 450_000, 14) > 300_000);
}

/// A fast stream whose delays mix what the queue's parts handle apart: most
/// a few hundred milliseconds (the row), some microseconds (the front, or
/// earlier than everything held), some hours (far, through many rebuilds),
/// and some the same nanosecond as the frame before (ties); released in
/// time as the emulator does, the same releases as the binary heap's.
#[test]
fn mixed_delays_release_as_the_heap_does() {
    let capacity = 1 << 16;
    let mut queue = ReleaseQueue::<u64>::new(QueueOrder::Reorder, capacity);
    let mut heap = HeapQueue::<u64>::new(capacity);
    let (mut released, mut last_t) = (0u64, 0u64);
    for i in 0..300_000u64 {
        let now = i * 3_000;
        assert_eq!(queue.next_release_ns(), heap.next_release_ns(), "at {now} ns");
        while let Some(r) = queue.pop_due(now) {
            assert_eq!(Some((r.release_ns, r.ingress_index, r.item)), heap.pop(), "release {released}");
            released += 1;
        }
        let x = netfi::scenario::splitmix64(i);
        let t = match x % 100 {
            0..=89 => now + x / 100 % 300_000_000,
            90..=94 => now + x / 100 % 10_000,
            95..=98 => last_t,
            _ => now + 3_600_000_000_000 + x / 100 % 3_600_000_000_000,
        };
        last_t = t;
        assert_eq!(queue.push(t, i, i), heap.push(t, i, i).map_err(Full));
    }
    while let Some(r) = queue.pop() {
        assert_eq!(Some((r.release_ns, r.ingress_index, r.item)), heap.pop(), "release {released}");
        released += 1;
    }
    assert_eq!(heap.len(), 0);
    assert!(released > 250_000);
}
