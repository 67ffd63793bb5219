//! `python.json` and `python.md` (printed too).

use crate::args::Settings;
use crate::figures::{self, Figures, Selection};
use crate::host::{host_facts, HostWindow};
use crate::parts::Part;
use anyhow::{Context, Result};
use netfi::metrics::fmt_ns;
use serde_json::{json, Value};
use std::fmt::Write as _;

/// What each part carried, in words.
fn title(p: &Part) -> &'static str {
    match p.transport {
        "iceoryx2" => "iceoryx2: Python console → netfi emulator → Python robot, feedback back through the emulator (Normal both ways)",
        _ => "UDP: Python console → netfi emulator's UDP bridge → Python robot, echoes back through its return path (Normal both ways)",
    }
}

pub fn write(s: &Settings, parts: &[Part], bench_host: &HostWindow) -> Result<()> {
    let mut md = String::new();
    let facts = host_facts(s);
    let _ = writeln!(
        md,
        "{} cores ({}), kernel {}, clock source {}; emulator on core {:?}, console on {:?}, robot on {:?} (Python nice value {}); {} frames/s per route; load average {:.2} at the start, {:.2} at the end; steal over the benchmark {:.2}%; other processes kept {:.2} cores busy on average.",
        facts["cores"], facts["cpu_model"].as_str().unwrap_or(""), facts["kernel"].as_str().unwrap_or(""), facts["clocksource"].as_str().unwrap_or(""),
        s.emulator_core, s.driver_core, s.robot_core, s.python_nice.map_or("unchanged".to_string(), |n| n.to_string()), s.rate_hz, bench_host.load_start, bench_host.load_end, bench_host.steal_fraction * 100.0, bench_host.others_busy_cores
    );
    let mut out = Vec::new();
    let mut bars = Vec::new();
    let mut chain_p50 = serde_json::Map::new();
    for p in parts {
        let figs: Vec<Figures> = Selection::ALL.iter().map(|&sel| Figures::of(p, sel)).collect();
        write_part(&mut md, p, &figs);
        if p.transport == "iceoryx2" {
            bars = figures::bars(&figs[0]);
        }
        let pick = figs.iter().find(|f| f.windows_used > 0).unwrap_or(&figs[2]);
        if let Some(d) = pick.dists.get("oneway_chain") {
            chain_p50.insert(p.transport.into(), json!({"p50_ns": d.p50, "selection": pick.selection}));
        }
        out.push(json!({
            "transport": p.transport, "dir": p.dir, "figures": figs, "windows": p.windows, "host": p.host,
            "console": p.console_summary, "robot": p.robot_summary, "emulator": p.emulator,
        }));
    }
    write_comparison(&mut md, &chain_p50);
    write_bars(&mut md, &bars);
    let doc = json!({"settings": s, "host": facts, "bench_host": bench_host, "parts": out, "oneway_chain_p50": chain_p50, "bars": bars});
    std::fs::write(s.out_dir.join("python.json"), serde_json::to_string_pretty(&doc)?).context("writing python.json")?;
    std::fs::write(s.out_dir.join("python.md"), &md).context("writing python.md")?;
    println!("\n{md}");
    Ok(())
}

/// The part's tables: over the quiet windows, the calm ones and all (a
/// selection that takes no window, or the same windows as the one before,
/// is only named).
fn write_part(md: &mut String, p: &Part, figs: &[Figures]) {
    let c = &p.console_summary;
    let e = &p.emulator;
    let _ = writeln!(md, "\n#### {}\n", title(p));
    let _ = writeln!(
        md,
        "Console sent {} through / {} direct, got {} / {} answers back; the emulator took {} frames in and delivered {}, dropped {}{}. {}. Steal over the part {:.2}%, load average {:.2} → {:.2}, other processes {:.2} cores busy.",
        c["sent"][0], c["sent"][1], c["feedback_received"][0], c["feedback_received"][1],
        e["frames"]["entered"], e["frames"]["delivered"], e["frames"]["dropped"].as_object().map_or(0, |m| m.values().filter_map(Value::as_u64).sum::<u64>()),
        e["feedback"].get("entered").map_or(String::new(), |f| format!("; feedback: {f} in, {} delivered", e["feedback"]["delivered"])),
        isolation(&e["isolation"]),
        p.host.steal_fraction * 100.0, p.host.load_start, p.host.load_end, p.host.others_busy_cores
    );
    let mut shown: Option<usize> = None;
    for f in figs {
        if f.windows_used == 0 || shown == Some(f.windows_used) {
            let _ = writeln!(md, "\n*{}*{}", f.host_line(), if f.windows_used == 0 { "" } else { " (the same windows as above)" });
            continue;
        }
        f.write_md(md);
        shown = Some(f.windows_used);
    }
    let rows = figures::emulator_rows(e);
    if !rows.is_empty() {
        let _ = writeln!(md, "\n*The emulator's own histograms, whole part:*\n\n| | p50 | p90 | p99 | p99.9 | max | frames |\n|---|---|---|---|---|---|---|");
        for (label, s) in rows {
            let _ = writeln!(md, "| {label} | {} | {} | {} | {} | {} | {} |", fmt_ns(s.p50), fmt_ns(s.p90), fmt_ns(s.p99), fmt_ns(s.p999), fmt_ns(s.max), s.count);
        }
    }
}

/// What `netfi emulator --isolate` did to its core, in words.
fn isolation(iso: &Value) -> String {
    match iso["cleared"].as_bool() {
        Some(true) => format!(
            "Core {} cleared for the emulator: {} threads of other processes and {} interrupts moved off it",
            iso["core"], iso["threads_moved"], iso["irqs_moved"]
        ),
        Some(false) => format!("The emulator's core was not cleared ({})", iso["warnings"]),
        None => "The emulator's core was not cleared (NETFI_BENCH_ISOLATE=0)".to_string(),
    }
}

fn write_comparison(md: &mut String, chain_p50: &serde_json::Map<String, Value>) {
    let get = |t: &str| chain_p50.get(t).and_then(|v| v["p50_ns"].as_u64());
    if let (Some(i), Some(u)) = (get("iceoryx2"), get("udp")) {
        let _ = writeln!(
            md,
            "\nThrough the emulator, Python to Python, one way at p50: iceoryx2 {}, UDP {} ({:.1}× as long over UDP).",
            fmt_ns(i),
            fmt_ns(u),
            u as f64 / i.max(1) as f64
        );
    }
}

fn write_bars(md: &mut String, bars: &[Value]) {
    if bars.is_empty() {
        return;
    }
    let _ = writeln!(md, "\n| bar | value | limit | met |\n|---|---|---|---|");
    for b in bars {
        let value = b["value_ns"].as_u64().map_or("–".to_string(), fmt_ns);
        let met = match b["met"].as_bool() {
            Some(true) => "yes".to_string(),
            Some(false) => "**no**".to_string(),
            None => format!("not judged ({})", b["why"].as_str().unwrap_or("")),
        };
        let _ = writeln!(md, "| {} | {value} | {} | {met} |", b["bar"].as_str().unwrap_or(""), fmt_ns(b["limit_ns"].as_u64().unwrap_or(0)));
    }
}
