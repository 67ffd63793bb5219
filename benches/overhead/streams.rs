//! The stream-count part: one `netfi emulator --streams N` serving N
//! console → robot pairs at 1 kHz per route each, for N in
//! `NETFI_BENCH_STREAMS` (default 1, 2, 8, 32). The benchmark plays all N
//! consoles and robots itself, in one thread on the other core (as the
//! chain intervals do for one): stream k's frames come k/N of a slot after
//! stream 0's, chain and direct alternating, every port polled between
//! sends. Per N: the emulator's release lateness (each stream's, from its
//! `emulator.json`: the median and the worst of the streams' percentiles),
//! the time inside it (release − taken, every frame of every stream), and
//! the latency it adds over the direct hop; with the host's steal and load
//! beside each.

use crate::args::Settings;
use crate::drive::{drive_many, slots_for, Routes};
use crate::emulator::{self, Emulator};
use crate::ends::IpcEnds;
use crate::host::{pin, HostTimer};
use crate::{check_interrupted, Results};
use anyhow::{Context, Result};
use netfi::metrics::{difference, fmt_ns, Summary};
use netfi::service::plan::{fresh_run_id, stream_run_id};
use serde_json::{json, Value};
use std::time::Duration;

/// The rate of each stream's routes, Hz.
const RATE_HZ: f64 = 1000.0;

/// The streams' `p` percentile of release lateness: their median and worst.
fn across(reports: &[netfi::service::emulator::EmulatorReport], p: impl Fn(&Summary) -> u64) -> (u64, u64) {
    let mut v: Vec<u64> = reports.iter().map(|r| p(&r.shaping.link.release_lateness_ns)).collect();
    v.sort_unstable();
    (v[v.len() / 2], v[v.len() - 1])
}

/// One point: N streams for the interval's length, repetition `rep`.
fn point(s: &Settings, n: usize, rep: usize) -> Result<Value> {
    check_interrupted()?;
    let dir = s.out_dir.join("runs").join(format!("streams-{n}-r{rep}"));
    let _ = std::fs::remove_dir_all(&dir);
    let run_id = fresh_run_id();
    let (_, slots) = slots_for(RATE_HZ, s.interval_s, Routes::Alternate);
    let mut args = emulator::args(s, "Normal", &dir, slots / 2 + 16, Some(run_id.clone()));
    args.stream.streams = n as u32;
    let _forget = emulator::ForgetRuns((0..n).map(|k| stream_run_id(&run_id, k)).collect());
    let emu = Emulator::spawn(&dir, &emulator::argv(&args, &[]))?;
    let mut ends = (0..n).map(|k| IpcEnds::open(&stream_run_id(&run_id, k))).collect::<Result<Vec<_>>>()?;
    let host = HostTimer::start(s.quiet);
    let d = drive_many(&mut ends, RATE_HZ, s.interval_s, 200_000_000);
    let host = host.stop();
    for e in ends.iter_mut() {
        e.end(slots / 2);
    }
    let reports = emu.finish_streams(Duration::from_secs(10), n).context("the emulator's reports")?;
    drop(ends);
    let (chain, direct, inside) = (d.chain.summary(), d.direct.summary(), d.inside.summary());
    let added = difference(&chain, &direct, &["p50", "p90", "p99", "p999"]);
    let (late_p50_median, late_p50_worst) = across(&reports, |x| x.p50);
    let (late_p99_median, late_p99_worst) = across(&reports, |x| x.p99);
    let lost = d.chain_sent - d.chain_received;
    println!(
        "  rep {rep} streams {n:>2}: release lateness p50 {} (worst stream {}), p99 {} (worst {}); inside p99 {}; added over direct p50 {} ns p99 {} ns; chain lost {lost}; steal {:.3}%, load {:.2}→{:.2}",
        fmt_ns(late_p50_median),
        fmt_ns(late_p50_worst),
        fmt_ns(late_p99_median),
        fmt_ns(late_p99_worst),
        fmt_ns(inside.p99),
        added["p50"],
        added["p99"],
        host.steal_fraction * 100.0,
        host.load_start,
        host.load_end
    );
    Ok(json!({
        "streams": n,
        "repetition": rep,
        "rate_hz_per_stream": RATE_HZ,
        "seconds": d.seconds,
        "host": host,
        "release_lateness_ns": {"p50_median": late_p50_median, "p50_worst": late_p50_worst, "p99_median": late_p99_median, "p99_worst": late_p99_worst},
        "inside_ns": inside,
        "chain_ns": chain,
        "direct_ns": direct,
        "added_ns": added,
        "send_lateness_ns": d.send_lateness.summary(),
        "chain_sent": d.chain_sent,
        "chain_received": d.chain_received,
        "refused": d.refused,
        "out_dir": dir,
    }))
}

/// The part: every stream count, `repetitions` times; `streams.json` and
/// a table on stdout, with the p99 bar (N = 32 at most twice N = 1).
pub fn streams_part(s: &Settings, res: &mut Results) -> Result<()> {
    pin(s.driver_core, s.rt_priority);
    for rep in 0..s.repetitions {
        for &n in &s.stream_counts {
            res.streams.push(point(s, n, rep)?);
        }
    }
    let p99 = |n: usize| -> Option<f64> {
        let mut v: Vec<f64> = res.streams.iter().filter(|p| p["streams"] == n).filter_map(|p| p["release_lateness_ns"]["p99_median"].as_f64()).collect();
        v.sort_by(f64::total_cmp);
        v.get(v.len() / 2).copied()
    };
    let (lo, hi) = (s.stream_counts.first().copied().unwrap_or(1), s.stream_counts.last().copied().unwrap_or(1));
    if let (Some(a), Some(b)) = (p99(lo), p99(hi)) {
        println!("  release lateness p99 at {hi} streams / at {lo}: {:.2}× (bar: at most 2×) — {}", b / a, if b <= 2.0 * a { "met" } else { "not met" });
    }
    let path = s.out_dir.join("streams.json");
    std::fs::write(&path, serde_json::to_vec_pretty(&res.streams)?).with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}
