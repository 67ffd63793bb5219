//! The cost of the stream count: one `netfi emulator --streams N` serving
//! N console → robot pairs at 1 kHz per route each, this program playing
//! all N consoles and robots in one thread on another core (stream k's
//! frames k/N of a slot after stream 0's, chain and direct alternating,
//! every port polled between sends). Per N: each stream's release
//! lateness (the median stream's and the worst), the time inside the
//! emulator, and the latency it adds over the direct hop, with the steal
//! and load beside each point; the curve in `cost.csv` (axis `streams`).
//!
//! ```sh
//! cargo bench --bench streams                       # N = 1, 2, 8, 32; 10 s each, 3 repetitions
//! cargo bench --bench streams -- --counts 1,64 --seconds 30
//! ```

#[path = "common/mod.rs"]
mod common;

use anyhow::{ensure, Context, Result};
use common::args::{check_interrupted, Placement};
use common::drive::{drive, slots_for, Routes};
use common::ends::IpcEnds;
use common::host::{clear_core, pin, restore_core, HostTimer};
use common::out::{CostRow, Out};
use common::process::{fresh_run_id, summary, Build, EmulatorSpec, ForgetRuns, OneBuild};
use netfi::service::args::streams;
use netfi::transport::udp::UdpArgs;
use common::table::{ns, Spread};
use netfi::metrics::difference;
use serde::Serialize;
use serde_json::{json, Value};
use std::fmt::Write as _;
use std::time::Duration;

/// Frames a second on each route of each stream.
const RATE_HZ: f64 = 1000.0;

/// `cargo bench --bench streams -- [FLAGS]`.
#[derive(Debug, clap::Parser, Serialize)]
#[command(name = "streams", bin_name = "cargo bench --bench streams --", about = "Release lateness and added latency against the number of streams one emulator serves")]
struct Args {
    #[command(flatten)]
    #[serde(flatten)]
    build: OneBuild,
    /// Stream counts (1 to 64)
    #[arg(long, value_delimiter = ',', default_value = "1,2,8,32")]
    counts: Vec<usize>,
    /// Length of each point
    #[arg(long, default_value_t = 10.0)]
    seconds: f64,
    #[arg(long, default_value_t = 3)]
    repetitions: usize,
}

fn main() {
    common::args::main("streams", "the cost of the stream count (minutes)", run);
}

fn run(a: Args) -> Result<()> {
    ensure!(a.seconds > 0.0 && a.repetitions >= 1, "--seconds and --repetitions must be positive");
    ensure!(a.counts.iter().all(|n| (1..=64).contains(n)), "--counts: from 1 to 64 streams");
    let (p, out, build) = a.build.start("streams")?;
    let _ = netfi::transport::cleanup_stale();
    let cleared = clear_core(&p);
    pin(p.bench_core, p.rt_priority);
    let mut points = Vec::new();
    for rep in 0..a.repetitions {
        for &n in &a.counts {
            points.push(point(&a, &p, &build, &out, n, rep)?);
        }
    }
    let (cleared, isolation) = restore_core(cleared);
    let mut md = format!("{}. {cleared}\n\nMedian over the repetitions (least – largest); release lateness of the median stream and of the worst.\n\n", p.line());
    let _ = writeln!(md, "| streams | release lateness p50 | p99 | p99, worst stream | added over the direct hop, p50 | p99 | steal |\n|---|---|---|---|---|---|---|");
    let mut rows = Vec::new();
    for &n in &a.counts {
        let at = |path: &str| Spread::of(points.iter().filter(|p| p["streams"] == n).filter_map(|p| common::process::num(p, path)));
        let (p99, steal) = (at("release_lateness_ns.p99_median"), at("host.steal_fraction"));
        let s = |x: Option<Spread>| x.map_or("–".into(), |x| x.ns());
        let steal = steal.map_or("–".into(), |s| s.percent());
        let _ = writeln!(md, "| {n} | {} | {} | {} | {} | {} | {steal} |", s(at("release_lateness_ns.p50_median")), s(p99), s(at("release_lateness_ns.p99_worst")), s(at("added_ns.p50")), s(at("added_ns.p99")));
        if let Some(p99) = p99 {
            rows.push(CostRow { axis: "streams", x: n as f64, series: "release lateness p99 (median stream; streams benchmark)".into(), ns: p99.median });
        }
    }
    out.write_cost(&rows)?;
    out.finish(&a, json!({"placement": p, "isolation": isolation, "build": build, "rate_hz_per_stream": RATE_HZ, "points": points}), &md)
}

/// One point: N streams for the interval's length.
fn point(a: &Args, p: &Placement, build: &Build, out: &Out, n: usize, rep: usize) -> Result<Value> {
    check_interrupted()?;
    let dir = out.run_dir(&format!("streams-{n}-r{rep}"))?;
    let run_id = fresh_run_id();
    let (_, slots) = slots_for(RATE_HZ, a.seconds, Routes::Alternate);
    let spec = EmulatorSpec {
        scenario: "Normal",
        dir: &dir,
        expected_frames: slots / 2 + 16,
        run_id: Some(&run_id),
        feedback: false,
        queue_capacity: None,
        ends: Default::default(),
        udp: UdpArgs::default(),
        streams: n as u32,
    };
    let _forget = ForgetRuns((0..n).map(|k| streams::run_id(&run_id, k)).collect());
    let emu = build.emulator(&spec, p)?;
    let mut ends = (0..n).map(|k| IpcEnds::open(&streams::run_id(&run_id, k))).collect::<Result<Vec<_>>>()?;
    let host = HostTimer::start(p.quiet);
    let d = drive(&mut ends, RATE_HZ, a.seconds, 200_000_000, true, Routes::Alternate);
    let host = host.stop();
    for e in ends.iter_mut() {
        e.end(slots / 2);
    }
    let reports = emu.finish_streams(Duration::from_secs(10), n).context("the emulator's reports")?;
    drop(ends);
    // Each stream's percentile of release lateness: their median and worst.
    let across = |key: &str| {
        let mut v: Vec<u64> = reports.iter().filter_map(|r| summary(r, "release_lateness_ns")).filter_map(|s| s.get(key)).collect();
        v.sort_unstable();
        (v.get(v.len() / 2).copied(), v.last().copied())
    };
    let ((p50_median, p50_worst), (p99_median, p99_worst)) = (across("p50"), across("p99"));
    let (chain, direct, inside) = (d.chain.summary(), d.direct.summary(), d.inside.summary());
    let added = difference(&chain, &direct, &["p50", "p90", "p99", "p999"]);
    println!(
        "  rep {rep} streams {n:>2}: release lateness p50 {} p99 {} (worst stream {}); added p50 {} p99 {}; chain lost {}; {}",
        ns(p50_median.unwrap_or(0) as i64),
        ns(p99_median.unwrap_or(0) as i64),
        ns(p99_worst.unwrap_or(0) as i64),
        ns(added["p50"]),
        ns(added["p99"]),
        d.chain_sent - d.chain_received,
        host.line()
    );
    Ok(json!({
        "streams": n,
        "repetition": rep,
        "seconds": d.seconds,
        "host": host,
        "release_lateness_ns": {"p50_median": p50_median, "p50_worst": p50_worst, "p99_median": p99_median, "p99_worst": p99_worst},
        "inside_ns": inside,
        "chain_ns": chain,
        "direct_ns": direct,
        "added_ns": added,
        "send_lateness_ns": d.send_lateness.summary(),
        "chain_sent": d.chain_sent,
        "chain_received": d.chain_received,
        "refused": d.refused,
        "dir": dir,
    }))
}
