//! What the netfi emulator adds between Python processes: a Python console
//! and a Python robot (`clients/python/bench/`, on iceoryx2's Python
//! bindings and `netfi_iox`), once over iceoryx2 and once through the UDP
//! bridge, each against a direct Python → Python hop in the same run, and
//! the emulator's share of the round trip from its own stamps.
//!
//! ```sh
//! cargo bench --bench python                     # both parts, 20 s each at 1 kHz per route
//! cargo bench --bench python -- --parts udp --seconds 60
//! ```
//!
//! The console sends a frame every half period, alternately through the
//! emulator and straight to the robot; the robot answers each at once on
//! the same route. A thread samples `/proc/stat` once a window: each figure
//! is given over the quiet windows (low steal), the calm ones (and other
//! processes nearly idle) and all. Needs python3 with `iceoryx2==0.10.0`;
//! without it the program says so and measures nothing.

#[path = "../common/mod.rs"]
mod common;
mod args;
mod figures;
mod parts;
mod windows;

use anyhow::{ensure, Result};
use args::Args;
use common::args::{check_interrupted, Placement};
use common::host::{clear_core, restore_core};
use common::out::Out;
use common::process::Build;
use figures::{Figures, Selection};
use netfi::metrics::fmt_ns;
use parts::Part;
use serde_json::{json, Value};
use std::fmt::Write as _;

fn main() {
    common::args::main("python", "what the emulator adds between Python processes (a minute)", run);
}

fn run(a: Args) -> Result<()> {
    ensure!(a.seconds > 0.0 && a.rate_hz > 0.0 && a.window_s > 0.0, "--seconds, --rate-hz and --window-s must be positive");
    if let Some(why) = parts::python_missing(&a.python) {
        println!("python: skipped: {} cannot import iceoryx2's Python bindings or netfi_iox ({why}); pip install iceoryx2==0.10.0", a.python);
        return Ok(());
    }
    let p = a.cores.placement(&a.common)?;
    let out = Out::create(&a.common, "python")?;
    let build = Build::new("netfi", a.netfi.as_deref())?;
    let _ = netfi::transport::cleanup_stale();
    let cleared = clear_core(&p);
    let mut done = Vec::new();
    for transport in ["iceoryx2", "udp"].into_iter().filter(|t| a.parts.iter().any(|x| x == t)) {
        check_interrupted()?;
        println!("  {transport}: {} s …", a.seconds);
        done.push(parts::run(&a, &p, &build, &out, transport)?);
    }
    let (cleared, isolation) = restore_core(cleared);
    let (figures, md) = report(&a, &p, &cleared, &done);
    out.finish(&a, json!({"placement": p, "isolation": isolation, "build": build, "parts": figures}), &md)
}

/// Every part's figures over each selection of windows, as JSON and as
/// Markdown.
fn report(a: &Args, p: &Placement, cleared: &str, parts: &[Part]) -> (Vec<Value>, String) {
    let robot = p.other_core.map_or("any core".to_string(), |c| format!("core {c}"));
    let mut md = format!("{}, the Python console on the benchmark's core, the robot on {robot}. {cleared} {} frames/s per route.\n", p.line(), a.rate_hz);
    let mut out = Vec::new();
    let mut chain_p50 = Vec::new();
    for part in parts {
        let figs: Vec<Figures> = Selection::ALL.iter().map(|&sel| Figures::of(part, sel)).collect();
        write_part(&mut md, part, &figs);
        let pick = figs.iter().find(|f| f.windows_used > 0).unwrap_or(&figs[2]);
        if let Some(d) = pick.dists.get("oneway_chain") {
            chain_p50.push((part.transport, d.p50));
        }
        out.push(json!({
            "transport": part.transport, "dir": part.dir, "figures": figs, "windows": part.windows, "host": part.host,
            "console": part.console_summary, "robot": part.robot_summary, "emulator": part.emulator,
        }));
    }
    if let [(_, i), (_, u)] = chain_p50[..] {
        let _ = writeln!(md, "\nThrough the emulator, Python to Python, one way at p50: iceoryx2 {}, UDP {} ({:.1}× as long over UDP).", fmt_ns(i), fmt_ns(u), u as f64 / i.max(1) as f64);
    }
    (out, md)
}

/// A part's tables: over the quiet windows, the calm ones and all (a
/// selection that takes no window, or the same windows as the one before,
/// is only named), then the emulator's own histograms.
fn write_part(md: &mut String, p: &Part, figs: &[Figures]) {
    let (c, e) = (&p.console_summary, &p.emulator);
    let what = match p.transport {
        "iceoryx2" => "iceoryx2: Python console → netfi emulator → Python robot, feedback back through the emulator (Normal both ways)",
        _ => "UDP: Python console → the UDP bridge → Python robot, echoes back through its return path (Normal both ways)",
    };
    let dropped: u64 = e["frames"]["dropped"].as_object().map_or(0, |m| m.values().filter_map(Value::as_u64).sum());
    let _ = writeln!(
        md,
        "\n## {what}\n\nThe console sent {} through / {} direct and got {} / {} answers back; the emulator took {} frames in, delivered {}, dropped {dropped}. Over the part {}.",
        c["sent"][0], c["sent"][1], c["feedback_received"][0], c["feedback_received"][1], e["frames"]["entered"], e["frames"]["delivered"], p.host.line()
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
