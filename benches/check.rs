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
use common::process::{wait, Build};
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
    let mut builds = vec![Build::new("netfi", a.netfi.as_deref())?];
    if let Some(b) = &a.baseline {
        builds.push(Build::new("baseline", Some(b))?);
    }
    let scenarios = if a.scenarios.is_empty() { vec!["PLM-2".to_string(), PLM2_DLM2.to_string()] } else { a.scenarios.clone() };
    let mut runs = Vec::new();
    for round in 0..a.runs {
        for sc in &scenarios {
            let order: Vec<&Build> = if round % 2 == 0 { builds.iter().collect() } else { builds.iter().rev().collect() };
            for b in order {
                runs.push(one_run(&a, &out, b, sc, round)?);
            }
        }
    }
    let mut md = format!("{} frames a run; median (least – largest) over {} runs.\n\n| scenario | build | wall, s | CPU, s | ns a frame (CPU) | steal per run | JSON the same as the first build's |\n|---|---|---|---|---|---|---|\n", a.frames, a.runs);
    let mut cells = Vec::new();
    for sc in &scenarios {
        let first = std::fs::read(json_path(&out.dir, &builds[0].label, sc)).unwrap_or_default();
        for b in &builds {
            let mine: Vec<&Run> = runs.iter().filter(|r| r.build == b.label && r.scenario == label(sc)).collect();
            let spread = |f: fn(&Run) -> f64| Spread::of(mine.iter().map(|r| f(r)));
            let (wall, cpu, steal) = (spread(|r| r.wall_s), spread(|r| r.cpu_s), spread(|r| r.host.steal_fraction));
            let same = std::fs::read(json_path(&out.dir, &b.label, sc)).map(|j| j == first).unwrap_or(false);
            let s = |x: Option<Spread>| x.map_or("–".into(), |x| format!("{:.3} ({:.3} – {:.3})", x.median, x.min, x.max));
            let per_frame = cpu.map_or("–".into(), |c| format!("{:.0}", c.median * 1e9 / a.frames as f64));
            let steal_s = steal.map_or("–".into(), |s| format!("{:.2}–{:.2}%", s.min * 100.0, s.max * 100.0));
            let _ = writeln!(md, "| {} | {} | {} | {} | {per_frame} | {steal_s} | {} |", label(sc), b.label, s(wall), s(cpu), if same { "yes" } else { "**no**" });
            cells.push(json!({"scenario": label(sc), "build": b.label, "wall_s": wall, "cpu_s": cpu, "steal_fraction": steal, "json_same_as_first_build": same}));
        }
    }
    out.finish(&a, json!({"builds": builds, "cells": cells, "runs": runs}), &md)
}

fn label(scenario: &str) -> String {
    Path::new(scenario).file_stem().map_or(scenario.to_string(), |s| s.to_string_lossy().into_owned())
}

/// Where a build's JSON of a scenario is kept (the last run's).
fn json_path(dir: &Path, build: &str, scenario: &str) -> PathBuf {
    dir.join("runs").join(format!("{}-{build}.json", label(scenario)))
}

/// CPU seconds of the children waited for so far.
fn children_cpu_s() -> f64 {
    // SAFETY: a zeroed rusage is a valid output buffer for getrusage.
    let mut u: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: `u` is a valid, writable rusage.
    if unsafe { libc::getrusage(libc::RUSAGE_CHILDREN, &mut u) } != 0 {
        return f64::NAN;
    }
    let tv = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 / 1e6;
    tv(u.ru_utime) + tv(u.ru_stime)
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
    let (host, cpu0, t0) = (HostTimer::now(), children_cpu_s(), Instant::now());
    let status = wait(cmd.spawn().with_context(|| format!("starting {}", b.netfi.display()))?)?;
    let (wall_s, cpu_s, host) = (t0.elapsed().as_secs_f64(), children_cpu_s() - cpu0, host.stop());
    check_interrupted()?;
    ensure!(status.success(), "{} scenario check {scenario}: {status}; see {}", b.label, path.display());
    println!("  round {round} {:<10} {:<12} {wall_s:.3} s wall, {cpu_s:.3} s CPU; {}", b.label, label(scenario), host.line());
    Ok(Run { build: b.label.clone(), scenario: label(scenario), round, wall_s, cpu_s, host })
}
