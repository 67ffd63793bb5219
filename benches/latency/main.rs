//! What the emulator adds to a frame's one-way latency, measured against a
//! direct hop in the same run: a real `netfi emulator` process on its own
//! core between two ends that this program plays in one thread on another
//! core (`common::chain`), over iceoryx2 and over kernel UDP, at each rate;
//! beside it the floor (one bare hop between the two cores, no emulator),
//! the probe (what the machine takes from a busy loop on each core), and
//! the release lateness while PLM-2 then DLM-2 holds hundreds of frames.
//!
//! ```sh
//! cargo bench --bench latency                                    # 10 s intervals, 3 repetitions
//! cargo bench --bench latency -- --transports iceoryx2 --rates-hz 1000 --seconds 60
//! ```
//!
//! added = chain − direct, percentile by percentile (docs/performance.md,
//! "Method").

#[path = "../common/mod.rs"]
mod common;
mod floor;
mod probe;

use anyhow::{ensure, Result};
use common::args::{Common, Cores, Placement, PLM2_DLM2};
use common::chain::{run_chain, ChainResult, Interval, Transport};
use common::drive::Routes;
use common::host::{clear_core, restore_core};
use common::out::Out;
use common::process::Build;
use common::table::{header, median_map, rate_label, row, spread_map, summary_map, Map};
use floor::FloorResult;
use netfi::metrics::Summary;
use probe::ProbeResult;
use serde::Serialize;
use serde_json::{json, Value};
use std::fmt::Write as _;
use std::path::PathBuf;

/// `cargo bench --bench latency -- [FLAGS]`.
#[derive(Debug, clap::Parser, Serialize)]
#[command(name = "latency", bin_name = "cargo bench --bench latency --", about = "What the emulator adds to a frame's one-way latency, against a direct hop in the same run")]
struct Args {
    #[command(flatten)]
    common: Common,
    #[command(flatten)]
    cores: Cores,
    /// The netfi binary whose emulator is measured [default: this
    /// package's build]
    #[arg(long, value_name = "PATH")]
    netfi: Option<PathBuf>,
    /// Frame rates on each route
    #[arg(long, value_delimiter = ',', default_value = "1000,100000")]
    rates_hz: Vec<f64>,
    #[arg(long, value_delimiter = ',', default_value = "iceoryx2,udp")]
    transports: Vec<Transport>,
    /// Length of each chain interval (the floor and the probe: half)
    #[arg(long, default_value_t = 10.0)]
    seconds: f64,
    #[arg(long, default_value_t = 3)]
    repetitions: usize,
    /// Leave out the iceoryx2 chain through PLM-2 then DLM-2 at 1 kHz
    #[arg(long)]
    no_delay: bool,
    /// Leave out the floor and the probe
    #[arg(long)]
    no_floor: bool,
}

/// Everything measured, interval by interval.
#[derive(Default, Serialize)]
struct Measured {
    chains: Vec<ChainResult>,
    floors: Vec<FloorResult>,
    probes: Vec<ProbeResult>,
}

fn main() {
    common::args::main("latency", "what the emulator adds to one-way latency (minutes)", run);
}

fn run(a: Args) -> Result<()> {
    ensure!(a.seconds > 0.0 && a.repetitions >= 1 && a.rates_hz.iter().all(|r| *r > 0.0), "--seconds, --repetitions and --rates-hz must be positive");
    let p = a.cores.placement(&a.common)?;
    let out = Out::create(&a.common, "latency")?;
    let build = Build::new("netfi", a.netfi.as_deref())?;
    let _ = netfi::transport::cleanup_stale();
    println!("latency: {}; {} s intervals, {} repetition(s)", p.line(), a.seconds, a.repetitions);
    let cleared = clear_core(&p);
    let mut m = Measured::default();
    for rep in 0..a.repetitions {
        repetition(&a, &p, &build, &out, rep, &mut m)?;
    }
    let (cleared, isolation) = restore_core(cleared);
    let mut md = format!("{}. {cleared}\n", p.line());
    let mut cells = Vec::new();
    for &t in &a.transports {
        for &rate in &a.rates_hz {
            cells.push(cell(&m, t, rate, &mut md));
        }
    }
    let delay = delay(&m, &mut md);
    probes_md(&m.probes, &mut md);
    out.finish(&a, json!({"placement": p, "isolation": isolation, "build": build, "latency": cells, "delay": delay, "intervals": m}), &md)
}

/// One repetition: per rate and transport a floor and a chain back to
/// back, then the probe, then the delay chain.
fn repetition(a: &Args, p: &Placement, build: &Build, out: &Out, rep: usize, m: &mut Measured) -> Result<()> {
    for &rate in &a.rates_hz {
        for &t in &a.transports {
            if !a.no_floor {
                let f = floor::floor_interval(p, t, rate, a.seconds / 2.0, rep)?;
                println!("  rep {rep} {:<8} {:>5} floor  {}", t.name(), rate_label(rate), f.hop_ns.line());
                m.floors.push(f);
            }
            let name = format!("{}-normal-{}-r{rep}", t.name(), rate_label(rate));
            let iv = Interval { name, transport: t, scenario: "Normal", rate_hz: rate, seconds: a.seconds, routes: Routes::Alternate, delayed: false, queue_capacity: None };
            let c = run_chain(build, out, p, &iv)?;
            println!("  rep {rep} {:<8} {:>5} chain  {}; direct {}; {}", t.name(), rate_label(rate), c.chain_ns.line(), c.direct_ns.line(), c.host.line());
            m.chains.push(c);
        }
    }
    if !a.no_floor {
        m.probes.extend(probe::probe_interval(p, a.seconds / 2.0, rep)?);
    }
    if !a.no_delay {
        let name = format!("iceoryx2-plm2_dlm2-1k-r{rep}");
        let iv = Interval { name, transport: Transport::Iceoryx2, scenario: PLM2_DLM2, rate_hz: 1000.0, seconds: a.seconds, routes: Routes::Alternate, delayed: true, queue_capacity: None };
        let c = run_chain(build, out, p, &iv)?;
        let late = c.emulator.release_lateness_ns.map_or("–".into(), |s| s.line());
        println!("  rep {rep} iceoryx2 PLM-2 + DLM-2 1k: release lateness {late}; {}", c.host.line());
        m.chains.push(c);
    }
    Ok(())
}

/// The median over repetitions of each percentile of `f`.
fn med<T>(items: &[&T], f: impl Fn(&T) -> Option<Summary>) -> Map {
    median_map(&items.iter().filter_map(|x| f(x).map(|s| summary_map(&s))).collect::<Vec<_>>())
}

/// The Normal chains of transport `t` at `rate`, with their floors: the
/// median over repetitions of each percentile, and its table.
fn cell(m: &Measured, t: Transport, rate: f64, md: &mut String) -> Value {
    let cs: Vec<&ChainResult> = m.chains.iter().filter(|c| c.transport == t && c.rate_hz == rate && c.scenario == "Normal").collect();
    let fs: Vec<&FloorResult> = m.floors.iter().filter(|f| f.transport == t && f.rate_hz == rate).collect();
    let added: Vec<Map> = cs.iter().map(|c| c.added_ns.clone()).collect();
    let rows: [(&str, Map); 8] = [
        ("floor: one cross-core hop, no emulator", med(&fs, |f| Some(f.hop_ns))),
        ("direct, alternating with the chain", med(&cs, |c| Some(c.direct_ns))),
        ("chain through the emulator", med(&cs, |c| Some(c.chain_ns))),
        ("**added = chain − direct**", median_map(&added)),
        ("chain: send → taken by the emulator", med(&cs, |c| c.hop1_ns)),
        ("chain: inside the emulator", med(&cs, |c| c.inside_ns)),
        ("chain: released → received", med(&cs, |c| c.hop2_ns)),
        ("emulator release lateness", med(&cs, |c| c.emulator.release_lateness_ns)),
    ];
    let steal = cs.iter().map(|c| c.host.steal_fraction).chain(fs.iter().map(|f| f.host.steal_fraction)).fold(0.0, f64::max);
    let _ = writeln!(md, "\n## {} at {} frames/s ({} repetitions; steal up to {:.2}%)\n\n{}", t.name(), rate_label(rate), cs.len(), steal * 100.0, header("one-way latency"));
    for (label, m) in rows.iter().filter(|(_, m)| !m.is_empty()) {
        let _ = writeln!(md, "{}", row(label, m));
    }
    let spread = spread_map(&added);
    let rows: serde_json::Map<String, Value> = rows.iter().map(|(k, v)| (k.trim_matches('*').to_string(), json!(v))).collect();
    json!({"transport": t, "rate_hz": rate, "repetitions": cs.len(), "steal_fraction_max": steal, "median_ns": rows, "added_spread_ns": spread})
}

/// The delay chains (every chain not of Normal): release lateness,
/// decision and the end-to-end time beyond the injected delay.
fn delay(m: &Measured, md: &mut String) -> Value {
    let ds: Vec<&ChainResult> = m.chains.iter().filter(|c| c.scenario != "Normal").collect();
    if ds.is_empty() {
        return Value::Null;
    }
    let rows = [
        ("release lateness (actual − scheduled)", med(&ds, |c| c.emulator.release_lateness_ns)),
        ("decision (taken → fate)", med(&ds, |c| c.emulator.decision_ns)),
        ("end to end beyond the injected delay", med(&ds, |c| Some(c.chain_ns))),
    ];
    let lateness: Vec<Map> = ds.iter().filter_map(|c| c.emulator.release_lateness_ns.map(|s| summary_map(&s))).collect();
    let _ = writeln!(md, "\n## iceoryx2, PLM-2 then DLM-2, 1k frames/s ({} repetitions)\n\n{}", ds.len(), header(""));
    for (label, m) in &rows {
        let _ = writeln!(md, "{}", row(label, m));
    }
    json!({"repetitions": ds.len(), "release_lateness_ns": rows[0].1, "release_lateness_spread_ns": spread_map(&lateness), "decision_ns": rows[1].1, "beyond_injected_delay_ns": rows[2].1})
}

fn probes_md(probes: &[ProbeResult], md: &mut String) {
    if probes.is_empty() {
        return;
    }
    let _ = writeln!(md, "\n## What the machine takes from a busy loop\n\n| repetition | core | gaps over 10 µs a second | over 100 µs | over 1 ms | time lost in gaps over 10 µs | steal |\n|---|---|---|---|---|---|---|");
    for p in probes {
        let core = p.core.map_or("-".to_string(), |c| c.to_string());
        let _ = writeln!(
            md,
            "| {} | {core} | {:.1} | {:.2} | {:.2} | {:.3}% | {:.2}% |",
            p.repetition,
            p.gaps_over_10us_per_s,
            p.gaps_over_100us_per_s,
            p.gaps_over_1ms_per_s,
            p.lost_fraction * 100.0,
            p.host.steal_fraction * 100.0
        );
    }
}
