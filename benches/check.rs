//! `scenario check` throughput: 10^7 frames of PLM-2 → DLM-2 in simulated
//! time, timed end to end (median of 3 runs), with the host steal time.
//! Run with `cargo bench --bench check`.

use netfi::check::{self, Arrivals};
use netfi::host::StealTimer;
use netfi::scenario::{self, Scenario};
use std::time::Instant;

fn main() {
    if std::env::args().any(|a| a == "--list") {
        return; // `cargo test --benches` lists benchmarks; nothing to list.
    }
    let spec = scenario::parse_str("[[stage]]\npreset = \"PLM-2\"\n[[stage]]\npreset = \"DLM-2\"\n", "bench", "bench").unwrap();
    let arrivals = Arrivals::Rate { frames: 10_000_000, rate_hz: 1000.0 };
    let steal_timer = StealTimer::start();
    let mut secs: Vec<f64> = (0..3)
        .map(|seed| {
            let t = Instant::now();
            let r = check::run(Scenario::new(&spec, seed).unwrap(), &arrivals, 1 << 16, |_| {});
            let s = t.elapsed().as_secs_f64();
            assert_eq!(r.frames, 10_000_000);
            s
        })
        .collect();
    secs.sort_by(f64::total_cmp);
    let s = steal_timer.stop();
    let steal = format!("{} ms ({:.2}%)", s.ms, s.fraction * 100.0);
    println!(
        "scenario check PLM-2 → DLM-2, 10^7 frames: median {:.3} s (min {:.3}, max {:.3}; {:.0} ns/frame); steal {steal}",
        secs[1], secs[0], secs[2], secs[1] * 1e9 / 1e7
    );
}
