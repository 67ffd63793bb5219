//! Micro benchmarks of the core's hot path: the codec, one decision per
//! model, one injector step, the release queue at several depths (criterion;
//! its results under `target/criterion/`). Run with `cargo bench --bench
//! micro`; steal time is printed beside the results. The emulator's loop
//! around them is `benches/emulator.rs`.

use criterion::{criterion_group, criterion_main, Criterion};
use netfi::host::CpuTimes;
use netfi::injector::Injector;
use netfi::model::{AnyModel, StageRng};
use netfi::sample::FrameSample;
use netfi::scenario::{self, ModelSpec, Scenario};
use netfi::scheduler::{QueueOrder, ReleaseQueue};
use rand::SeedableRng;
use std::hint::black_box;

fn model(text: &str) -> AnyModel {
    let spec = scenario::parse_str(text, "bench", "bench").unwrap();
    let m: &ModelSpec = &spec.phases[0].stages[0].model;
    m.build().unwrap()
}

fn decisions(c: &mut Criterion) {
    let cases = [
        ("bernoulli", "[[stage]]\nmodel = \"bernoulli\"\np = 0.3\n"),
        ("ge_lomax PLM-2", "[[stage]]\npreset = \"PLM-2\"\n"),
        ("markov4", "[[stage]]\nmodel = \"markov4\"\np13 = 0.01\np31 = 0.3\np32 = 0.1\np23 = 0.05\np14 = 0.005\n"),
        ("gilbert_elliott", "[[stage]]\nmodel = \"gilbert_elliott\"\np = 0.01\nr = 0.1\nloss_bad = 0.7\nloss_good = 0.001\n"),
        ("delay DLM-2", "[[stage]]\npreset = \"DLM-2\"\n"),
        ("outage CLM-2", "[[stage]]\npreset = \"CLM-2\"\n"),
        ("jitter", "[[stage]]\nmodel = \"jitter\"\nmean_ms = 20\nsd_ms = 5\ndist = \"normal\"\ncorrelation = 0.5\n"),
        ("rate", "[[stage]]\nmodel = \"rate\"\nrate_bit_s = 1e6\n"),
    ];
    // A trace link's file is read by the shell: its schedule given here,
    // one opportunity a millisecond.
    let schedule: String = (1..=1000).map(|ms| format!("{ms}\n")).collect();
    let trace = ModelSpec::LinkTrace(netfi::model::LinkTraceParams::new("bench", netfi::model::Schedule::parse(&schedule).unwrap()));
    let mut g = c.benchmark_group("decide");
    let models = cases.into_iter().map(|(name, text)| (name, model(text))).chain([("trace", trace.build().unwrap())]);
    for (name, mut m) in models {
        let mut rng = StageRng::seed_from_u64(1);
        let mut t = 0u64;
        g.bench_function(name, |b| {
            b.iter(|| {
                t += 1_000_000;
                black_box(m.decide(black_box(t), &mut rng))
            })
        });
    }
    g.finish();
}

fn injector_step(c: &mut Criterion) {
    // Nothing injected: the path every frame takes through `netfi run Normal`.
    let normal = netfi::load::resolve("Normal").unwrap();
    let mut inj: Injector<FrameSample> = Injector::new(Scenario::new(&normal, 1).unwrap(), 1 << 16);
    let mut now = 0u64;
    c.bench_function("injector step Normal (ingress + release, nothing injected)", |b| {
        b.iter(|| {
            now += 1_000;
            let e = inj.ingress(now, FrameSample::ZERO);
            black_box(e);
            black_box(inj.pop_due(now))
        })
    });

    let spec = scenario::parse_str("[[stage]]\npreset = \"PLM-2\"\n[[stage]]\npreset = \"DLM-2\"\n", "bench", "bench").unwrap();
    let mut inj: Injector<FrameSample> = Injector::new(Scenario::new(&spec, 1).unwrap(), 1 << 16);
    let mut now = 0u64;
    // Warm up to the steady-state queue depth (~300 frames at 1 kHz).
    for _ in 0..5_000 {
        now += 1_000_000;
        while inj.pop_due(now).is_some() {}
        inj.ingress(now, FrameSample::ZERO);
    }
    c.bench_function("injector step PLM-2 → DLM-2 (ingress + due releases, 1 kHz)", |b| {
        b.iter(|| {
            now += 1_000_000;
            while let Some(r) = inj.pop_due(now) {
                black_box(r);
            }
            black_box(inj.ingress(now, FrameSample::ZERO))
        })
    });
}

fn queue_depths(c: &mut Criterion) {
    // Steady state at a fixed depth: the queue is filled once, then every
    // iteration pushes one frame and takes the earliest one out, so the depth
    // stays constant. Release times advance by 1 µs per frame plus a jitter
    // spread over twice the depth (as a delay stage produces), so a push
    // lands anywhere in the queue and the reorder queue really reorders.
    let mut g = c.benchmark_group("release queue push+pop");
    for order in [QueueOrder::Fifo, QueueOrder::Reorder] {
        for depth in [1usize, 1_000, 100_000, 1_000_000] {
            let jitter_ns = 2 * depth as u64 * 1_000;
            let release = move |i: u64| i * 1_000 + netfi::scenario::splitmix64(i) % jitter_ns.max(1);
            let mut q = ReleaseQueue::<FrameSample>::new(order, depth + 1);
            let mut i = 0u64;
            while q.len() < depth {
                q.push(release(i), i, FrameSample::ZERO).unwrap();
                i += 1;
            }
            g.bench_function(format!("{order:?} depth {depth}"), |b| {
                b.iter(|| {
                    q.push(release(i), i, FrameSample::ZERO).unwrap();
                    i += 1;
                    black_box(q.pop())
                })
            });
            assert_eq!(q.len(), depth, "the depth stays constant");
        }
    }
    g.finish();
}

fn codec(c: &mut Criterion) {
    use netfi::frame::{ItpFrame, ItpView};
    let frame = ItpFrame { sequence: 7, delx: [12, -3], dely: [4, 5], delz: [-6, 7], qw: [1.0, 1.0], grasp: [30, 60], surgeon_mode: 1, ..ItpFrame::default() }
        .with_checksum();
    let bytes = frame.to_bytes();
    let mut g = c.benchmark_group("codec");
    g.bench_function("encode ItpFrame → 124 bytes", |b| b.iter(|| black_box(black_box(&frame).to_bytes())));
    g.bench_function("decode + verify 124 bytes → ItpFrame", |b| {
        b.iter(|| ItpFrame::parse(&ItpView::new_unchecked(black_box(&bytes[..]))).unwrap())
    });
    g.bench_function("checksum check on the view", |b| b.iter(|| ItpView::new_unchecked(black_box(&bytes[..])).verify_checksum()));
    g.finish();
}

fn report_steal(_c: &mut Criterion) {
    if let (Some(start), Some(now)) = (START.get(), CpuTimes::read()) {
        let s = now.steal_since(start);
        println!("host steal during the benchmarks: {} ms ({:.3}% of CPU time)", s.ms, s.fraction * 100.0);
    }
}

static START: std::sync::OnceLock<CpuTimes> = std::sync::OnceLock::new();

fn start(_c: &mut Criterion) {
    if let Some(t) = CpuTimes::read() {
        let _ = START.set(t);
    }
}

criterion_group! {
    name = benches;
    config = Criterion::default().warm_up_time(std::time::Duration::from_millis(500)).measurement_time(std::time::Duration::from_secs(2));
    targets = start, codec, decisions, injector_step, queue_depths, report_steal
}
criterion_main!(benches);
