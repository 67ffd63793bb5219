//! The reorder queue's push + pop cost against its depth: `ReleaseQueue`
//! with `QueueOrder::Reorder` (a ladder queue; labelled `ladder`) beside the
//! binary heap the project started with, in the same run. Each case fills the queue to a depth once,
//! then every iteration pushes one frame and takes the earliest out, so the
//! depth stays constant.
//!
//! Release times: `dlm2-1kHz` and `dlm2-300kHz` are arrivals every 1 ms or
//! 3.33 µs plus delays drawn from the DLM-2 preset (210 ms + a two-phase
//! hyperexponential); `uniform` is arrivals every 1 µs plus a delay uniform
//! over twice the depth in microseconds. At a depth beyond what the arrival
//! rate and delay hold in flight, the frame taken out is simply the earliest
//! held: the queue is measured, not the stream.
//!
//! `stream` cases are the emulator's own pattern instead: frame `i`
//! arrives at `i × spacing`, and each iteration pushes it and takes out
//! every frame due by its arrival, so the depth is what the rate and the
//! delays hold in flight (printed after each case), in a queue of the
//! capacity the emulator would have: its default (65 536) for shallow
//! streams, far larger than what they hold.
//!
//! Times are the benchmark thread's CPU time (`CLOCK_THREAD_CPUTIME_ID`),
//! not wall time: on a shared machine the wall clock also counts the time
//! the thread waited for a core, which says nothing about the queue (the
//! caches the other processes share are still theirs to disturb, so the
//! load is printed).
//!
//! Beside them, `floor`: no queue at all, only the item's own trip through
//! memory that any queue holding that many frames makes: each iteration
//! copies a 192-byte item out of a slot among `depth` (scattered, and
//! prefetched 16 iterations ahead, as the queue's pops are) and a new one
//! into it. What the floor grows by with the depth is the machine's caches
//! and memory, not a queue's algorithm.
//!
//! `cargo bench --bench queue` (about a minute); `-- ladder`, `-- heap` or
//! `-- floor` narrows it. Load and host steal are printed beside the results.

use criterion::{criterion_group, criterion_main, BatchSize, Criterion};
use netfi::host::CpuTimes;
use netfi::model::{StageRng, Verdict};
use netfi::scenario::{self, ModelSpec};
use netfi::scheduler::{QueueOrder, ReleaseQueue};
use rand::SeedableRng;
use std::hint::black_box;

#[path = "common/cpu_time.rs"]
mod cpu_time;
use cpu_time::ThreadCpu;

#[path = "../tests/common/heap_queue.rs"]
mod heap_queue;
use heap_queue::HeapQueue;

/// The emulator's item: a 192-byte shared-memory sample.
type Item = netfi::sample::FrameSample;

/// The emulator's release queue capacity when none is asked for.
const DEFAULT_CAPACITY: usize = netfi::service::plan::DEFAULT_QUEUE_CAPACITY;

/// Delays are drawn once (2^20 of them, cycled) so the model's cost is not
/// in the measurement.
const DELAYS: usize = 1 << 20;

fn dlm2_delays_ns() -> Vec<u64> {
    let spec = scenario::parse_str("[[stage]]\npreset = \"DLM-2\"\n", "bench", "bench").unwrap();
    let m: &ModelSpec = &spec.phases[0].stages[0].model;
    let mut model = m.build().unwrap();
    let mut rng = StageRng::seed_from_u64(7);
    (0..DELAYS as u64)
        .map(|i| match model.decide(i * 1_000_000, &mut rng) {
            Verdict::Pass { delay_ns } => delay_ns,
            _ => unreachable!("a delay stage only passes"),
        })
        .collect()
}

/// Release times of frame `i`: arrival + delay.
#[derive(Clone)]
struct Releases {
    spacing_ns: u64,
    delays_ns: std::sync::Arc<Vec<u64>>,
}

impl Releases {
    #[inline]
    fn at(&self, i: u64) -> u64 {
        i * self.spacing_ns + self.delays_ns[i as usize & (DELAYS - 1)]
    }
}

fn uniform(depth: usize) -> Releases {
    let spread_ns = 2 * depth as u64 * 1_000;
    let delays = (0..DELAYS as u64).map(|i| netfi::scenario::splitmix64(i) % spread_ns.max(1)).collect();
    Releases { spacing_ns: 1_000, delays_ns: std::sync::Arc::new(delays) }
}

/// The queue, then the heap, at a constant `depth`.
fn pair<I: Copy + Default + std::fmt::Debug>(g: &mut criterion::BenchmarkGroup<'_, ThreadCpu>, name: &str, depth: usize, releases: &Releases, item: I) {
    let mut q = ReleaseQueue::<I>::new(QueueOrder::Reorder, depth + 1);
    let mut i = 0u64;
    while q.len() < depth {
        q.push(releases.at(i), i, item).unwrap();
        i += 1;
    }
    // Each popped item goes into a loan, a place of the caller's, as the
    // emulator's release copies it into the publisher's: the queue reads
    // it in place (`pop_ref`), the heap hands it out by value.
    let mut loan = item;
    g.bench_function(format!("ladder {name}"), |b| {
        b.iter(|| {
            q.push(releases.at(i), i, item).unwrap();
            i += 1;
            let r = q.pop_ref().unwrap();
            loan = *r.item;
            black_box(&mut loan);
            r.release_ns
        })
    });
    assert_eq!(q.len(), depth, "the depth stays constant");
    let mut q = HeapQueue::<I>::new(depth + 1);
    let mut i = 0u64;
    while q.len() < depth {
        q.push(releases.at(i), i, item).unwrap();
        i += 1;
    }
    g.bench_function(format!("heap {name}"), |b| {
        b.iter(|| {
            q.push(releases.at(i), i, item).unwrap();
            i += 1;
            let (release_ns, _, popped) = q.pop().unwrap();
            loan = popped;
            black_box(&mut loan);
            release_ns
        })
    });
    assert_eq!(q.len(), depth, "the depth stays constant");
}

/// A stream through the queue, then through the heap (see the module's
/// text): each iteration one arrival and every release due by then.
fn stream(g: &mut criterion::BenchmarkGroup<'_, ThreadCpu>, name: &str, capacity: usize, releases: &Releases) {
    let item = Item::ZERO;
    let mut loan = item;
    let mut q = ReleaseQueue::<Item>::new(QueueOrder::Reorder, capacity);
    let mut i = 0u64;
    g.bench_function(format!("ladder stream {name}"), |b| {
        b.iter(|| {
            let now_ns = i * releases.spacing_ns;
            q.push(releases.at(i), i, item).unwrap();
            i += 1;
            while let Some(r) = q.pop_due_ref(now_ns) {
                loan = *r.item;
                black_box(&mut loan);
            }
        })
    });
    let held = q.len();
    let mut q = HeapQueue::<Item>::new(capacity);
    let mut i = 0u64;
    g.bench_function(format!("heap stream {name}"), |b| {
        b.iter(|| {
            let now_ns = i * releases.spacing_ns;
            q.push(releases.at(i), i, item).unwrap();
            i += 1;
            while q.next_release_ns().is_some_and(|t| t <= now_ns) {
                loan = q.pop().unwrap().2;
                black_box(&mut loan);
            }
        })
    });
    println!("stream {name}: {held} frames held at the end (heap {})", q.len());
}

/// The memory floor at `depth` (see the module's text): the items' slots
/// on cache lines and huge pages, as the queue keeps them.
fn floor(g: &mut criterion::BenchmarkGroup<'_, ThreadCpu>, depth: usize) {
    #[derive(Clone, Copy, Default)]
    #[repr(C, align(64))]
    struct Lined(Item);
    let slots_n = depth.next_power_of_two();
    let mut slots: Vec<Lined> = Vec::with_capacity(slots_n);
    advise_huge_pages(&mut slots);
    slots.resize(slots_n, Lined::default());
    let mask = slots_n as u64 - 1;
    // A fixed scatter over the slots (Fibonacci hashing of the iteration).
    let slot = move |k: u64| ((k.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 20) & mask) as usize;
    let item = Item::ZERO;
    let mut loan = item;
    let mut k = 0u64;
    g.bench_function(format!("floor depth {depth}"), |b| {
        b.iter(|| {
            prefetch(&slots[slot(k + 16)]);
            let s = slot(k);
            loan = slots[s].0;
            black_box(&mut loan);
            slots[s].0 = item;
            k += 1;
        })
    });
}

fn prefetch<X>(p: &X) {
    #[cfg(target_arch = "x86_64")]
    for off in (0..size_of::<X>()).step_by(64) {
        // SAFETY: a prefetch is a hint; it cannot fault.
        unsafe { core::arch::x86_64::_mm_prefetch::<{ core::arch::x86_64::_MM_HINT_T0 }>((p as *const X).cast::<i8>().wrapping_add(off)) };
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = p;
}

#[cfg(target_os = "linux")]
fn advise_huge_pages<X>(v: &mut Vec<X>) {
    const HUGE: usize = 2 << 20;
    let start = v.as_mut_ptr() as usize;
    let (from, to) = (start.next_multiple_of(HUGE), (start + v.capacity() * size_of::<X>()) / HUGE * HUGE);
    if to > from {
        // SAFETY: advice on memory this vector owns and has not written.
        unsafe { libc::madvise(from as *mut libc::c_void, to - from, libc::MADV_HUGEPAGE) };
    }
}

#[cfg(not(target_os = "linux"))]
fn advise_huge_pages<X>(_v: &mut Vec<X>) {}

fn queue_depths(c: &mut Criterion<ThreadCpu>) {
    let dlm2 = std::sync::Arc::new(dlm2_delays_ns());
    let mut g = c.benchmark_group("reorder push+pop");
    for depth in [1usize, 1_000, 100_000, 1_000_000] {
        let cases = [
            ("dlm2-1kHz", Releases { spacing_ns: 1_000_000, delays_ns: dlm2.clone() }),
            ("dlm2-300kHz", Releases { spacing_ns: 3_333, delays_ns: dlm2.clone() }),
            ("uniform", uniform(depth)),
        ];
        for (dist, releases) in cases {
            pair(&mut g, &format!("{dist} depth {depth}"), depth, &releases, Item::ZERO);
        }
        floor(&mut g, depth);
        // The same with an 8-byte item: what the 192-byte sample's own
        // cache misses (written at push, read at pop) add at depth.
        let releases = Releases { spacing_ns: 3_333, delays_ns: dlm2.clone() };
        pair(&mut g, &format!("dlm2-300kHz depth {depth} u64 item"), depth, &releases, 0u64);
    }
    let uniform_ms = |ms: u64| {
        let spread_ns = ms * 1_000_000;
        let delays = (0..DELAYS as u64).map(|i| netfi::scenario::splitmix64(i) % spread_ns).collect();
        Releases { spacing_ns: 3_333, delays_ns: std::sync::Arc::new(delays) }
    };
    stream(&mut g, &format!("dlm2-1kHz capacity {DEFAULT_CAPACITY}"), DEFAULT_CAPACITY, &Releases { spacing_ns: 1_000_000, delays_ns: dlm2.clone() });
    stream(&mut g, &format!("uniform-1ms-300kHz capacity {DEFAULT_CAPACITY}"), DEFAULT_CAPACITY, &uniform_ms(1));
    stream(&mut g, &format!("uniform-10ms-300kHz capacity {DEFAULT_CAPACITY}"), DEFAULT_CAPACITY, &uniform_ms(10));
    stream(&mut g, "dlm2-300kHz capacity 131072", 1 << 17, &Releases { spacing_ns: 3_333, delays_ns: dlm2.clone() });
    g.finish();
    // Construction (allocating and touching every slot) is start-up cost;
    // shown once so a capacity's price is visible.
    let mut g = c.benchmark_group("reorder construction");
    g.sample_size(10);
    g.bench_function("ladder capacity 1048576", |b| {
        b.iter_batched(|| (), |_| ReleaseQueue::<Item>::new(QueueOrder::Reorder, 1 << 20), BatchSize::PerIteration)
    });
    g.finish();
}

fn report_host(_c: &mut Criterion<ThreadCpu>) {
    if let (Some(start), Some(now)) = (START.get(), CpuTimes::read()) {
        let s = now.steal_since(start);
        println!("host steal during the benchmarks: {} ms ({:.3}% of CPU time)", s.ms, s.fraction * 100.0);
    }
    if let Ok(load) = std::fs::read_to_string("/proc/loadavg") {
        println!("load average at the end: {}", load.trim());
    }
}

static START: std::sync::OnceLock<CpuTimes> = std::sync::OnceLock::new();

fn start(_c: &mut Criterion<ThreadCpu>) {
    if let Some(t) = CpuTimes::read() {
        let _ = START.set(t);
    }
    if let Ok(load) = std::fs::read_to_string("/proc/loadavg") {
        println!("load average at the start: {}", load.trim());
    }
}

criterion_group! {
    name = benches;
    config = Criterion::default()
        .with_measurement(ThreadCpu)
        .warm_up_time(std::time::Duration::from_millis(300))
        .measurement_time(std::time::Duration::from_secs(1))
        .sample_size(20);
    targets = start, queue_depths, report_host
}
criterion_main!(benches);
