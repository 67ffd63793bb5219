//! Fitting's speed: single fits (each with `--seeds` seeds), then a full
//! regeneration of the fault parameter database, which must equal the
//! shipped `config/faultdb.toml` (the fits are reproducible from their
//! seeds).
//!
//! ```sh
//! cargo bench --bench fit                       # single fits and the database (minutes)
//! cargo bench --bench fit -- --no-database
//! ```

#[path = "common/mod.rs"]
mod common;

use anyhow::{anyhow, ensure, Result};
use common::args::{check_interrupted, Common};
use common::host::HostTimer;
use common::out::Out;
use common::table::Spread;
use netfi::fit::db::{self, Database};
use netfi::fit::{run, FitRequest, Kind, Metric, Objective};
use serde::Serialize;
use serde_json::json;
use std::fmt::Write as _;
use std::time::Instant;

/// `cargo bench --bench fit -- [FLAGS]`.
#[derive(Debug, clap::Parser, Serialize)]
#[command(name = "fit", bin_name = "cargo bench --bench fit --", about = "Single fits and a full regeneration of the fault parameter database")]
struct Args {
    #[command(flatten)]
    common: Common,
    /// Seeds of each single fit
    #[arg(long, default_value_t = 3)]
    seeds: u64,
    /// Threads [default: every core]
    #[arg(long)]
    threads: Option<usize>,
    /// Leave out the database's regeneration
    #[arg(long)]
    no_database: bool,
}

/// A single fit: its name, and its request for a seed.
type Case = (&'static str, Box<dyn Fn(u64) -> FitRequest>);

/// The single fits.
fn cases() -> Vec<Case> {
    vec![
        ("loss 1% (the slowest entry)", Box::new(|s| FitRequest::new(Kind::Loss, 0.01, s))),
        ("loss 30%", Box::new(|s| FitRequest::new(Kind::Loss, 0.3, s))),
        ("delay 250 ms", Box::new(|s| FitRequest::new(Kind::Delay, 250.0, s))),
        ("outage 10%", Box::new(|s| FitRequest::new(Kind::Outage, 0.1, s))),
        ("loss 30% + mean run 3 frames", Box::new(|s| FitRequest::new(Kind::Loss, 0.3, s).with_goal(Metric::LossRunMean, 3.0))),
        ("delay 300 ms + p99 1000 ms", Box::new(|s| FitRequest::new(Kind::Delay, 300.0, s).with_goal(Metric::DelayMsP99, 1000.0))),
        (
            "outage 50%, Monte Carlo objective",
            Box::new(|s| {
                let mut r = FitRequest::new(Kind::Outage, 0.5, s);
                r.objective = Objective::MonteCarlo;
                r
            }),
        ),
    ]
}

fn main() {
    common::args::main("fit", "fitting's speed (minutes)", run);
}

fn run(a: Args) -> Result<()> {
    ensure!(a.seeds >= 1, "--seeds must be at least 1");
    let out = Out::create(&a.common, "fit")?;
    let threads = a.threads.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    let mut md = format!("{threads} threads; median (least – largest) over {} seeds.\n\n| fit | seconds | steal |\n|---|---|---|\n", a.seeds);
    let mut singles = Vec::new();
    for (label, make) in cases() {
        check_interrupted()?;
        let host = HostTimer::now();
        let mut secs = Vec::new();
        for seed in 1..=a.seeds {
            let t = Instant::now();
            let r = run::fit(&make(seed), threads, &|_| {}).map_err(|e| anyhow!("{label}, seed {seed}: {e}"))?;
            ensure!(r.within_tolerance, "{label}, seed {seed}: outside the tolerance ({:?})", r.realized);
            secs.push(t.elapsed().as_secs_f64());
        }
        let (s, host) = (Spread::of(secs.iter().copied()), host.stop());
        let cell = s.map_or("–".into(), |s| format!("{:.3} ({:.3} – {:.3})", s.median, s.min, s.max));
        println!("  {label:<36} {cell} s; {}", host.line());
        let _ = writeln!(md, "| {label} | {cell} | {:.2}% |", host.steal_fraction * 100.0);
        singles.push(json!({"fit": label, "seconds": s, "each_s": secs, "host": host}));
    }
    let database = if a.no_database { serde_json::Value::Null } else { database(threads, &mut md)? };
    out.finish(&a, json!({"threads": threads, "single": singles, "database": database}), &md)
}

/// Regenerates the database and checks it against the shipped one.
fn database(threads: usize, md: &mut String) -> Result<serde_json::Value> {
    check_interrupted()?;
    let plan = db::plan(db::DEFAULT_SEED);
    let (host, t) = (HostTimer::now(), Instant::now());
    let fits = run::fit_many(&plan, threads, &|_, _| {}).into_iter().collect::<Result<Vec<_>, _>>().map_err(|e| anyhow!("an entry did not fit: {e}"))?;
    let (secs, host) = (t.elapsed().as_secs_f64(), host.stop());
    let regenerated = Database::from_results(db::DEFAULT_SEED, &fits).map_err(|e| anyhow!("{e}"))?;
    let shipped = db::embedded().map_err(|e| anyhow!("the shipped database: {e}"))?;
    let same = &regenerated == shipped;
    let frames: u64 = fits.iter().map(|f| f.frames).sum();
    let _ = writeln!(md, "\nThe database: {} entries in {secs:.1} s ({frames} frames confirmed; {}); the same as config/faultdb.toml: {}.", fits.len(), host.line(), if same { "yes" } else { "**no**" });
    ensure!(same, "the regenerated database differs from config/faultdb.toml");
    Ok(json!({"entries": fits.len(), "seconds": secs, "frames_confirmed": frames, "host": host, "same_as_shipped": same}))
}
