//! What the emulator alone sustains: a real `netfi emulator` (trace,
//! histograms and report as always) with this program playing console and
//! robot in one thread on another core, every frame through the emulator,
//! so the rate stops where the emulator stops keeping up, not where a
//! console on a shared core does. Each trial also records the emulator
//! loop's own time a frame (`busy` in `emulator.json`): the cost curve
//! against the rate (`cost.csv`, axis `rate`).
//!
//! ```sh
//! cargo bench --bench capacity                                 # 7·10^5 and 10^6 frames/s, Normal and PLM-2 + DLM-2, 10 s each
//! cargo bench --bench capacity -- --rates-hz 1000000 --repetitions 3 --search
//! ```
//!
//! A trial is sustained when every frame sent entered the emulator, every
//! frame it delivered came back, nothing was dropped outside the scenario
//! or left held, no trace row was lost, and the thread really offered the
//! rate (at least 98% of it, from its first to its last send).

#[path = "common/mod.rs"]
mod common;

use anyhow::{ensure, Result};
use common::args::{Common, Cores, Placement, PLM2_DLM2};
use common::chain::{run_chain, ChainResult, Interval, Transport};
use common::drive::Routes;
use common::host::{clear_core, restore_core, speed_on, Speed};
use common::out::{CostRow, Out};
use common::process::{scenario_label, Build};
use common::table::{ns, rate_label};
use serde::Serialize;
use serde_json::json;
use std::fmt::Write as _;
use std::path::PathBuf;

/// `cargo bench --bench capacity -- [FLAGS]`.
#[derive(Debug, clap::Parser, Serialize)]
#[command(name = "capacity", bin_name = "cargo bench --bench capacity --", about = "What the emulator alone sustains, and its time a frame against the rate")]
struct Args {
    #[command(flatten)]
    common: Common,
    #[command(flatten)]
    cores: Cores,
    /// The netfi binary whose emulator is measured [default: this
    /// package's build]
    #[arg(long, value_name = "PATH")]
    netfi: Option<PathBuf>,
    /// Rates tried, frames a second
    #[arg(long, value_delimiter = ',', default_value = "700000,1000000")]
    rates_hz: Vec<f64>,
    /// A scenario (preset or file), repeatable [default: Normal and
    /// config/scenarios/plm2_dlm2.toml]
    #[arg(long = "scenario", value_name = "SCENARIO")]
    scenarios: Vec<String>,
    /// Length of each trial, after a 0.5 s warm-up
    #[arg(long, default_value_t = 10.0)]
    seconds: f64,
    /// Trials at each rate
    #[arg(long, default_value_t = 1)]
    repetitions: usize,
    /// Then search from the first rate (doubling up to twice it, or
    /// halving) to within 5% of the highest rate sustained
    #[arg(long)]
    search: bool,
}

/// One trial.
#[derive(Debug, Serialize)]
struct Trial {
    scenario: String,
    rate_hz: f64,
    verdict: String,
    sustained: bool,
    offered_fps: f64,
    busy_ns_per_frame: Option<f64>,
    /// The driving core's speed before and after (`common::host::speed`).
    speed_before: Speed,
    speed_after: Speed,
    chain: ChainResult,
}

fn main() {
    common::args::main("capacity", "what the emulator alone sustains (minutes)", run);
}

fn run(a: Args) -> Result<()> {
    ensure!(a.seconds > 0.0 && a.repetitions >= 1 && !a.rates_hz.is_empty() && a.rates_hz.iter().all(|r| *r >= 1000.0), "--seconds and --repetitions must be positive, --rates-hz at least 1000");
    let p = a.cores.placement(&a.common)?;
    let out = Out::create(&a.common, "capacity")?;
    let build = Build::new("netfi", a.netfi.as_deref())?;
    let _ = netfi::transport::cleanup_stale();
    let cleared = clear_core(&p);
    let scenarios = if a.scenarios.is_empty() { vec!["Normal".to_string(), PLM2_DLM2.to_string()] } else { a.scenarios.clone() };
    let mut trials = Vec::new();
    let mut best = serde_json::Map::new();
    for sc in &scenarios {
        let mut run_at = |rate: f64| -> Result<bool> {
            let t = trial(&a, &p, &build, &out, sc, rate, trials.len())?;
            let ok = t.sustained;
            trials.push(t);
            Ok(ok)
        };
        for &rate in &a.rates_hz {
            for _ in 0..a.repetitions {
                run_at(rate)?;
            }
        }
        if a.search {
            let found = search_rates(a.rates_hz[0], 2.0 * a.rates_hz[0], &mut run_at)?;
            best.insert(scenario_label(sc), json!(found));
        }
    }
    let (cleared, isolation) = restore_core(cleared);
    let rows: Vec<CostRow> = trials
        .iter()
        .filter(|t| t.sustained)
        .filter_map(|t| Some(CostRow { axis: "rate", x: t.offered_fps.round(), series: format!("emulator busy ns a frame (capacity: {})", t.scenario), ns: t.busy_ns_per_frame? }))
        .collect();
    out.write_cost(&rows)?;
    let md = markdown(&p, &cleared, &trials, &best);
    out.finish(&a, json!({"placement": p, "isolation": isolation, "build": build, "best_sustained_fps": best, "trials": trials}), &md)
}

fn trial(a: &Args, p: &Placement, build: &Build, out: &Out, scenario: &str, rate_hz: f64, k: usize) -> Result<Trial> {
    let speed_before = speed_on(p.bench_core);
    let name = format!("{k}-{}-{}", scenario_label(scenario), rate_label(rate_hz));
    // The release queue holds a second of frames, so a delay scenario tests
    // the emulator's speed, not the queue's size.
    let queue = Some((rate_hz as usize).max(1 << 16));
    let iv = Interval { name, transport: Transport::Iceoryx2, scenario, rate_hz, seconds: a.seconds, routes: Routes::ChainOnly, delayed: scenario != "Normal", queue_capacity: queue };
    let c = run_chain(build, out, p, &iv)?;
    let speed_after = speed_on(p.bench_core);
    let offered_fps = if c.send_seconds > 0.0 { (rate_hz * a.seconds).round() / c.send_seconds } else { 0.0 };
    let verdict = verdict(&c, offered_fps);
    let busy = c.emulator.busy_ns_per_frame();
    println!(
        "  {:<10} {:>9.0} frames/s: {verdict} (offered {offered_fps:.0}/s; busy {} ns a frame; release lateness p99 {}; {}; core speed {:.2}/{:.2} ns a step)",
        scenario_label(scenario),
        rate_hz,
        busy.map_or("-".into(), |b| format!("{b:.0}")),
        c.emulator.release_lateness_ns.map_or("–".into(), |s| ns(s.p99 as i64)),
        c.host.line(),
        speed_before.alu_ns,
        speed_after.alu_ns
    );
    Ok(Trial { scenario: scenario_label(scenario), rate_hz, sustained: verdict == "sustained", verdict, offered_fps, busy_ns_per_frame: busy, speed_before, speed_after, chain: c })
}

/// Why a trial was not sustained, or "sustained".
fn verdict(c: &ChainResult, offered_fps: f64) -> String {
    let e = &c.emulator;
    let unintended: Vec<String> = e.dropped.iter().filter(|(k, _)| matches!(k.as_str(), "queue_full" | "wrong_size" | "bad_checksum")).map(|(k, v)| format!("{v} {k}")).collect();
    if c.refused > 0 {
        format!("the emulator's port refused {} frames", c.refused)
    } else if e.entered < c.chain_sent {
        format!("{} frames sent never entered the emulator", c.chain_sent - e.entered)
    } else if !unintended.is_empty() {
        format!("dropped outside the scenario: {}", unintended.join(", "))
    } else if c.chain_received < e.delivered {
        format!("{} frames delivered but not received", e.delivered - c.chain_received)
    } else if e.held_at_end > 0 {
        format!("{} frames still held at the end", e.held_at_end)
    } else if e.trace_overflowed > 0 {
        format!("{} trace rows lost", e.trace_overflowed)
    } else if offered_fps < 0.98 * c.rate_hz {
        format!("the driving thread offered only {offered_fps:.0} frames/s")
    } else {
        "sustained".to_string()
    }
}

/// The highest rate `run` sustains: doubling from `start_hz` (at most
/// `max_hz`) until a rate fails, or halving (down to 1 000/s) until one
/// passes, then bisection to 5% (rates rounded to 1 000/s). `None` if no
/// rate passed.
fn search_rates(start_hz: f64, max_hz: f64, mut run: impl FnMut(f64) -> Result<bool>) -> Result<Option<f64>> {
    let (mut lo, mut hi): (Option<f64>, Option<f64>) = (None, None);
    let mut rate = start_hz;
    while run(rate)? {
        lo = Some(rate);
        if rate >= max_hz {
            break;
        }
        rate = (rate * 2.0).min(max_hz);
    }
    if lo != Some(rate) {
        hi = Some(rate);
    }
    let mut r = start_hz / 2.0;
    while lo.is_none() && r >= 1000.0 {
        if run(r)? {
            lo = Some(r);
        } else {
            hi = Some(r);
        }
        r /= 2.0;
    }
    while let (Some(l), Some(h)) = (lo, hi) {
        let mid = ((l + h) / 2.0 / 1000.0).round() * 1000.0;
        if (h - l) / l <= 0.05 || mid <= l || mid >= h {
            break;
        }
        if run(mid)? {
            lo = Some(mid);
        } else {
            hi = Some(mid);
        }
    }
    Ok(lo)
}

fn markdown(p: &Placement, cleared: &str, trials: &[Trial], best: &serde_json::Map<String, serde_json::Value>) -> String {
    let mut md = format!("{}. {cleared}\n\n", p.line());
    let _ = writeln!(md, "| scenario | rate, frames/s | verdict | offered | emulator busy ns a frame | release lateness p99 | steal | core speed before / after, ns a step |\n|---|---|---|---|---|---|---|---|");
    for t in trials {
        let _ = writeln!(
            md,
            "| {} | {:.0} | {} | {:.0} | {} | {} | {:.2}% | {:.2} / {:.2} |",
            t.scenario,
            t.rate_hz,
            t.verdict,
            t.offered_fps,
            t.busy_ns_per_frame.map_or("–".into(), |b| format!("{b:.0}")),
            t.chain.emulator.release_lateness_ns.map_or("–".into(), |s| ns(s.p99 as i64)),
            t.chain.host.steal_fraction * 100.0,
            t.speed_before.alu_ns,
            t.speed_after.alu_ns
        );
    }
    for (k, v) in best {
        let _ = writeln!(md, "\n{k}: the highest rate sustained in the search, {} frames/s.", v.as_f64().map_or("none".into(), |v| format!("{v:.0}")));
    }
    md
}
