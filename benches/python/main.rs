//! What the netfi emulator adds between Python processes: a Python console
//! and a Python robot (clients/python/bench/, on iceoryx2's official
//! Python bindings and the `netfi_iox` module), once over iceoryx2 and once
//! over UDP through the emulator's UDP bridge, each against a direct
//! Python → Python hop measured in the same run.
//!
//! `cargo bench --bench python` runs both parts for 20 s each at 1 kHz per
//! route (about a minute in all); `-- --quick` runs each for 2 s, to check
//! that it runs. Results go to `target/netfi-bench/python/`: `python.json`,
//! `python.md` (printed too) and each part's files under `runs/`. The method
//! and this machine's figures are in docs/performance.md ("Python clients:
//! what the emulator adds"). In short:
//!
//! - **Two routes, alternating.** The console sends one frame every half
//!   period, alternately through the emulator (the chain) and straight to
//!   the robot (direct), so both routes run at the rate and see the same
//!   moments of the run. The robot records each frame's one-way latency and
//!   answers it at once on the same route; the console records the round
//!   trip of each answer. Over iceoryx2 the direct hop is a second run id
//!   with no emulator (the console publishes on its `emulator` channel and
//!   takes the robot's `feedback` itself); over UDP it is the robot's second
//!   socket. The emulator runs `Normal` both ways (`--return-scenario
//!   Normal`: the iceoryx2 feedback loop, or the UDP return path).
//! - **The emulator's share.** Over iceoryx2 every frame carries the
//!   emulator's stamps, and every answer carries those of the command and
//!   its own: the emulator's share of a round trip is the time each
//!   direction spent inside it (taken → released), summed. The round trip
//!   through the emulator − the direct one is reported beside it.
//! - **Quiet windows.** A thread samples `/proc/stat` and the CPU time of
//!   the benchmark's processes once a window (1 s): each window's steal and
//!   the cores other processes kept busy. Every figure is given over the
//!   quiet windows (steal ≤ 1 %, others ≤ 0.25 cores) and over all, with
//!   the host's state over the windows it used. The bars (the emulator's
//!   share of the round trip: p50 ≤ 2 µs, p99 ≤ 20 µs) are judged over the
//!   quiet windows; nothing is asserted.
//!
//! Placement: the emulator on the last core, which it clears of other
//! threads and interrupts for its run (`netfi emulator --isolate`, as
//! `netfi run` and benches/overhead do); the console on the first core, the
//! robot on a third where there is one, else beside the console (both poll
//! with `sched_yield`, so each gives the core up when it has nothing to do).
//!
//! | variable | default | meaning |
//! |---|---|---|
//! | `NETFI_BENCH_SECONDS` | 20 (2 quick) | length of each part after a 0.5 s warm-up |
//! | `NETFI_BENCH_RATE` | 1000 | frames per second on each route |
//! | `NETFI_BENCH_WINDOW_S` | 1 | length of a window |
//! | `NETFI_BENCH_QUIET_STEAL` | 0.01 | a quiet window's largest steal fraction |
//! | `NETFI_BENCH_QUIET_OTHERS` | 0.25 | … and the most cores other processes may keep busy in it |
//! | `NETFI_BENCH_QUIET_CORES` | unset | before each part, wait until other processes keep at most this many cores busy (`NETFI_BENCH_QUIET_WAIT_S`, 600, at most) |
//! | `NETFI_BENCH_RT_PRIORITY` | unset | run the emulator at this SCHED_FIFO priority |
//! | `NETFI_BENCH_ISOLATE` | 1 | `0`: leave the emulator's core as it is |
//! | `NETFI_BENCH_PYTHON` | `python3` | the interpreter |
//! | `NETFI_BENCH_PYTHON_NICE` | unset | run the Python console and robot at this nice value (e.g. `-10`, with root: ahead of other work on their core) |
//! | `NETFI_BENCH_QUICK` | unset | `1`: as `--quick` |
//! | `NETFI_BENCH_OUT` | `target/netfi-bench/python` | where results go |
//!
//! Without python3 or its `iceoryx2` package the benchmark says so and
//! exits successfully, measuring nothing.
//!
//! The emulator process and the host's figures are benches/overhead's own
//! modules (`emulator.rs`, `host.rs`), compiled in here unchanged.

mod args;
#[allow(dead_code)]
#[path = "../overhead/emulator.rs"]
mod emulator;
mod figures;
#[allow(dead_code)]
#[path = "../overhead/host.rs"]
mod host;
mod parts;
mod report;
mod windows;

use anyhow::{bail, Result};
use args::{Args, Settings};
use clap::Parser;

const NETFI: &str = env!("CARGO_BIN_EXE_netfi");

fn main() {
    if !std::env::args().skip(1).any(|a| a == "--bench") {
        println!("python: a benchmark of about a minute; run it with `cargo bench --bench python` (`-- --quick`: seconds)");
        return;
    }
    if let Err(e) = run(&Args::parse()) {
        eprintln!("python benchmark failed: {e:#}");
        std::process::exit(1);
    }
}

fn run(args: &Args) -> Result<()> {
    let s = Settings::from_env(args)?;
    if let Some(why) = parts::python_missing(&s) {
        println!("python: skipped: {} cannot import iceoryx2's Python bindings or netfi_iox ({why}); pip install iceoryx2==0.10.0", s.python);
        return Ok(());
    }
    std::fs::create_dir_all(&s.out_dir)?;
    netfi::service::signals::install();
    let _ = netfi::transport::cleanup_stale();
    println!(
        "netfi Python benchmark: parts {}, {} s each at {} Hz per route; emulator core {:?}, console core {:?}, robot core {:?}, Python nice value {:?}; results in {}",
        s.parts.join(","),
        s.seconds,
        s.rate_hz,
        s.emulator_core,
        s.driver_core,
        s.robot_core,
        s.python_nice,
        s.out_dir.display()
    );
    let bench_host = host::HostTimer::start(None);
    let mut done = Vec::new();
    for transport in args::PARTS.into_iter().filter(|p| s.wants(p)) {
        if netfi::service::signals::stop_requested() {
            bail!("interrupted (Ctrl-C / SIGTERM): no results written");
        }
        println!("  {transport}: {} s …", s.seconds);
        done.push(parts::run(&s, transport)?);
    }
    report::write(&s, &done, &bench_host.stop())
}
