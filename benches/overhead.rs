//! What `netfi run` adds, as shipped: release lateness and the latency
//! added over the direct hop, of `netfi run Normal` and `netfi run` of
//! PLM-2 + DLM-2 at 1 kHz, from each run's `report.json`; each figure as
//! its spread over the runs, with the steal time and load of every run.
//!
//! With `--baseline`, a second build is timed in the same program, runs
//! of the two alternated (A B, then B A, …) on the same machine, so both
//! see the same phases of the host: this is how before/after figures are
//! taken.
//!
//! ```sh
//! cargo bench --bench overhead                          # this build: 5 runs of 10 s per scenario
//! cargo bench --bench overhead -- --baseline /tmp/old/netfi --runs 10
//! ```
//!
//! A build to compare with is any commit's `cargo build --release` output
//! (`target/release/netfi` and the `netfi-*` service binaries beside it,
//! copied away); an older build's `report.json` is read as far as it has
//! the fields.

#[path = "common/mod.rs"]
mod common;

use anyhow::{ensure, Result};
use common::args::{Common, PLM2_DLM2};
use common::host::{HostTimer, HostWindow};
use common::out::Out;
use common::process::{alternate, at, num, scenario_label, summary, Build};
use common::table::{ns, spread_ns, Map, Spread};
use netfi::metrics::{difference, Summary};
use serde::Serialize;
use serde_json::{json, Value};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// `cargo bench --bench overhead -- [FLAGS]`.
#[derive(Debug, clap::Parser, Serialize)]
#[command(name = "overhead", bin_name = "cargo bench --bench overhead --", about = "What netfi run adds: release lateness and added latency, one build or two alternated")]
struct Args {
    #[command(flatten)]
    common: Common,
    /// The netfi binary to measure [default: this package's build]
    #[arg(long, value_name = "PATH")]
    netfi: Option<PathBuf>,
    /// A second build, timed alternately with the first
    #[arg(long, value_name = "PATH")]
    baseline: Option<PathBuf>,
    /// Runs of each scenario by each build
    #[arg(long, default_value_t = 5)]
    runs: usize,
    /// Length of each run
    #[arg(long, default_value_t = 10.0)]
    seconds: f64,
    /// Frames a second
    #[arg(long, default_value_t = 1000.0)]
    rate_hz: f64,
    /// A scenario (preset or file), repeatable [default: Normal and
    /// config/scenarios/plm2_dlm2.toml]
    #[arg(long = "scenario", value_name = "SCENARIO")]
    scenarios: Vec<String>,
    /// A further flag for every `netfi run` (both builds must take it),
    /// repeatable: `--run-arg=--no-isolate`
    #[arg(long = "run-arg", value_name = "FLAG", allow_hyphen_values = true)]
    run_args: Vec<String>,
}

/// One run's figures, as far as its build reports them.
#[derive(Debug, Clone, Serialize)]
struct RunFigures {
    build: String,
    scenario: String,
    round: usize,
    release_lateness_ns: Option<Summary>,
    /// Through the emulator beyond the injected delay − the direct hop, per
    /// percentile (the report's `added_over_direct`).
    added_ns: Option<Map>,
    end_to_end_extra_ns: Option<Summary>,
    direct_hop_ns: Option<Summary>,
    decision_ns: Option<Summary>,
    ingress_wait_ns: Option<Summary>,
    emulator_busy_ns_per_frame: Option<f64>,
    balanced: Option<bool>,
    faults: Value,
    /// The run's own steal fraction (`report.json`).
    steal_fraction: Option<f64>,
    host: HostWindow,
    dir: PathBuf,
}

impl RunFigures {
    fn of(build: &str, scenario: &str, round: usize, r: &Value, host: HostWindow, dir: &Path) -> RunFigures {
        let (extra, direct) = (summary(r, "overhead_ns.end_to_end_extra"), summary(r, "overhead_ns.direct_hop"));
        let added = serde_json::from_value(at(r, "overhead_ns.added_over_direct").clone())
            .ok()
            .or_else(|| extra.zip(direct).map(|(a, b)| difference(&a, &b, &["p50", "p90", "p99", "p999"])));
        RunFigures {
            build: build.to_string(),
            scenario: scenario.to_string(),
            round,
            release_lateness_ns: summary(r, "overhead_ns.release_lateness"),
            added_ns: added,
            end_to_end_extra_ns: extra,
            direct_hop_ns: direct,
            decision_ns: summary(r, "overhead_ns.decision"),
            ingress_wait_ns: summary(r, "overhead_ns.ingress_wait"),
            emulator_busy_ns_per_frame: num(r, "emulator.busy.busy_ns_per_frame"),
            balanced: at(r, "frames.balanced").as_bool(),
            faults: at(r, "faults").clone(),
            steal_fraction: num(r, "steal.fraction"),
            host,
            dir: dir.to_path_buf(),
        }
    }

    fn added(&self, k: &str) -> Option<f64> {
        self.added_ns.as_ref().and_then(|m| m.get(k)).map(|v| *v as f64)
    }
}

/// The figures one build gave one scenario over its runs.
#[derive(Debug, Serialize)]
struct Cell {
    build: String,
    scenario: String,
    runs: usize,
    release_lateness_p50_ns: Option<Spread>,
    release_lateness_p99_ns: Option<Spread>,
    added_p50_ns: Option<Spread>,
    added_p99_ns: Option<Spread>,
    steal_fraction: Option<Spread>,
    unbalanced_runs: usize,
}

impl Cell {
    fn of(build: &str, scenario: &str, runs: &[&RunFigures]) -> Cell {
        let lat = |f: fn(&Summary) -> u64| Spread::of(runs.iter().filter_map(|r| r.release_lateness_ns.as_ref().map(|s| f(s) as f64)));
        Cell {
            build: build.to_string(),
            scenario: scenario.to_string(),
            runs: runs.len(),
            release_lateness_p50_ns: lat(|s| s.p50),
            release_lateness_p99_ns: lat(|s| s.p99),
            added_p50_ns: Spread::of(runs.iter().filter_map(|r| r.added("p50"))),
            added_p99_ns: Spread::of(runs.iter().filter_map(|r| r.added("p99"))),
            steal_fraction: Spread::of(runs.iter().map(|r| r.steal_fraction.unwrap_or(r.host.steal_fraction))),
            unbalanced_runs: runs.iter().filter(|r| r.balanced == Some(false)).count(),
        }
    }

    fn md_row(&self) -> String {
        let steal = self.steal_fraction.map_or("–".into(), |s| s.percent());
        format!(
            "| {} | {} | {} | {} | {} | {} | {steal} |",
            self.build,
            self.runs,
            spread_ns(self.release_lateness_p50_ns),
            spread_ns(self.release_lateness_p99_ns),
            spread_ns(self.added_p50_ns),
            spread_ns(self.added_p99_ns)
        )
    }
}

fn main() {
    common::args::main("overhead", "what netfi run adds (minutes)", run);
}

fn run(a: Args) -> Result<()> {
    ensure!(a.runs >= 1 && a.seconds > 0.0 && a.rate_hz > 0.0, "--runs, --seconds and --rate-hz must be positive");
    let out = Out::create(&a.common, "overhead")?;
    let builds = Build::pair(a.netfi.as_deref(), a.baseline.as_deref())?;
    let scenarios = if a.scenarios.is_empty() { vec!["Normal".to_string(), PLM2_DLM2.to_string()] } else { a.scenarios.clone() };
    let runs = alternate(&builds, &scenarios, a.runs, |b, sc, round| one_run(&a, &out, b, sc, round))?;
    let cells: Vec<Cell> = scenarios
        .iter()
        .flat_map(|sc| builds.iter().map(move |b| (sc, b)))
        .map(|(sc, b)| Cell::of(&b.label, &scenario_label(sc), &runs.iter().filter(|r| r.build == b.label && r.scenario == scenario_label(sc)).collect::<Vec<_>>()))
        .collect();
    let md = markdown(&a, &scenarios, &cells, &runs);
    out.finish(&a, json!({"builds": builds, "cells": cells, "runs": runs}), &md)
}

fn one_run(a: &Args, out: &Out, b: &Build, scenario: &str, round: usize) -> Result<RunFigures> {
    let dir = out.run_dir(&format!("{}-{}-r{round}", scenario_label(scenario), b.label))?;
    let host = HostTimer::start(a.common.quiet());
    let r = b.run(&dir, scenario, a.rate_hz, a.seconds, &a.run_args)?;
    let f = RunFigures::of(&b.label, &scenario_label(scenario), round, &r, host.stop(), &dir);
    let p = |s: &Option<Summary>, k: fn(&Summary) -> u64| s.as_ref().map_or("–".into(), |s| ns(k(s) as i64));
    let added = |k: &str| f.added(k).map_or("–".into(), |v| ns(v as i64));
    println!(
        "  round {round} {:<10} {:<12} release lateness p50 {} p99 {}; added p50 {} p99 {}; steal {:.2}%, load {:.1}",
        b.label,
        f.scenario,
        p(&f.release_lateness_ns, |s| s.p50),
        p(&f.release_lateness_ns, |s| s.p99),
        added("p50"),
        added("p99"),
        f.steal_fraction.unwrap_or(f.host.steal_fraction) * 100.0,
        f.host.load_end
    );
    Ok(f)
}

fn markdown(a: &Args, scenarios: &[String], cells: &[Cell], runs: &[RunFigures]) -> String {
    let mut md = String::new();
    for sc in scenarios.iter().map(|s| scenario_label(s)) {
        let _ = writeln!(md, "## {sc} at {} frames/s, {} s runs\n", a.rate_hz, a.seconds);
        let _ = writeln!(md, "Median (least – largest) over the runs.\n");
        let _ = writeln!(md, "| build | runs | release lateness p50 | p99 | added latency p50 | p99 | steal per run |\n|---|---|---|---|---|---|---|");
        let mine: Vec<&Cell> = cells.iter().filter(|c| c.scenario == sc).collect();
        for c in &mine {
            let _ = writeln!(md, "{}", c.md_row());
        }
        if let [new, old] = mine[..] {
            // Lateness is positive: a ratio reads well. Added latency is a
            // difference of two distributions and may be negative: the
            // difference of the medians says more.
            let r = |x: Option<Spread>, y: Option<Spread>| x.zip(y).map_or("–".into(), |(x, y)| format!("{:.2}×", x.median / y.median.max(1.0)));
            let d = |x: Option<Spread>, y: Option<Spread>| {
                x.zip(y).map_or("–".into(), |(x, y)| {
                    let v = (x.median - y.median).round() as i64;
                    format!("{}{}", if v >= 0 { "+" } else { "" }, ns(v))
                })
            };
            let _ = writeln!(
                md,
                "| {} against {} (medians) | | {} | {} | {} | {} | |",
                new.build,
                old.build,
                r(new.release_lateness_p50_ns, old.release_lateness_p50_ns),
                r(new.release_lateness_p99_ns, old.release_lateness_p99_ns),
                d(new.added_p50_ns, old.added_p50_ns),
                d(new.added_p99_ns, old.added_p99_ns)
            );
        }
        md.push('\n');
    }
    let _ = writeln!(md, "Every run, in the order run:\n\n| round | scenario | build | lateness p50 / p99 | added p50 / p99 | steal | others |\n|---|---|---|---|---|---|---|");
    for r in runs {
        let l = r.release_lateness_ns.as_ref().map_or("–".into(), |s| format!("{} / {}", ns(s.p50 as i64), ns(s.p99 as i64)));
        let ad = |k: &str| r.added(k).map_or("–".into(), |v| ns(v as i64));
        let steal = r.steal_fraction.unwrap_or(r.host.steal_fraction) * 100.0;
        let _ = writeln!(md, "| {} | {} | {} | {l} | {} / {} | {steal:.2}% | {:.2} cores |", r.round, r.scenario, r.build, ad("p50"), ad("p99"), r.host.others_busy_cores);
    }
    md
}
