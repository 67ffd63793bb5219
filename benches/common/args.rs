//! A program's start: the flags every program takes ([`Common`]), where the
//! emulator and the benchmark's own threads run ([`Placement`]), the entry
//! that runs a program only under `cargo bench` ([`main`]), and Ctrl-C.

use anyhow::{bail, Result};
use serde::Serialize;
use std::path::{Path, PathBuf};

/// The `netfi` binary this package builds.
pub const NETFI: &str = env!("CARGO_BIN_EXE_netfi");

/// The repository root, for the scenarios under `config/`.
pub const ROOT: &str = env!("CARGO_MANIFEST_DIR");

/// The delay scenario of the study: PLM-2's bursty loss, then DLM-2's
/// 300 ms hyperexponential delay.
pub const PLM2_DLM2: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/config/scenarios/plm2_dlm2.toml");

/// The flags every program takes.
#[derive(Debug, Clone, clap::Args, Serialize)]
pub struct Common {
    /// Where the results go: `<program>.json`, `<program>.md` and each run's
    /// files under `runs/` [default: target/netfi-bench/<program>]
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Before each measurement, wait until other processes keep at most
    /// this many cores busy …
    #[arg(long, value_name = "CORES")]
    pub quiet_cores: Option<f64>,
    /// … but no longer than this
    #[arg(long, value_name = "SECONDS", default_value_t = 600.0)]
    pub quiet_wait_s: f64,
    /// Set by `cargo bench`; without it the program only says how to run it.
    #[arg(long, hide = true)]
    #[serde(skip)]
    pub bench: bool,
}

impl Common {
    /// The results directory of `program`.
    pub fn out_dir(&self, program: &str) -> PathBuf {
        match &self.out {
            Some(dir) => dir.clone(),
            None => Path::new(ROOT).join("target").join("netfi-bench").join(program),
        }
    }

    /// `--quiet-cores` and `--quiet-wait-s`, if set.
    pub fn quiet(&self) -> Option<(f64, f64)> {
        self.quiet_cores.map(|c| (c, self.quiet_wait_s))
    }
}

/// The flags of the programs that start `netfi emulator` themselves.
#[derive(Debug, Clone, clap::Args, Serialize)]
pub struct Cores {
    /// The emulator's core [default: the last]
    #[arg(long, value_name = "CORE")]
    pub emulator_core: Option<usize>,
    /// The core of the benchmark's own ends [default: the first]
    #[arg(long, value_name = "CORE")]
    pub bench_core: Option<usize>,
    /// Run the emulator and the benchmark's threads at this SCHED_FIFO
    /// priority
    #[arg(long, value_name = "PRIORITY")]
    pub rt_priority: Option<i32>,
    /// Leave the emulator's core as it is (by default the program clears
    /// it of other threads and interrupts, as `netfi run` does for a run)
    #[arg(long)]
    pub no_isolate: bool,
}

/// Where the emulator and the benchmark's threads run.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Placement {
    pub emulator_core: Option<usize>,
    /// The benchmark's own ends (or a client's first process).
    pub bench_core: Option<usize>,
    /// A second client process: a third core where there is one, else the
    /// bench core.
    pub other_core: Option<usize>,
    pub rt_priority: Option<i32>,
    pub isolate: bool,
    /// Wait for at most `.0` busy cores of other processes, at most `.1` s.
    pub quiet: Option<(f64, f64)>,
}

impl Placement {
    /// "emulator on core 1, the benchmark on core 0".
    pub fn line(&self) -> String {
        let core = |c: Option<usize>| c.map_or("no core of its own".to_string(), |c| format!("core {c}"));
        format!("emulator on {}, the benchmark on {}", core(self.emulator_core), core(self.bench_core))
    }
}

impl Cores {
    /// The placement: the emulator on the last core, the benchmark on the
    /// first (the placement of `netfi run` on a small machine), unless the
    /// flags say otherwise.
    pub fn placement(&self, common: &Common) -> Result<Placement> {
        let cores = online_cores();
        for c in [self.emulator_core, self.bench_core].into_iter().flatten() {
            if !cores.contains(&c) {
                bail!("core {c} is not online (cores {cores:?})");
            }
        }
        let (first, last) = (cores.first().copied(), cores.last().copied().filter(|_| cores.len() > 1));
        let bench_core = self.bench_core.or(first);
        Ok(Placement {
            emulator_core: self.emulator_core.or(last),
            bench_core,
            other_core: if cores.len() >= 3 { cores.get(1).copied() } else { bench_core },
            rt_priority: self.rt_priority,
            isolate: !self.no_isolate,
            quiet: common.quiet(),
        })
    }
}

/// The cores online, whatever this process's own mask (which a `netfi
/// run` clearing a core elsewhere on the host narrows meanwhile).
pub fn online_cores() -> Vec<usize> {
    netfi::host::isolate::online_cpus().into_iter().collect()
}

/// Runs `run` with the parsed arguments when started by `cargo bench`
/// (which passes `--bench`). `cargo test --benches` runs benchmarks
/// without it; then the program only says how to run it. An error is
/// printed and the process exits with 1.
pub fn main<A: clap::Parser>(name: &str, what: &str, run: impl FnOnce(A) -> Result<()>) {
    // `--list` asks a benchmark binary for its cases (libtest's flag).
    if std::env::args().any(|a| a == "--list") {
        println!("{name}: benchmark");
        return;
    }
    if !std::env::args().skip(1).any(|a| a == "--bench") {
        println!("{name}: {what}; run it with `cargo bench --bench {name}` (`-- --help` lists its flags)");
        return;
    }
    let args = A::parse();
    // Ctrl-C and SIGTERM set a flag that every loop polls: the program then
    // stops its processes and exits without writing half a result.
    netfi::service::signals::install();
    if let Err(e) = run(args) {
        eprintln!("{name} failed: {e:#}");
        std::process::exit(1);
    }
}

/// Whether Ctrl-C or SIGTERM has been received.
#[inline]
pub fn stopped() -> bool {
    netfi::service::signals::stop_requested()
}

/// Fails with "interrupted" once Ctrl-C or SIGTERM has been received.
pub fn check_interrupted() -> Result<()> {
    if stopped() {
        bail!("interrupted (Ctrl-C / SIGTERM): the processes were stopped, no results written");
    }
    Ok(())
}

/// Puts the stop flag's handler back: iceoryx2 installs its own when a
/// process opens its first node, and Ctrl-C would then go unseen.
pub fn keep_signals() {
    netfi::service::signals::ensure_installed();
}
