//! What to run: the command line (`Args`) and the environment (`Settings`).

use anyhow::{bail, Context, Result};
use serde::Serialize;
use std::path::{Path, PathBuf};

/// The parts of the benchmark, in the order they run within a repetition.
pub const PARTS: [&str; 7] = ["latency", "delay", "product", "throughput", "capacity", "sockperf", "streams"];

/// The benchmark's command line, after `cargo bench --bench overhead --`.
#[derive(Debug, clap::Parser)]
#[command(name = "overhead", bin_name = "cargo bench --bench overhead --", about = "What the emulator adds to a frame's one-way latency, its release lateness and throughput (docs/performance.md)")]
pub struct Args {
    /// Set by `cargo bench`; without it the benchmark only says how to run it.
    #[arg(long, hide = true)]
    pub bench: bool,
    /// Every part, briefly: 1 s intervals, 1 repetition, 1 s throughput
    /// trials (also `NETFI_BENCH_QUICK=1`); the variables that set these
    /// still win. For checking that the benchmark runs, not for figures.
    #[arg(long)]
    pub quick: bool,
    /// The throughput search's first rate, frames/s (default 50 000, or
    /// `NETFI_BENCH_THROUGHPUT_FROM`): it doubles from here until a rate
    /// fails, then bisects. Starting near the expected figure saves trials.
    #[arg(long, value_name = "HZ")]
    pub throughput_from: Option<f64>,
    /// Parts to run (latency, delay, product, throughput, sockperf, streams; default
    /// all, or `NETFI_BENCH_PARTS`). Other words, such as a `cargo bench`
    /// filter, are ignored.
    pub parts: Vec<String>,
}

/// What to run, from the environment and the arguments.
#[derive(Debug, Clone, Serialize)]
pub struct Settings {
    pub full: bool,
    pub quick: bool,
    pub interval_s: f64,
    pub floor_s: f64,
    pub repetitions: usize,
    pub rates_hz: Vec<f64>,
    pub parts: Vec<String>,
    pub throughput_trial_s: f64,
    /// The throughput search's first rate.
    pub throughput_from_hz: f64,
    pub rt_priority: Option<i32>,
    /// Wait before each interval until other processes keep at most this
    /// many cores busy, for at most this many seconds.
    pub quiet: Option<(f64, f64)>,
    pub out_dir: PathBuf,
    pub emulator_core: Option<usize>,
    pub driver_core: Option<usize>,
    /// Clear the emulator's core of every other thread and interrupt that
    /// may run elsewhere, for the whole benchmark (`netfi::host::isolate`).
    pub isolate: bool,
    /// The emulator's telemetry interval, ms (`NETFI_BENCH_TELEMETRY_MS`,
    /// default the emulator's 100); 0 runs it without the control and
    /// telemetry services, to compare.
    pub telemetry_ms: u64,
    /// Stream counts of the streams part (`NETFI_BENCH_STREAMS`, default
    /// 1,2,8,32).
    pub stream_counts: Vec<usize>,
}

/// A non-empty environment variable.
fn var(name: &str) -> Option<String> {
    std::env::var(name).ok().filter(|v| !v.trim().is_empty())
}

/// A number from the environment, else `default`.
fn num(name: &str, default: f64) -> Result<f64> {
    match var(name) {
        Some(v) => v.trim().parse::<f64>().with_context(|| format!("{name}={v}: expected a number")),
        None => Ok(default),
    }
}

fn parsed<T: std::str::FromStr>(name: &str, what: &str) -> Result<Option<T>>
where
    T::Err: std::error::Error + Send + Sync + 'static,
{
    var(name).map(|v| v.trim().parse::<T>().with_context(|| format!("{name}={v}{what}"))).transpose()
}

impl Settings {
    pub fn from_env(args: &Args) -> Result<Settings> {
        let full = var("NETFI_BENCH_FULL").is_some_and(|v| v != "0");
        let quick = args.quick || var("NETFI_BENCH_QUICK").is_some_and(|v| v != "0");
        let (interval, reps, trial) = match (quick, full) {
            (true, _) => (1.0, 1.0, 1.0),
            (false, true) => (60.0, 5.0, 10.0),
            (false, false) => (10.0, 3.0, 10.0),
        };
        let interval_s = num("NETFI_BENCH_SECONDS", interval)?;
        let repetitions = num("NETFI_BENCH_REPS", reps)? as usize;
        let throughput_trial_s = num("NETFI_BENCH_THROUGHPUT_S", trial)?;
        let throughput_from_hz = match args.throughput_from {
            Some(hz) => hz,
            None => num("NETFI_BENCH_THROUGHPUT_FROM", 50_000.0)?,
        };
        anyhow::ensure!(interval_s > 0.0 && repetitions >= 1 && throughput_trial_s > 0.0, "intervals and repetitions must be positive");
        anyhow::ensure!(throughput_from_hz >= 1000.0, "the throughput search starts at 1000 frames/s or more");
        let rt_priority = parsed::<i32>("NETFI_BENCH_RT_PRIORITY", "")?;
        let quiet = match parsed::<f64>("NETFI_BENCH_QUIET_CORES", ": expected a number of cores")? {
            Some(cores) => Some((cores, num("NETFI_BENCH_QUIET_WAIT_S", 600.0)?)),
            None => None,
        };
        let out_dir = match var("NETFI_BENCH_OUT") {
            Some(v) => PathBuf::from(v),
            None => Path::new(env!("CARGO_TARGET_TMPDIR")).parent().context("locating the target directory")?.join("netfi-bench"),
        };
        // The emulator gets the last core, the benchmark's driving thread
        // the first: the same placement as `netfi run` on a small machine.
        let cores: Vec<usize> = core_affinity::get_core_ids().unwrap_or_default().iter().map(|c| c.id).collect();
        let (emulator_core, driver_core) = match cores.as_slice() {
            [first, .., last] => (Some(*last), Some(*first)),
            _ => (None, None),
        };
        Ok(Settings {
            isolate: var("NETFI_BENCH_ISOLATE").is_none_or(|v| v != "0"),
            full,
            quick,
            interval_s,
            floor_s: interval_s / 2.0,
            repetitions,
            rates_hz: rates()?,
            parts: parts(args)?,
            throughput_trial_s,
            throughput_from_hz,
            rt_priority,
            quiet,
            out_dir,
            emulator_core,
            driver_core,
            telemetry_ms: num("NETFI_BENCH_TELEMETRY_MS", netfi::service::telemetry::DEFAULT_INTERVAL_MS as f64)? as u64,
            stream_counts: stream_counts()?,
        })
    }

    pub fn wants(&self, part: &str) -> bool {
        self.parts.iter().any(|p| p == part)
    }

    /// Length of each sockperf ping-pong: a floor interval, at least 5 s
    /// (1 s in the quick run).
    pub fn sockperf_s(&self) -> f64 {
        self.floor_s.max(if self.quick { 1.0 } else { 5.0 })
    }
}

/// `NETFI_BENCH_RATES`, else 1 kHz and 100 kHz.
fn rates() -> Result<Vec<f64>> {
    let rates_hz = match var("NETFI_BENCH_RATES") {
        Some(v) => v
            .split(',')
            .map(|r| r.trim().parse::<f64>().with_context(|| format!("NETFI_BENCH_RATES: `{r}` is not a rate in Hz")))
            .collect::<Result<Vec<f64>>>()?,
        None => vec![1000.0, 100_000.0],
    };
    anyhow::ensure!(rates_hz.iter().all(|r| r.is_finite() && *r > 0.0), "NETFI_BENCH_RATES: rates must be positive");
    Ok(rates_hz)
}

/// `NETFI_BENCH_STREAMS`, else 1, 2, 8 and 32.
fn stream_counts() -> Result<Vec<usize>> {
    let counts = match var("NETFI_BENCH_STREAMS") {
        Some(v) => v.split(',').map(|n| n.trim().parse::<usize>().with_context(|| format!("NETFI_BENCH_STREAMS: `{n}` is not a count"))).collect::<Result<Vec<_>>>()?,
        None => vec![1, 2, 8, 32],
    };
    let max = netfi::service::plan::MAX_STREAMS as usize;
    anyhow::ensure!(counts.iter().all(|n| (1..=max).contains(n)), "NETFI_BENCH_STREAMS: counts from 1 to {max}");
    Ok(counts)
}

/// `NETFI_BENCH_PARTS`, else the part names among the arguments, else all.
fn parts(args: &Args) -> Result<Vec<String>> {
    let from_args: Vec<String> = args.parts.iter().filter(|a| PARTS.contains(&a.as_str())).cloned().collect();
    let parts: Vec<String> = match var("NETFI_BENCH_PARTS") {
        Some(v) => v.split(',').map(|p| p.trim().to_string()).collect(),
        None if !from_args.is_empty() => from_args,
        None => PARTS.iter().map(|p| p.to_string()).collect(),
    };
    if let Some(p) = parts.iter().find(|p| !PARTS.contains(&p.as_str())) {
        bail!("unknown part `{p}`; the parts are {}", PARTS.join(", "));
    }
    Ok(parts)
}
