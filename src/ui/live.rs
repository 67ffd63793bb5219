//! A running run's live side, through `netfi ctl` child processes: its
//! telemetry (`netfi ctl watch --json`, followed on a thread, the last
//! intervals kept) and its control (`netfi ctl switch|phase|pause|resume
//! --json`, one process per request). The server itself opens no iceoryx2
//! node: it neither touches the run's shared memory nor has its signals
//! taken over by iceoryx2's handlers.

use crate::html::plot::{self, Figure, Line, Mark, Scale};
use maud::{html, PreEscaped};
use serde::Deserialize;
use std::collections::VecDeque;
use std::io::{BufRead, BufReader};
use std::path::Path;
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
    pub fn follow(netfi: &Path, run_id: &str) -> Result<Telemetry, super::UiError> {
        let samples = Arc::new(Mutex::new(VecDeque::with_capacity(KEPT)));
        let stop = Arc::new(AtomicBool::new(false));
        let child = Arc::new(AtomicU32::new(0));
        let (s, st, c, exe, id) = (samples.clone(), stop.clone(), child.clone(), netfi.to_path_buf(), run_id.to_string());
        let thread = std::thread::Builder::new().name("ui-telemetry".into()).spawn(move || watch(&exe, &id, &s, &st, &c)).map_err(super::UiError::Thread)?;
        Ok(Telemetry { samples, stop, child, thread: Some(thread) })
    }

    /// The live table and plots, once an interval came.
    pub fn html(&self) -> Option<String> {
        let samples = self.samples.lock().expect("telemetry lock");
        let last = samples.back()?;
        let ms = |ns: u64| format!("{:.3}", ns as f64 / 1e6);
        let us = |ns: u64| format!("{:.2}", ns as f64 / 1e3);
        let interval = plot::short(&(last.length_ns as f64 / 1e6));
        let table = html! {
            p { "The last interval of " span id="live-interval-ms" { (interval) } " ms, ending at "
                (format!("{:.1} s", (last.start_ns + last.length_ns) as f64 / 1e9)) " from the run's first frame:" }
            table id="live-figures" class="figures" {
                tr { th { "run phase" } td id="live-phase" { (last.phase) } th { "faults" }
                     td id="live-faults" { @if last.paused { "paused" } @else { "on" } } }
                tr { th { "frames in it" } td { (last.entered) } th { "dropped in it" } td { (last.dropped) }
                     th { "loss in it" } td id="live-loss" { (last.loss_rate.map_or("-".into(), |l| format!("{l:.4}"))) } }
                tr { th { "delay drawn p50 / p99 (ms)" } td colspan="2" { (ms(last.injected_ns.p50)) " / " (ms(last.injected_ns.p99)) }
                     th { "release lateness p50 / p99.9 (µs)" } td colspan="2" { (us(last.lateness_ns.p50)) " / " (us(last.lateness_ns.p999)) } }
            }
        };
        let marks = marks(&samples);
        Some(table.into_string() + &loss_plot(&samples, &marks).unwrap_or_default() + &delay_plot(&samples, &marks).unwrap_or_default())
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

/// The run's phase changes and pauses among the intervals kept, at each
/// interval's start (the telemetry's resolution).
fn marks(samples: &VecDeque<Interval>) -> Vec<Mark> {
    let t = |s: &Interval| s.start_ns as f64 / 1e9;
    let mut out = Vec::new();
    let mut paused_from: Option<f64> = None;
    for (prev, s) in samples.iter().zip(samples.iter().skip(1)) {
        if s.phase != prev.phase {
            out.push(Mark::At { x: t(s), label: format!("phase {}", s.phase) });
        }
        match (prev.paused, s.paused) {
            (false, true) => paused_from = Some(t(s)),
            (true, false) => out.push(Mark::Paused { x: paused_from.take().unwrap_or(t(prev)), to: Some(t(s)) }),
            _ => {}
        }
    }
    if let Some(x) = paused_from.or_else(|| samples.front().filter(|s| s.paused).map(t)) {
        out.push(Mark::Paused { x, to: None });
    }
    out
}

/// The time axis of the intervals kept: at least a second wide.
fn span(samples: &VecDeque<Interval>) -> Option<std::ops::Range<f64>> {
    let t = |s: &Interval| (s.start_ns + s.length_ns) as f64 / 1e9;
    let (first, last) = (t(samples.front()?), t(samples.back()?));
    Some(first.min(last - 1.0)..last.max(first + 1.0))
}

/// Loss per interval over the last minute.
fn loss_plot(samples: &VecDeque<Interval>, marks: &[Mark]) -> Option<String> {
    let t = |s: &Interval| (s.start_ns + s.length_ns) as f64 / 1e9;
    let points: Vec<(f64, f64)> = samples.iter().filter_map(|s| Some((t(s), s.loss_rate?))).collect();
    let ms = plot::short(&(samples.back()?.length_ns as f64 / 1e6));
    let svg = plot::svg(&Figure {
        id: "plot-live-loss",
        title: &format!("Loss per {ms} ms interval"),
        x_desc: "time from the run's first frame (s)",
        y_desc: "fraction of the interval's frames dropped",
        x: Scale::linear(span(samples)?),
        y: Scale::linear(0.0..1.0),
        x_fmt: &plot::short,
        y_fmt: &plot::short,
        lines: vec![Line { label: "loss".into(), color: plot::BLUE, points }],
        bars: Vec::new(),
        marks,
    })
    .ok()?;
    Some(html! { div class="plot" { (PreEscaped(svg)) } }.into_string())
}

/// The delay drawn per interval (p50, p99) over the last minute; none
/// while no interval delayed a frame.
fn delay_plot(samples: &VecDeque<Interval>, marks: &[Mark]) -> Option<String> {
    let t = |s: &Interval| (s.start_ns + s.length_ns) as f64 / 1e9;
    let delayed = samples.iter().filter(|s| s.entered > s.dropped);
    let line = |label: &str, color, v: &dyn Fn(&Interval) -> u64| Line {
        label: label.into(),
        color,
        points: delayed.clone().map(|s| (t(s), v(s) as f64 / 1e6)).collect(),
    };
    let lines = vec![line("drawn, p50", plot::ORANGE, &|s| s.injected_ns.p50), line("drawn, p99", plot::GREY, &|s| s.injected_ns.p99)];
    let top = lines.iter().flat_map(|l| l.points.iter().map(|p| p.1)).fold(0.0, f64::max);
    if top <= 0.0 {
        return None;
    }
    let ms = plot::short(&(samples.back()?.length_ns as f64 / 1e6));
    let svg = plot::svg(&Figure {
        id: "plot-live-delay",
        title: &format!("Delay drawn per {ms} ms interval"),
        x_desc: "time from the run's first frame (s)",
        y_desc: "delay (ms)",
        x: Scale::linear(span(samples)?),
        y: Scale::linear(0.0..top * 1.1),
        x_fmt: &plot::short,
        y_fmt: &plot::short,
        lines,
        bars: Vec::new(),
        marks,
    })
    .ok()?;
    Some(html! { div class="plot" { (PreEscaped(svg)) } }.into_string())
}

/// A control request from the run's page.
#[derive(Debug, Clone, Deserialize)]
#[serde(tag = "cmd", rename_all = "snake_case", deny_unknown_fields)]
pub enum Control {
    /// Switch to a preset, or to scenario text (the scenario being
    /// built), now or `at` (as `netfi ctl --at` reads it: `12.5s` from the
    /// run's first frame, `+5s` from now).
    Switch {
        #[serde(default)]
        preset: Option<String>,
        #[serde(default)]
        toml: Option<String>,
        #[serde(default)]
        at: Option<String>,
    },
    /// Go to a phase (number from 1, or name) of the scenario running.
    Phase {
        phase: String,
        #[serde(default)]
        at: Option<String>,
    },
    Pause,
    Resume,
    Show,
}

/// Scenario texts a run was switched to, kept in its directory.
const SWITCH_FILES_MAX: usize = 1024;

/// Sends `req` to the run `run_id` (writing into `out`) by `netfi ctl`: the
/// emulator's answer as `{event: {t_s, what}, state}` (no event for
/// `show`), or its error (the scenario parser's, for a bad switch). A
/// scenario text is written to `out/switch-N.toml` first, a record of what
/// the run was switched to.
pub fn control(netfi: &Path, run_id: &str, out: &Path, req: &Control) -> Result<serde_json::Value, String> {
    let at = |at: &Option<String>| at.as_deref().map(str::trim).filter(|a| !a.is_empty()).map(|a| format!("--at={a}"));
    let args: Vec<String> = match req {
        Control::Switch { preset: Some(p), toml: None, at: when } => {
            if crate::scenario::canonical_name(p).is_none() {
                return Err(format!("`{p}` is not a preset (presets: {})", crate::scenario::PRESET_NAMES.join(", ")));
            }
            ["switch".to_string()].into_iter().chain(at(when)).chain(["--".to_string(), p.clone()]).collect()
        }
        Control::Switch { preset: None, toml: Some(text), at: when } => {
            crate::scenario::parse_str(text, "the scenario being built", "scenario").map_err(|e| e.to_string())?;
            let path = (1..=SWITCH_FILES_MAX)
                .map(|n| out.join(format!("switch-{n}.toml")))
                .find(|p| !p.exists())
                .ok_or_else(|| format!("the run was switched to {SWITCH_FILES_MAX} scenarios already"))?;
            crate::durable::write_whole(&path, text.as_bytes()).map_err(|e| e.to_string())?;
            ["switch".to_string()].into_iter().chain(at(when)).chain(["--".to_string(), path.display().to_string()]).collect()
        }
        Control::Switch { .. } => return Err("switch: give a preset or the scenario's text, one of them".into()),
        Control::Phase { phase, at: when } => ["phase".to_string()].into_iter().chain(at(when)).chain(["--".to_string(), phase.clone()]).collect(),
        Control::Pause => vec!["pause".into()],
        Control::Resume => vec!["resume".into()],
        Control::Show => vec!["show".into()],
    };
    let out = Command::new(netfi)
        .args(["ctl", "--run-id", run_id, "--json"])
        .args(&args)
        .stdin(Stdio::null())
        .output()
        .map_err(|e| format!("starting {}: {e}", netfi.display()))?;
    if !out.status.success() {
        return Err(String::from_utf8_lossy(&out.stderr).trim().trim_start_matches("error: ").to_string());
    }
    let r: serde_json::Value = serde_json::from_slice(&out.stdout).map_err(|e| format!("reading the emulator's answer: {e}"))?;
    if matches!(req, Control::Show) {
        return Ok(serde_json::json!({ "state": r["state"] }));
    }
    let t_s = r.pointer("/state/t_s").and_then(|v| v.as_f64()).unwrap_or(0.0);
    Ok(serde_json::json!({ "event": { "t_s": t_s, "what": r["message"] }, "state": r["state"] }))
}
