//! A running run's live side, through `netfi ctl` child processes: its
//! telemetry (`netfi ctl watch --json`, followed on a thread, the last
//! intervals kept) and its control (`netfi ctl switch|pause|resume
//! --json`, one process per request). The server itself opens no iceoryx2
//! node: it neither touches the run's shared memory nor has its signals
//! taken over by iceoryx2's handlers.

use crate::html::plot::{self, Figure, Line, Scale};
use maud::{html, PreEscaped};
use serde::Deserialize;
use std::collections::VecDeque;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// Intervals kept for the live plot: a minute at the default 100 ms.
const KEPT: usize = 600;

/// One telemetry interval, as `netfi ctl watch --json` prints it.
#[derive(Debug, Clone, Deserialize)]
struct Interval {
    start_ns: u64,
    length_ns: u64,
    phase: u32,
    paused: bool,
    entered: u64,
    dropped: u64,
    loss_rate: Option<f64>,
    injected_ns: Percentiles,
    lateness_ns: Percentiles,
}

#[derive(Debug, Clone, Deserialize)]
struct Percentiles {
    p50: u64,
    #[serde(default)]
    p99: u64,
    #[serde(default)]
    p999: u64,
}

/// The telemetry of one run, as it comes.
pub(crate) struct Telemetry {
    samples: Arc<Mutex<VecDeque<Interval>>>,
    stop: Arc<AtomicBool>,
    /// The watching `netfi ctl`, while there is one.
    child: Arc<AtomicU32>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Telemetry {
    /// Follows the telemetry of `run_id` with `netfi` until
    /// [`Telemetry::stop`] or the run's emulator ends (until its telemetry
    /// exists, it asks again every 200 ms).
    pub fn follow(netfi: &Path, run_id: &str) -> anyhow::Result<Telemetry> {
        let samples = Arc::new(Mutex::new(VecDeque::with_capacity(KEPT)));
        let stop = Arc::new(AtomicBool::new(false));
        let child = Arc::new(AtomicU32::new(0));
        let (s, st, c, exe, id) = (samples.clone(), stop.clone(), child.clone(), netfi.to_path_buf(), run_id.to_string());
        let thread = std::thread::Builder::new().name("ui-telemetry".into()).spawn(move || watch(&exe, &id, &s, &st, &c))?;
        Ok(Telemetry { samples, stop, child, thread: Some(thread) })
    }

    /// The live table and plot, once an interval came.
    pub fn html(&self) -> Option<String> {
        let samples = self.samples.lock().expect("telemetry lock");
        let last = samples.back()?;
        let ms = |ns: u64| format!("{:.3}", ns as f64 / 1e6);
        let us = |ns: u64| format!("{:.2}", ns as f64 / 1e3);
        let table = html! {
            table id="live-figures" class="figures" {
                tr { th { "t" } td { (format!("{:.1} s", (last.start_ns + last.length_ns) as f64 / 1e9)) }
                     th { "phase" } td id="live-phase" { (last.phase) } th { "faults" }
                     td { @if last.paused { "paused" } @else { "on" } } }
                tr { th { "entered" } td { (last.entered) } th { "dropped" } td { (last.dropped) }
                     th { "loss" } td id="live-loss" { (last.loss_rate.map_or("-".into(), |l| format!("{l:.4}"))) } }
                tr { th { "delay p50 / p99 (ms)" } td colspan="2" { (ms(last.injected_ns.p50)) " / " (ms(last.injected_ns.p99)) }
                     th { "lateness p50 / p99.9 (µs)" } td colspan="2" { (us(last.lateness_ns.p50)) " / " (us(last.lateness_ns.p999)) } }
            }
        };
        Some(table.into_string() + &loss_plot(&samples).unwrap_or_default())
    }

    /// Stops following: the watching process is ended, the thread joined.
    pub fn stop(&mut self) {
        self.stop.store(true, Ordering::Release);
        if let Ok(pid @ 1..) = i32::try_from(self.child.load(Ordering::Acquire)) {
            // SAFETY: signalling our own child; a pid already reaped is 0 here.
            unsafe { libc::kill(pid, libc::SIGTERM) };
        }
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl Drop for Telemetry {
    fn drop(&mut self) {
        self.stop();
    }
}

fn watch(netfi: &Path, run_id: &str, samples: &Mutex<VecDeque<Interval>>, stop: &AtomicBool, child_pid: &AtomicU32) {
    let mut seen = false;
    while !stop.load(Ordering::Acquire) && !seen {
        let spawned = Command::new(netfi)
            .args(["ctl", "--run-id", run_id, "--json", "watch"])
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn();
        let Ok(mut child) = spawned else { return };
        child_pid.store(child.id(), Ordering::Release);
        for line in BufReader::new(child.stdout.take().expect("piped")).lines().map_while(Result::ok) {
            let Ok(s) = serde_json::from_str::<Interval>(&line) else { continue };
            seen = true;
            let mut q = samples.lock().expect("telemetry lock");
            if q.len() == KEPT {
                q.pop_front();
            }
            q.push_back(s);
        }
        let _ = child.wait();
        child_pid.store(0, Ordering::Release);
        if !seen {
            std::thread::sleep(Duration::from_millis(200));
        }
    }
}

/// Loss per interval over the last minute.
fn loss_plot(samples: &VecDeque<Interval>) -> Option<String> {
    let t = |s: &Interval| (s.start_ns + s.length_ns) as f64 / 1e9;
    let (first, last) = (t(samples.front()?), t(samples.back()?));
    let points: Vec<(f64, f64)> = samples.iter().filter_map(|s| Some((t(s), s.loss_rate?))).collect();
    let svg = plot::svg(&Figure {
        id: "plot-live-loss",
        title: "Loss per interval",
        x_desc: "time (s)",
        y_desc: "loss",
        x: Scale::linear(first.min(last - 1.0)..last.max(first + 1.0)),
        y: Scale::linear(0.0..1.0),
        x_fmt: &plot::short,
        y_fmt: &plot::short,
        lines: vec![Line { label: "loss".into(), color: plot::BLUE, points }],
        bars: Vec::new(),
        legend: plotters::prelude::SeriesLabelPosition::UpperRight,
    })
    .ok()?;
    Some(html! { div class="plot" { (PreEscaped(svg)) } }.into_string())
}

/// A control request from the page (`{cmd, arg}`: `switch` to a preset,
/// `pause`, `resume`, `show`) sent to the run `run_id` by `netfi ctl`: the
/// emulator's answer as `{event: {t_s, what}, state}`, or its error (the
/// scenario parser's, for a bad switch).
pub fn control(netfi: &PathBuf, run_id: &str, req: &serde_json::Value) -> Result<serde_json::Value, String> {
    let arg = req.get("arg").and_then(|a| a.as_str()).unwrap_or_default();
    let cmd: Vec<&str> = match req.get("cmd").and_then(|c| c.as_str()) {
        Some("switch") if crate::scenario::canonical_name(arg).is_some() => vec!["switch", arg],
        Some("switch") => return Err(format!("`{arg}` is not a preset (presets: {})", crate::scenario::PRESET_NAMES.join(", "))),
        Some(c @ ("pause" | "resume" | "show")) => vec![c],
        other => return Err(format!("unknown command {other:?}: switch, pause, resume or show")),
    };
    let out = Command::new(netfi)
        .args(["ctl", "--run-id", run_id, "--json"])
        .args(&cmd)
        .stdin(Stdio::null())
        .output()
        .map_err(|e| format!("starting {}: {e}", netfi.display()))?;
    if !out.status.success() {
        return Err(String::from_utf8_lossy(&out.stderr).trim().trim_start_matches("error: ").to_string());
    }
    let r: serde_json::Value = serde_json::from_slice(&out.stdout).map_err(|e| format!("reading the emulator's answer: {e}"))?;
    let t_s = r.pointer("/state/t_s").and_then(|v| v.as_f64()).unwrap_or(0.0);
    Ok(serde_json::json!({ "event": { "t_s": t_s, "what": r["message"] }, "state": r["state"] }))
}
