//! Simulated time's speed: `netfi scenario check SCENARIO --frames N
//! --json` timed as a process (wall and CPU time), one build or two
//! alternated (A B, then B A, …) on the same machine; with two, whether
//! their JSON is byte for byte the same.
//!
//! ```sh
//! cargo bench --bench check                                      # PLM-2 and plm2_dlm2.toml, 10^7 frames, 5 runs
//! cargo bench --bench check -- --baseline /tmp/old/netfi --runs 9
//! ```

#[path = "common/mod.rs"]
mod common;

use anyhow::{ensure, Context, Result};
use common::args::{check_interrupted, Common, PLM2_DLM2};
use common::host::{HostTimer, HostWindow};
use common::out::Out;
use common::host::cpu_s;
use common::process::{alternate, scenario_label, wait, Build};
use common::table::Spread;
use serde::Serialize;
use serde_json::json;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Instant;

/// `cargo bench --bench check -- [FLAGS]`.
#[derive(Debug, clap::Parser, Serialize)]
#[command(name = "check", bin_name = "cargo bench --bench check --", about = "netfi scenario check's speed, one build or two alternated")]
struct Args {
    #[command(flatten)]
    common: Common,
    /// The netfi binary to time [default: this package's build]
    #[arg(long, value_name = "PATH")]
    netfi: Option<PathBuf>,
    /// A second build, timed alternately with the first
    #[arg(long, value_name = "PATH")]
    baseline: Option<PathBuf>,
    /// Runs of each scenario by each build
    #[arg(long, default_value_t = 5)]
    runs: usize,
    /// Frames simulated a run
    #[arg(long, default_value_t = 10_000_000)]
    frames: u64,
    /// A scenario (preset or file), repeatable [default: PLM-2 and
    /// config/scenarios/plm2_dlm2.toml]
    #[arg(long = "scenario", value_name = "SCENARIO")]
    scenarios: Vec<String>,
}

/// One timed run.
#[derive(Debug, Serialize)]
struct Run {
    build: String,
    scenario: String,
    round: usize,
    wall_s: f64,
    /// User + system time of the process.
    cpu_s: f64,
    host: HostWindow,
}

fn main() {
    common::args::main("check", "netfi scenario check's speed (a minute)", run);
}

fn run(a: Args) -> Result<()> {
    ensure!(a.runs >= 1 && a.frames >= 1, "--runs and --frames must be positive");
    let out = Out::create(&a.common, "check")?;
    let builds = Build::pair(a.netfi.as_deref(), a.baseline.as_deref())?;
    let scenarios = if a.scenarios.is_empty() { vec!["PLM-2".to_string(), PLM2_DLM2.to_string()] } else { a.scenarios.clone() };
    let runs = alternate(&builds, &scenarios, a.runs, |b, sc, round| one_run(&a, &out, b, sc, round))?;
    let mut md = format!("{} frames a run; median (least – largest) over {} runs.\n\n| scenario | build | wall, s | CPU, s | ns a frame (CPU) | steal per run | JSON the same as the first build's |\n|---|---|---|---|---|---|---|\n", a.frames, a.runs);
    let mut cells = Vec::new();
    for sc in &scenarios {
        let first = std::fs::read(json_path(&out.dir, &builds[0].label, sc)).unwrap_or_default();
        for b in &builds {
            let mine: Vec<&Run> = runs.iter().filter(|r| r.build == b.label && r.scenario == scenario_label(sc)).collect();
            let spread = |f: fn(&Run) -> f64| Spread::of(mine.iter().map(|r| f(r)));
            let (wall, cpu, steal) = (spread(|r| r.wall_s), spread(|r| r.cpu_s), spread(|r| r.host.steal_fraction));
            let same = std::fs::read(json_path(&out.dir, &b.label, sc)).map(|j| j == first).unwrap_or(false);
            let s = |x: Option<Spread>| x.map_or("–".into(), |x| format!("{:.3} ({:.3} – {:.3})", x.median, x.min, x.max));
            let per_frame = cpu.map_or("–".into(), |c| format!("{:.0}", c.median * 1e9 / a.frames as f64));
            let steal_s = steal.map_or("–".into(), |s| s.percent());
            let _ = writeln!(md, "| {} | {} | {} | {} | {per_frame} | {steal_s} | {} |", scenario_label(sc), b.label, s(wall), s(cpu), if same { "yes" } else { "**no**" });
            cells.push(json!({"scenario": scenario_label(sc), "build": b.label, "wall_s": wall, "cpu_s": cpu, "steal_fraction": steal, "json_same_as_first_build": same}));
        }
    }
    out.finish(&a, json!({"builds": builds, "cells": cells, "runs": runs}), &md)
}

/// Where a build's JSON of a scenario is kept (the last run's).
fn json_path(dir: &Path, build: &str, scenario: &str) -> PathBuf {
    dir.join("runs").join(format!("{}-{build}.json", scenario_label(scenario)))
}

fn one_run(a: &Args, out: &Out, b: &Build, scenario: &str, round: usize) -> Result<Run> {
    check_interrupted()?;
    let path = json_path(&out.dir, &b.label, scenario);
    std::fs::create_dir_all(path.parent().context("a runs directory")?)?;
    let mut cmd = Command::new(&b.netfi);
    cmd.args(["scenario", "check", scenario, "--frames", &a.frames.to_string(), "--seed", "1", "--json"]);
    // The JSON alone in its file; the seed line goes to the log.
    let json = std::fs::File::create(&path).with_context(|| format!("creating {}", path.display()))?;
    let log = std::fs::File::create(path.with_extension("log"))?;
    cmd.stdin(Stdio::null()).stdout(json).stderr(log);
    let (host, cpu0, t0) = (HostTimer::now(), cpu_s(libc::RUSAGE_CHILDREN), Instant::now());
    let status = wait(cmd.spawn().with_context(|| format!("starting {}", b.netfi.display()))?)?;
    let (wall_s, cpu_s, host) = (t0.elapsed().as_secs_f64(), cpu_s(libc::RUSAGE_CHILDREN) - cpu0, host.stop());
    check_interrupted()?;
    ensure!(status.success(), "{} scenario check {scenario}: {status}; see {}", b.label, path.display());
    println!("  round {round} {:<10} {:<12} {wall_s:.3} s wall, {cpu_s:.3} s CPU; {}", b.label, scenario_label(scenario), host.line());
    Ok(Run { build: b.label.clone(), scenario: scenario_label(scenario), round, wall_s, cpu_s, host })
}
