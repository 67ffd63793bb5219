//! A running run's live side, from the UI's process: its telemetry
//! (followed on a thread of its own, the last intervals kept) and its
//! control service (one request per call). Both are the emulator's
//! published iceoryx2 services (docs/interface.md), as `netfi ctl` uses
//! them.

use crate::html::plot::{self, Figure, Line, Scale};
use crate::service::control::{Request, Response, Target};
use crate::transport::ipc::control::{ControlClient, TelemetrySample, TelemetrySubscriber};
use crate::transport::{IpcConfig, RunId};
use maud::{html, PreEscaped};
use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// Intervals kept for the live plot: a minute at the default 100 ms.
const KEPT: usize = 600;

/// The telemetry of one run, as it comes.
pub(crate) struct Telemetry {
    samples: Arc<Mutex<VecDeque<TelemetrySample>>>,
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Telemetry {
    /// Follows the telemetry of `run_id` until [`Telemetry::stop`] or the
    /// emulator ends (it waits for the emulator to publish first).
    pub fn follow(run_id: &str) -> anyhow::Result<Telemetry> {
        let config = IpcConfig::new(RunId::new(run_id)?);
        let samples = Arc::new(Mutex::new(VecDeque::with_capacity(KEPT)));
        let stop = Arc::new(AtomicBool::new(false));
        let (s, st) = (samples.clone(), stop.clone());
        let thread = std::thread::Builder::new().name("ui-telemetry".into()).spawn(move || watch(&config, &s, &st))?;
        Ok(Telemetry { samples, stop, thread: Some(thread) })
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
                     td { @if last.flags & 1 == 1 { "paused" } @else { "on" } } }
                tr { th { "entered" } td { (last.entered) } th { "dropped" } td { (last.dropped) }
                     th { "loss" } td id="live-loss" { (format!("{:.4}", last.loss_rate)) } }
                tr { th { "delay p50 / p99 (ms)" } td colspan="2" { (ms(last.injected_ns[0])) " / " (ms(last.injected_ns[2])) }
                     th { "lateness p50 / p99.9 (µs)" } td colspan="2" { (us(last.lateness_ns[0])) " / " (us(last.lateness_ns[2])) } }
            }
        };
        let plot = loss_plot(&samples).unwrap_or_default();
        Some(table.into_string() + &plot)
    }

    /// Stops following (the thread ends within its poll interval).
    pub fn stop(&mut self) {
        self.stop.store(true, Ordering::Release);
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

fn watch(config: &IpcConfig, samples: &Mutex<VecDeque<TelemetrySample>>, stop: &AtomicBool) {
    let tick = Duration::from_millis(50);
    let sub = loop {
        if stop.load(Ordering::Acquire) {
            return;
        }
        if let Ok(s) = TelemetrySubscriber::open(config) {
            break s;
        }
        std::thread::sleep(tick);
    };
    while !stop.load(Ordering::Acquire) && sub.publisher_alive() {
        while let Some(s) = sub.recv() {
            let mut q = samples.lock().expect("telemetry lock");
            if q.len() == KEPT {
                q.pop_front();
            }
            q.push_back(s);
        }
        std::thread::sleep(tick);
    }
}

/// Loss and delay per interval over the last minute.
fn loss_plot(samples: &VecDeque<TelemetrySample>) -> Option<String> {
    let t = |s: &TelemetrySample| (s.start_ns + s.length_ns) as f64 / 1e9;
    let (first, last) = (t(samples.front()?), t(samples.back()?));
    let points: Vec<(f64, f64)> = samples.iter().filter(|s| s.loss_rate.is_finite()).map(|s| (t(s), s.loss_rate)).collect();
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
/// `pause`, `resume`, `show`) sent to the run `run_id`: the emulator's
/// answer as `{event: {t_s, what}, state}`, or its error.
pub fn control(run_id: &str, req: &serde_json::Value) -> Result<serde_json::Value, String> {
    let arg = req.get("arg").and_then(|a| a.as_str()).unwrap_or_default().to_string();
    let request = match req.get("cmd").and_then(|c| c.as_str()) {
        Some("switch") => Request::Switch { scenario: Target::Preset(arg), at_ms: None },
        Some("pause") => Request::Pause,
        Some("resume") => Request::Resume,
        Some("show") => Request::Show,
        other => return Err(format!("unknown command {other:?}: switch, pause, resume or show")),
    };
    let config = IpcConfig::new(RunId::new(run_id).map_err(|e| e.to_string())?);
    let client = ControlClient::open(&config).map_err(|e| format!("{e:#}"))?;
    let body = serde_json::to_vec(&request).map_err(|e| e.to_string())?;
    let bytes = client.request(&body, Duration::from_secs(5)).map_err(|e| format!("{e:#}"))?;
    let r: Response = serde_json::from_slice(&bytes).map_err(|e| format!("reading the emulator's answer: {e}"))?;
    if !r.ok {
        return Err(r.message);
    }
    let t_s = r.state.as_ref().map_or(0.0, |s| s.t_s);
    Ok(serde_json::json!({ "event": { "t_s": t_s, "what": r.message }, "state": r.state }))
}
