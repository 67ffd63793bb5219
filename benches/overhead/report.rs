//! The results written: `overhead.json` (every figure) and `overhead.md`
//! (the same as tables), and the tables printed.

use crate::args::Settings;
use crate::figures::{ns, row, Figures};
use crate::host::{host_facts, HostWindow};
use crate::Results;
use anyhow::{Context, Result};
use netfi::host::isolate::IsolationSummary;
use netfi::metrics::fmt_ns;
use serde_json::{json, Value};
use std::collections::BTreeMap;
use std::fmt::Write as _;

/// How the whole benchmark went: the host over it, what was cleared, how
/// long it took.
pub struct Overall {
    pub host: HostWindow,
    pub isolation: Option<IsolationSummary>,
    pub minutes: f64,
}

/// `overhead.json`.
pub fn document(s: &Settings, res: &Results, fig: &Figures, all: &Overall) -> Value {
    json!({
        "schema": "netfi-bench/overhead/1",
        "host": host_facts(s),
        "settings": s,
        "isolation": all.isolation,
        "host_over_the_benchmark": all.host,
        "minutes": all.minutes,
        "added_latency_ns": fig.added,
        "added_latency_spread_ns": fig.added_spread,
        "chain_ns": fig.chain,
        "direct_ns": fig.direct,
        "floor_ns": fig.floor,
        "release_lateness_ns": fig.lateness,
        "throughput_fps": res.throughput_fps,
        "throughput": res.throughput,
        "capacity": res.capacity,
        "product_run": res.products,
        "probe_intervals": res.probes,
        "sockperf": fig.sockperf,
        "sockperf_intervals": res.sockperfs,
        "bars": fig.bars,
        "chain_intervals": res.chains,
        "floor_intervals": res.floors,
    })
}

/// Writes both files into the output directory and prints the tables.
pub fn write(s: &Settings, res: &Results, fig: &Figures, all: &Overall) -> Result<()> {
    let doc = document(s, res, fig, all);
    let json_path = s.out_dir.join("overhead.json");
    std::fs::write(&json_path, serde_json::to_vec_pretty(&doc)?).with_context(|| format!("writing {}", json_path.display()))?;
    let mut md = String::new();
    header(&mut md, s, &doc, all);
    if !fig.md_latency.is_empty() {
        let _ = writeln!(md, "\n## One-way latency, Normal scenario (nothing injected)\n{}", fig.md_latency);
    }
    if !fig.md_delay.is_empty() {
        let _ = writeln!(md, "\n## Under delay\n{}", fig.md_delay);
    }
    sockperf(&mut md, s, fig);
    probes(&mut md, res);
    products(&mut md, res);
    throughput(&mut md, s, res);
    capacity(&mut md, s, res);
    bars(&mut md, fig);
    let _ = writeln!(md, "\nHdrHistogram logs: `hlog/`; each run's files: `runs/`. Method: `docs/performance.md`.");
    let md_path = s.out_dir.join("overhead.md");
    std::fs::write(&md_path, &md).with_context(|| format!("writing {}", md_path.display()))?;
    println!("\n{md}");
    println!("written: {} and {}", json_path.display(), md_path.display());
    Ok(())
}

fn header(md: &mut String, s: &Settings, doc: &Value, all: &Overall) {
    let _ = writeln!(md, "# netfi overhead\n");
    let _ = writeln!(
        md,
        "{} cores ({}), kernel {}, clock source {}; emulator on core {:?}, the benchmark's ends on core {:?}. {} s intervals (floors {} s), {} repetition(s); {:.1} minutes; steal over the whole benchmark {:.2}%.",
        doc["host"]["cores"],
        doc["host"]["cpu_model"].as_str().unwrap_or("?"),
        doc["host"]["kernel"].as_str().unwrap_or("?"),
        doc["host"]["clocksource"].as_str().unwrap_or("?"),
        s.emulator_core,
        s.driver_core,
        s.interval_s,
        s.floor_s,
        s.repetitions,
        all.minutes,
        all.host.steal_fraction * 100.0
    );
    match &all.isolation {
        Some(i) => {
            let _ = writeln!(md, "\nThe emulator's core was cleared for the benchmark (`NETFI_BENCH_ISOLATE`, default on), and all put back at the end: {i}.");
        }
        None => {
            let _ = writeln!(md, "\nThe emulator's core was not cleared (`NETFI_BENCH_ISOLATE=0`, or not permitted): other threads could run on it.");
        }
    }
}

fn sockperf(md: &mut String, s: &Settings, fig: &Figures) {
    for f in fig.sockperf.values() {
        let m = |k: &str| serde_json::from_value::<BTreeMap<String, i64>>(f[k]["median"].clone()).unwrap_or_default();
        let halt = f["guest_halt_poll_ns"].as_u64();
        let _ = writeln!(
            md,
            "\n## sockperf ping-pong through the UDP bridge (guest halt polling {})\n\n64-byte messages, client and server on core {:?}, `netfi emulator --payload raw` (Normal) on core {:?}; sockperf's latency (half the round trip; the round trip is twice it); {} repetition(s).\n",
            halt.map_or("not available".to_string(), |n| format!("{n} ns")),
            s.driver_core,
            s.emulator_core,
            f["repetitions"],
        );
        let _ = writeln!(md, "| sockperf latency | p50 | p90 | p99 | p99.9 | p99.99 | max |\n|---|---|---|---|---|---|---|");
        let _ = writeln!(md, "{}", row("direct (client → server)", &m("direct_ns")));
        let _ = writeln!(md, "{}", row("through netfi (client → emulator → server, and back)", &m("through_netfi_ns")));
        let _ = writeln!(md, "{}", row("**added**", &m("added_ns")));
    }
}

fn probes(md: &mut String, res: &Results) {
    if res.probes.is_empty() {
        return;
    }
    let _ = writeln!(md, "\n## What the machine takes from a busy loop on each core\n");
    let _ = writeln!(md, "| repetition | core | gaps over 10 µs /s | over 100 µs /s | over 1 ms /s | time lost in gaps over 10 µs | longest gap | steal | other processes |\n|---|---|---|---|---|---|---|---|---|");
    for p in &res.probes {
        let _ = writeln!(
            md,
            "| {} | {} | {:.1} | {:.2} | {:.2} | {:.3}% | {} | {:.2}% | {:.2} cores |",
            p.repetition,
            p.core.map_or("-".to_string(), |c| c.to_string()),
            p.gaps_over_10us_per_s,
            p.gaps_over_100us_per_s,
            p.gaps_over_1ms_per_s,
            p.lost_fraction * 100.0,
            fmt_ns(p.gaps_ns.max),
            p.host.steal_fraction * 100.0,
            p.host.others_busy_cores
        );
    }
}

fn products(md: &mut String, res: &Results) {
    if res.products.is_empty() {
        return;
    }
    let _ = writeln!(md, "\n## `netfi run Normal` as shipped (console and simulator share a core on 2 cores)\n");
    let _ = writeln!(
        md,
        "| repetition | end-to-end extra p50 / p99 | direct hop p50 / p99 | added over direct p50 / p99 | release lateness p99 | steal | other processes |\n|---|---|---|---|---|---|---|"
    );
    for p in &res.products {
        let g = |k: &str, q: &str| p[k][q].as_i64().map_or("?".into(), ns);
        let _ = writeln!(
            md,
            "| {} | {} / {} | {} / {} | {} / {} | {} | {:.2}% | {:.2} cores |",
            p["repetition"],
            g("end_to_end_extra_ns", "p50"),
            g("end_to_end_extra_ns", "p99"),
            g("direct_hop_ns", "p50"),
            g("direct_hop_ns", "p99"),
            g("added_over_direct_ns", "p50"),
            g("added_over_direct_ns", "p99"),
            g("release_lateness_ns", "p99"),
            p["steal_fraction"].as_f64().unwrap_or(0.0) * 100.0,
            p["host"]["others_busy_cores"].as_f64().unwrap_or(f64::NAN)
        );
    }
}

fn throughput(md: &mut String, s: &Settings, res: &Results) {
    if res.throughput.is_empty() {
        return;
    }
    let _ = writeln!(md, "\n## Throughput ({} s per trial, `netfi run --no-direct`)\n", s.throughput_trial_s);
    let _ = writeln!(
        md,
        "| scenario | sustained, frames/s | first rate not sustained, and why | emulator capacity, frames/s (busy ns a frame, at offered rate) | without busy turns over 200 µs | capacity range over the trials | capacity bar met (every busy turn counted) |\n|---|---|---|---|---|---|---|"
    );
    for (k, v) in &res.throughput {
        let c = &v["emulator_capacity"];
        let f = |x: &Value| x.as_f64().map_or("-".to_string(), |x| format!("{x:.0}"));
        let _ = writeln!(
            md,
            "| {k} | {:.0} | {} | {} ({} ns at {}) | {} ({} ns) | {}–{} | {} (≥ {}) |",
            v["best_fps"].as_f64().unwrap_or(0.0),
            v["first_failure"].as_str().unwrap_or("none up to the search's limit"),
            f(&c["capacity_fps"]),
            f(&c["busy_ns_per_frame"]),
            f(&c["at_rate_hz"]),
            f(&c["short_turns_capacity_fps"]),
            f(&c["short_turns_ns_per_frame"]),
            f(&c["range_fps"][0]),
            f(&c["range_fps"][1]),
            if c["met"].as_bool() == Some(true) { "yes" } else { "**no**" },
            f(&c["bar_fps"])
        );
    }
}

fn capacity(md: &mut String, s: &Settings, res: &Results) {
    if res.capacity.is_empty() {
        return;
    }
    let _ = writeln!(md, "\n## Capacity: the emulator alone ({} s per trial, every frame through it)\n", s.throughput_trial_s);
    let _ = writeln!(md, "| scenario | trial, frames/s | verdict | offered | emulator busy ns a frame | release lateness p99 | steal | host speed (ALU / memory ns a step, before) |\n|---|---|---|---|---|---|---|---|");
    for (k, v) in &res.capacity {
        for t in v["trials"].as_array().into_iter().flatten() {
            let busy = &t["emulator"]["busy"];
            let _ = writeln!(
                md,
                "| {k} | {:.0} | {} | {:.0} | {} | {} | {:.2}% | {:.2} / {:.0} |",
                t["rate_hz"].as_f64().unwrap_or(0.0),
                t["verdict"].as_str().unwrap_or("?"),
                t["offered_fps"].as_f64().unwrap_or(0.0),
                busy["busy_ns_per_frame"].as_f64().map_or("-".into(), |x| format!("{x:.0}")),
                ns(t["emulator"]["release_lateness_ns"]["p99"].as_i64().unwrap_or(0)),
                t["host"]["steal_fraction"].as_f64().unwrap_or(0.0) * 100.0,
                t["host_speed_before"]["alu_ns"].as_f64().unwrap_or(f64::NAN),
                t["host_speed_before"]["chase_ns"].as_f64().unwrap_or(f64::NAN),
            );
        }
        let _ = writeln!(
            md,
            "\n{k}: {:.0} frames/s sustained; the bar ({:.0}) sustained in {} of {} trials.\n",
            v["best_fps"].as_f64().unwrap_or(0.0),
            v["bar_fps"].as_f64().unwrap_or(0.0),
            v["at_bar_sustained"],
            v["at_bar_trials"]
        );
    }
}

fn bars(md: &mut String, fig: &Figures) {
    if fig.bars.is_empty() {
        return;
    }
    let _ = writeln!(md, "\n## Bars\n\n| bar | value | limit | met |\n|---|---|---|---|");
    for b in &fig.bars {
        let (value, limit) = if let Some(v) = b["value_ns"].as_i64() {
            (ns(v), ns(b["limit_ns"].as_i64().unwrap_or(0)))
        } else if let Some(v) = b["value_fps"].as_f64() {
            (format!("{v:.0} frames/s"), format!("{} frames/s", b["limit_fps"]))
        } else {
            (format!("{:.1}×", b["value_ratio"].as_f64().unwrap_or(0.0)), format!("{}×", b["limit_ratio"]))
        };
        let _ = writeln!(md, "| {} | {value} | {limit} | {} |", b["bar"].as_str().unwrap_or("?"), if b["met"].as_bool() == Some(true) { "yes" } else { "**no**" });
    }
}
