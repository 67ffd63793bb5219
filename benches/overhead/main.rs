//! The macro benchmark: what the emulator adds to a frame's one-way latency,
//! measured against the physical floor (a bare iceoryx2 hop) and against
//! kernel UDP, its release lateness, and the highest frame rate it sustains
//! with no unintended loss.
//!
//! `cargo bench --bench overhead` runs everything with 10 s intervals, three
//! times (10 to 15 minutes on 2 cores); `NETFI_BENCH_FULL=1` runs the long
//! version (60 s intervals, 5 repetitions). Results go to
//! `target/netfi-bench/`: `overhead.json`, `overhead.md`, HdrHistogram logs
//! under `hlog/`, and each run's own files under `runs/`. The method is in
//! `docs/performance.md`; in short:
//!
//! - **Chain intervals.** A real `netfi emulator` process, pinned to the
//!   last core, runs a scenario between two ports. This benchmark plays both
//!   ends in *one* thread on another core: it sends frame after frame,
//!   alternately through the emulator (the chain) and straight to itself (the
//!   direct hop), and busy-polls both receive ports in between. Because the
//!   same thread sends and receives, no arrival ever waits for a sender to
//!   give up a core, and both routes see the same placement, the same load
//!   and the same moments. Added latency = chain − direct, percentile by
//!   percentile. Over iceoryx2 the frames carry the emulator's stamps, so the
//!   chain is also split into its first hop, the time inside the emulator
//!   and its second hop. Over UDP the ends are non-blocking, busy-polled
//!   loopback sockets and the send times are kept in a table by sequence.
//! - **Floor intervals.** No emulator: a sender thread on the first core and
//!   a receiver thread spinning on the emulator's core exchange frames over
//!   the same transport: the physical cost of one cross-core hop.
//! - **Probe.** A thread spinning on each core records the gaps between its
//!   clock reads: what interrupts, the hypervisor and other tasks take from
//!   any busy loop there, the emulator's included.
//! - **Delay interval.** The iceoryx2 chain through PLM-2 then DLM-2: release
//!   lateness while hundreds of frames wait for their times, and the
//!   end-to-end latency beyond the injected delay.
//! - **Product run.** `netfi run Normal` as shipped (console and simulator
//!   processes), for its own report of the same quantities.
//! - **Streams.** One emulator serving N streams (`--streams N`), the
//!   benchmark playing all N consoles and robots in one thread: release
//!   lateness, the time inside the emulator and the added latency at 1 kHz
//!   per stream, for N = 1, 2, 8, 32 (`streams.json`).
//! - **Throughput.** `netfi run --no-direct` at rising rates (doubling, then
//!   bisection) for 10 s each; a rate is sustained when every frame is
//!   delivered or dropped by the scenario, nothing else. Each trial also
//!   records the emulator loop's own time per frame (its busy turns, from
//!   `emulator.json`) and the capacity it implies, set against the scale
//!   bar (10⁶ frames/s with Normal, 7·10⁵ with PLM-2 + DLM-2) whatever rate
//!   the console reached.
//! - **Capacity.** The emulator alone at the scale bar's rates (10⁶ frames/s
//!   with Normal, 7·10⁵ with PLM-2 + DLM-2) and up or down from them to 5%,
//!   for the throughput trial's length: the benchmark plays console and
//!   robot in one thread, every frame through the emulator, so the rate
//!   stops where the emulator stops keeping up, not where the product's
//!   console on a shared core does.
//!
//! Each interval records the host's steal time, its load average and the
//! CPU that other processes used during it. Nothing
//! here asserts a time: the figures are printed and written beside the bars
//! of `docs/performance.md`, reported as met or not met.
//!
//! Settings (environment variables):
//!
//! | variable | default | meaning |
//! |---|---|---|
//! | `NETFI_BENCH_FULL` | unset | `1`: 60 s intervals, 5 repetitions |
//! | `NETFI_BENCH_SECONDS` | 10 (60 full) | length of each chain interval (floor intervals: half) |
//! | `NETFI_BENCH_REPS` | 3 (5 full) | repetitions of the latency, delay and product intervals, and trials at each capacity bar |
//! | `NETFI_BENCH_RATES` | `1000,100000` | frame rates of the latency intervals, Hz |
//! | `NETFI_BENCH_QUICK` | unset | `1`: every part briefly (as `--quick`): 1 s intervals, 1 repetition, 1 s throughput trials |
//! | `NETFI_BENCH_PARTS` | all | comma list of `latency`, `delay`, `product`, `throughput`, `capacity`, `sockperf`, `streams` |
//! | `NETFI_BENCH_STREAMS` | `1,2,8,32` | stream counts of the streams part (1 kHz per route per stream) |
//! | `NETFI_BENCH_THROUGHPUT_S` | 10 | length of each throughput and capacity trial |
//! | `NETFI_BENCH_RT_PRIORITY` | unset | run the emulator and this benchmark's threads at this SCHED_FIFO priority |
//! | `NETFI_BENCH_QUIET_CORES` | unset | before each interval, wait until other processes keep at most this many cores busy |
//! | `NETFI_BENCH_QUIET_WAIT_S` | 600 | ... but for at most this long |
//! | `NETFI_BENCH_ISOLATE` | 1 | `0`: leave the emulator's core as it is |
//! | `NETFI_BENCH_OUT` | `target/netfi-bench` | where results go |
//!
//! Arguments after `--` (see [`args::Args`], `-- --help`): part names
//! select parts too (`cargo bench --bench overhead -- latency`), and
//! `--quick` runs every part briefly, to check that the benchmark runs.
//!
//! The program follows the method: `args` (what to run), `host` (the host
//! around each interval), `ends` and `drive` (the benchmark's ends and the
//! loop that drives them), `emulator` (the process), `chain`, `floor`,
//! `probe`, `sockperf`, `product`, `throughput` and `capacity` (the intervals and
//! parts), `figures` (medians over repetitions, the bars) and `report`
//! (`overhead.json`, `overhead.md`).


mod args;
mod capacity;
mod chain;
mod drive;
mod emulator;
mod ends;
mod figures;
mod floor;
mod host;
mod probe;
mod product;
mod report;
mod sockperf;
mod streams;
mod throughput;

use anyhow::{bail, Context, Result};
use args::{Args, Settings};
use chain::ChainResult;
use clap::Parser;
use figures::Figures;
use floor::FloorResult;
use host::HostTimer;
use netfi::host::isolate::Isolation;
use netfi::metrics::LatencyHistogram;
use netfi::service::signals::stop_requested;
use probe::ProbeResult;
use serde::Serialize;
use serde_json::Value;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

const NETFI: &str = env!("CARGO_BIN_EXE_netfi");

/// The delay scenario of the delay interval and of the second throughput
/// search (the study's 30% loss followed by its 300 ms delay).
const PLM2_DLM2: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/config/scenarios/plm2_dlm2.toml");

fn main() {
    // `cargo bench` passes `--bench`; `cargo test --benches` does not, and
    // this benchmark takes minutes, so it only says how to run it.
    if !std::env::args().skip(1).any(|a| a == "--bench") {
        println!("overhead: a macro benchmark of several minutes; run it with `cargo bench --bench overhead`");
        return;
    }
    if let Err(e) = run(&Args::parse()) {
        eprintln!("overhead benchmark failed: {e:#}");
        std::process::exit(1);
    }
}

/// The transports of the latency part.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
enum Transport {
    Iceoryx2,
    Udp,
}

impl Transport {
    const ALL: [Transport; 2] = [Transport::Iceoryx2, Transport::Udp];

    fn name(self) -> &'static str {
        match self {
            Transport::Iceoryx2 => "iceoryx2",
            Transport::Udp => "udp",
        }
    }
}

/// Every interval's results, as the parts add them.
#[derive(Debug, Default)]
struct Results {
    chains: Vec<ChainResult>,
    floors: Vec<FloorResult>,
    products: Vec<Value>,
    probes: Vec<ProbeResult>,
    sockperfs: Vec<Value>,
    throughput: BTreeMap<String, Value>,
    throughput_fps: BTreeMap<String, f64>,
    capacity: BTreeMap<String, Value>,
    streams: Vec<Value>,
}

/// Fails with "interrupted" once Ctrl-C or SIGTERM has been received.
fn check_interrupted() -> Result<()> {
    if stop_requested() {
        bail!("interrupted (Ctrl-C / SIGTERM): the emulators stopped, the core restored, no results written");
    }
    Ok(())
}

/// Writes `h` as an HdrHistogram log `dir/name.hlog`.
fn write_hlog(h: &LatencyHistogram, dir: &Path, name: &str, tag: &str, seconds: f64) -> Result<PathBuf> {
    std::fs::create_dir_all(dir)?;
    let path = dir.join(format!("{name}.hlog"));
    h.write_log(&path, tag, 0.0, seconds).with_context(|| format!("writing {}", path.display()))?;
    Ok(path)
}

fn run(args: &Args) -> Result<()> {
    let s = Settings::from_env(args)?;
    std::fs::create_dir_all(&s.out_dir).with_context(|| format!("creating {}", s.out_dir.display()))?;
    // Ctrl-C and SIGTERM set a flag that every loop below polls: the
    // benchmark then stops its emulators and runs, restores the core it
    // cleared, and exits without writing half a result.
    netfi::service::signals::install();
    let _ = std::fs::remove_dir_all(s.out_dir.join("hlog"));
    let _ = netfi::transport::cleanup_stale();
    let started = Instant::now();
    let bench_host = HostTimer::start(None);
    announce(&s);
    let mut isolation = prepare_host(&s);
    let mut res = Results::default();
    for rep in 0..s.repetitions {
        repetition(&s, rep, &mut res)?;
    }
    if s.wants("throughput") {
        throughput::throughput_part(&s, &mut res)?;
    }
    if s.wants("capacity") {
        capacity::capacity_part(&s, &mut res)?;
    }
    if s.wants("streams") {
        streams::streams_part(&s, &mut res)?;
    }
    let fig = Figures::of(&s, &res);
    check_interrupted()?;
    let host = bench_host.stop();
    let isolation = isolation.as_mut().map(|i| i.restore());
    report::write(&s, &res, &fig, &report::Overall { host, isolation, minutes: started.elapsed().as_secs_f64() / 60.0 })
}

/// The parts of one repetition, in their order.
fn repetition(s: &Settings, rep: usize, res: &mut Results) -> Result<()> {
    if s.wants("latency") {
        chain::latency_part(s, rep, res)?;
    }
    if s.wants("delay") || s.wants("latency") {
        probe::probe_part(s, rep, res)?;
    }
    if s.wants("sockperf") {
        sockperf::sockperf_part(s, rep, res)?;
    }
    if s.wants("delay") {
        chain::delay_part(s, rep, res)?;
    }
    if s.wants("product") {
        product::product_part(s, rep, res)?;
    }
    Ok(())
}

fn announce(s: &Settings) {
    println!(
        "netfi overhead benchmark: {} s intervals, {} repetition(s), rates {:?} Hz, parts {}; emulator core {:?}, driving core {:?}; results in {}",
        s.interval_s,
        s.repetitions,
        s.rates_hz,
        s.parts.join(","),
        s.emulator_core,
        s.driver_core,
        s.out_dir.display()
    );
    if s.emulator_core.is_none() {
        println!("  (fewer than 2 cores: nothing is pinned, and the figures mean little)");
    }
}

/// Puts back what an interrupted earlier run left moved, then clears the
/// emulator's core for the benchmark (unless told not to).
fn prepare_host(s: &Settings) -> Option<Isolation> {
    if let Ok(done) = netfi::host::record::restore_orphans(None) {
        for (path, r) in done {
            println!("  (restored {} placement(s) left moved by an interrupted earlier run, from {})", r.undone, path.display());
        }
    }
    match (s.isolate, s.emulator_core) {
        (true, Some(core)) => match netfi::host::isolate::isolate(core) {
            Ok(iso) => {
                println!("  {} (for the benchmark)", iso.summary());
                Some(iso)
            }
            Err(e) => {
                println!("  (could not clear core {core}: {e}; measuring without)");
                None
            }
        },
        _ => None,
    }
}
