//! What to run: the command line (`Args`) and the environment (`Settings`).
//! `Settings` carries the fields that the modules shared with
//! benches/overhead (`emulator.rs`, `host.rs`) read.

use anyhow::{Context, Result};
use serde::Serialize;
use std::path::{Path, PathBuf};

/// The parts of the benchmark, in the order they run.
pub const PARTS: [&str; 2] = ["iceoryx2", "udp"];

/// The benchmark's command line, after `cargo bench --bench python --`.
#[derive(Debug, clap::Parser)]
#[command(name = "python", bin_name = "cargo bench --bench python --", about = "What the netfi emulator adds between Python processes, over iceoryx2 and the UDP bridge (docs/performance.md)")]
pub struct Args {
    /// Set by `cargo bench`; without it the benchmark only says how to run it.
    #[arg(long, hide = true)]
    pub bench: bool,
    /// Every part for 2 s (also `NETFI_BENCH_QUICK=1`; `NETFI_BENCH_SECONDS`
    /// still wins): checks that the benchmark runs, no figures to quote.
    #[arg(long)]
    pub quick: bool,
    /// Parts to run: iceoryx2, udp (default both).
    pub parts: Vec<String>,
}

/// What to run, from the environment and the arguments.
#[derive(Debug, Clone, Serialize)]
pub struct Settings {
    pub quick: bool,
    /// Length of each part's measured interval (after a 0.5 s warm-up).
    pub seconds: f64,
    /// Frames per second on each route.
    pub rate_hz: f64,
    /// Length of the windows the run is cut into for the host's state.
    pub window_s: f64,
    /// A window is quiet when its steal is at most this fraction of the
    /// CPU time…
    pub quiet_steal: f64,
    /// …and other processes kept at most this many cores busy in it.
    pub quiet_others: f64,
    pub parts: Vec<String>,
    pub out_dir: PathBuf,
    pub python: String,
    pub emulator_core: Option<usize>,
    /// The console's core (benches/overhead calls it the driving core).
    pub driver_core: Option<usize>,
    pub robot_core: Option<usize>,
    /// The Python programs' nice value, if one is set.
    pub python_nice: Option<i32>,
    pub rt_priority: Option<i32>,
    /// Let the emulator clear its core for its run (`netfi emulator
    /// --isolate`, as `netfi run` and benches/overhead do).
    pub isolate: bool,
    /// Wait before each part until other processes keep at most this many
    /// cores busy, for at most this many seconds (as benches/overhead).
    pub quiet: Option<(f64, f64)>,
    /// The emulator's telemetry interval, ms (`NETFI_BENCH_TELEMETRY_MS`,
    /// default the emulator's; 0 serves neither control nor telemetry).
    pub telemetry_ms: u64,
}

fn var(name: &str) -> Option<String> {
    std::env::var(name).ok().filter(|v| !v.trim().is_empty())
}

fn num(name: &str, default: f64) -> Result<f64> {
    match var(name) {
        Some(v) => v.trim().parse::<f64>().with_context(|| format!("{name}={v}: expected a number")),
        None => Ok(default),
    }
}

impl Settings {
    pub fn from_env(args: &Args) -> Result<Settings> {
        let quick = args.quick || var("NETFI_BENCH_QUICK").is_some_and(|v| v != "0");
        let seconds = num("NETFI_BENCH_SECONDS", if quick { 2.0 } else { 20.0 })?;
        let rate_hz = num("NETFI_BENCH_RATE", 1000.0)?;
        let window_s = num("NETFI_BENCH_WINDOW_S", 1.0)?;
        anyhow::ensure!(seconds > 0.0 && rate_hz > 0.0 && window_s > 0.0, "seconds, rate and window must be positive");
        let rt_priority = match var("NETFI_BENCH_RT_PRIORITY") {
            Some(v) => Some(v.trim().parse::<i32>().with_context(|| format!("NETFI_BENCH_RT_PRIORITY={v}"))?),
            None => None,
        };
        let python_nice = match var("NETFI_BENCH_PYTHON_NICE") {
            Some(v) => Some(v.trim().parse::<i32>().with_context(|| format!("NETFI_BENCH_PYTHON_NICE={v}"))?),
            None => None,
        };
        let quiet = match var("NETFI_BENCH_QUIET_CORES") {
            Some(_) => Some((num("NETFI_BENCH_QUIET_CORES", 0.0)?, num("NETFI_BENCH_QUIET_WAIT_S", 600.0)?)),
            None => None,
        };
        let out_dir = match var("NETFI_BENCH_OUT") {
            Some(v) => PathBuf::from(v),
            None => Path::new(env!("CARGO_TARGET_TMPDIR")).parent().context("locating the target directory")?.join("netfi-bench").join("python"),
        };
        // The emulator gets the last core, the console the first, the robot
        // a third where there is one (else it shares the console's).
        let cores: Vec<usize> = core_affinity::get_core_ids().unwrap_or_default().iter().map(|c| c.id).collect();
        let (emulator_core, driver_core, robot_core) = match cores.as_slice() {
            [a, b, .., last] if cores.len() >= 3 => (Some(*last), Some(*a), Some(*b)),
            [a, .., last] => (Some(*last), Some(*a), Some(*a)),
            _ => (None, None, None),
        };
        Ok(Settings {
            quick,
            seconds,
            rate_hz,
            window_s,
            telemetry_ms: num("NETFI_BENCH_TELEMETRY_MS", netfi::service::telemetry::DEFAULT_INTERVAL_MS as f64)? as u64,
            quiet_steal: num("NETFI_BENCH_QUIET_STEAL", 0.01)?,
            quiet_others: num("NETFI_BENCH_QUIET_OTHERS", 0.25)?,
            parts: parts(args),
            out_dir,
            python: var("NETFI_BENCH_PYTHON").unwrap_or_else(|| "python3".into()),
            emulator_core,
            driver_core,
            robot_core,
            python_nice,
            rt_priority,
            isolate: var("NETFI_BENCH_ISOLATE").is_none_or(|v| v != "0"),
            quiet,
        })
    }

    pub fn wants(&self, part: &str) -> bool {
        self.parts.iter().any(|p| p == part)
    }
}

/// The part names among the arguments, else both (other words, such as
/// a `cargo bench` filter, are ignored).
fn parts(args: &Args) -> Vec<String> {
    let named: Vec<String> = args.parts.iter().filter(|a| PARTS.contains(&a.as_str())).cloned().collect();
    if named.is_empty() {
        PARTS.iter().map(|p| p.to_string()).collect()
    } else {
        named
    }
}
