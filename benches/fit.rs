//! Fitting throughput: single fits (median of 3 seeds each) and a full
//! regeneration of the fault parameter database, with the host's steal time
//! and load. Run with `cargo bench --bench fit`.
//!
//! Targets: one fit in at most 5 s, the whole database in at most 10 min on
//! 2 cores. The regenerated database must equal the shipped one: the fits are
//! reproducible from their seeds.

use netfi::fit::db::{self, Database};
use netfi::fit::{run, FitRequest, Kind, Metric, Objective};
use netfi::host::StealTimer;
use std::time::Instant;

fn steal(timer: StealTimer) -> String {
    let s = timer.stop();
    format!("steal {} ms ({:.1}%)", s.ms, s.fraction * 100.0)
}

fn load() -> String {
    std::fs::read_to_string("/proc/loadavg").map_or_else(|_| "unavailable".into(), |s| s.trim().to_string())
}

fn main() {
    if std::env::args().any(|a| a == "--list") {
        return; // `cargo test --benches` lists benchmarks; nothing to list.
    }
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    println!("{threads} threads; load average {}", load());

    let single = |label: &str, make: &dyn Fn(u64) -> FitRequest| {
        let timer = StealTimer::start();
        let mut secs: Vec<f64> = (1..=3)
            .map(|seed| {
                let req = make(seed);
                let t = Instant::now();
                let r = run::fit(&req, threads, &|_| {}).unwrap_or_else(|e| panic!("{label}: {e}"));
                assert!(r.within_tolerance, "{label}: {:?}", r.realized);
                t.elapsed().as_secs_f64()
            })
            .collect();
        secs.sort_by(f64::total_cmp);
        println!(
            "fit {label:<34} median {:.3} s (min {:.3}, max {:.3}); {}",
            secs[1],
            secs[0],
            secs[2],
            steal(timer)
        );
    };
    single("loss 1% (the slowest entry)", &|s| FitRequest::new(Kind::Loss, 0.01, s));
    single("loss 30%", &|s| FitRequest::new(Kind::Loss, 0.3, s));
    single("delay 250 ms", &|s| FitRequest::new(Kind::Delay, 250.0, s));
    single("outage 10%", &|s| FitRequest::new(Kind::Outage, 0.1, s));
    single("loss 30% + mean run 3 frames", &|s| {
        FitRequest::new(Kind::Loss, 0.3, s).with_goal(Metric::LossRunMean, 3.0)
    });
    single("delay 300 ms + p99 1000 ms", &|s| {
        FitRequest::new(Kind::Delay, 300.0, s).with_goal(Metric::DelayMsP99, 1000.0)
    });
    single("outage 50%, Monte Carlo objective", &|s| {
        let mut r = FitRequest::new(Kind::Outage, 0.5, s);
        r.objective = Objective::MonteCarlo;
        r
    });

    let plan = db::plan(db::DEFAULT_SEED);
    let timer = StealTimer::start();
    let t = Instant::now();
    let fits: Vec<_> =
        run::fit_many(&plan, threads, &|_, _| {}).into_iter().map(|r| r.expect("every entry fits")).collect();
    let secs = t.elapsed().as_secs_f64();
    let database = Database::from_results(db::DEFAULT_SEED, &fits).expect("every entry within tolerance");
    let frames: u64 = fits.iter().map(|f| f.frames).sum();
    println!(
        "database: {} entries in {secs:.1} s on {threads} threads ({frames} frames confirmed); {}; load average {}",
        fits.len(),
        steal(timer),
        load()
    );
    let shipped = db::embedded().expect("the shipped database parses");
    assert_eq!(&database, shipped, "the regenerated database differs from config/faultdb.toml");
    println!("database: identical to config/faultdb.toml");
}
