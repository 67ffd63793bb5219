//! What a scenario will realize, before it runs: the checker
//! ([`crate::check`]) in simulated time, every frame's fate summarized as a
//! run's trace is ([`crate::html::trace::TraceSummary`]) and drawn with the
//! report's own figures: a loss raster, the loss-run (burst) lengths, the
//! delay against the analytic law, loss over time, and the outage timeline.

use crate::check::{self, Arrivals, CheckReport};
use crate::html::inputs::Law;
use crate::html::plot::{self, Bars, Figure, Scale};
use crate::html::trace::TraceSummary;
use crate::html::{figures, HtmlError};
use crate::injector::{DropCause, Entered, Fate};
use crate::model::ModelKind;
use crate::scenario::Scenario;
use maud::{html, PreEscaped};

/// Frames drawn in the raster: the first 10 000, a row of 100 each.
const RASTER_FRAMES: u64 = 10_000;
const RASTER_ROW: u64 = 100;

/// The preview of the scenario in `text` over `frames` at `rate_hz`, as an
/// HTML fragment; an error is the parser's or the checker's message.
pub fn render(text: &str, frames: u64, rate_hz: f64) -> Result<String, String> {
    let spec = crate::scenario::parse_str(text, "scenario", "scenario").map_err(|e| e.to_string())?;
    let seed = spec.seed.unwrap_or(1);
    let capacity = spec.queue_capacity.unwrap_or(crate::service::run::DEFAULT_QUEUE_CAPACITY);
    crate::scheduler::ReleaseQueue::<()>::check_capacity(crate::scheduler::QueueOrder::Reorder, capacity).map_err(|e| e.to_string())?;
    let arrivals = Arrivals::at_rate(frames, rate_hz)?;
    let scenario = Scenario::new(&spec, seed).map_err(|e| e.to_string())?;
    let law = Law::of_scenario(&scenario);
    let duration_s = frames as f64 / rate_hz;
    let mut seen = Seen::new(crate::html::inputs::bin_ns(duration_s));
    let report = check::run_observed(scenario, &arrivals, capacity, |_| {}, |i, t, e| seen.record(i, t, e));
    seen.summary.close_run();
    page(&report, &seen, law.as_ref(), seed).map_err(|e| e.to_string())
}

/// Every frame's fate, summarized.
struct Seen {
    summary: TraceSummary,
    /// Whether each of the first [`RASTER_FRAMES`] frames was dropped.
    raster: Vec<bool>,
    /// Outage windows as seen by the frames, `[from, to)` s.
    outages: Vec<(f64, f64)>,
    last_t_s: f64,
}

impl Seen {
    fn new(bin_ns: u64) -> Seen {
        Seen { summary: TraceSummary::new(bin_ns), raster: Vec::new(), outages: Vec::new(), last_t_s: 0.0 }
    }

    fn record(&mut self, i: u64, t_ns: u64, e: &Entered) {
        let (dropped, drawn) = match e.fate {
            Fate::Scheduled { delay_ns, .. } => (false, Some(delay_ns)),
            Fate::Dropped(_) => (true, None),
        };
        self.summary.record_simulated(t_ns, drawn);
        if i < RASTER_FRAMES {
            self.raster.push(dropped);
        }
        let t_s = t_ns as f64 / 1e9;
        if let Fate::Dropped(DropCause::Stage { kind: ModelKind::Outage, .. }) = e.fate {
            match self.outages.last_mut() {
                Some(w) if w.1 >= self.last_t_s => w.1 = t_s,
                _ => self.outages.push((t_s, t_s)),
            }
        }
        self.last_t_s = t_s;
    }
}

fn page(r: &CheckReport, seen: &Seen, law: Option<&Law>, seed: u64) -> Result<String, HtmlError> {
    let s = &seen.summary;
    let plots = [
        Some(raster(&seen.raster)),
        figures::loss_runs(&s.loss_runs)?,
        figures::delay_law(s, law)?,
        figures::loss_over_time(s)?,
        outage_timeline(&seen.outages, s.end_s())?,
    ];
    let [lo, hi] = r.loss_rate_ci95;
    Ok(html! {
        table id="preview-figures" class="figures" {
            tr { th { "frames" } td id="preview-frames-n" { (r.frames) } th { "seed" } td { (seed) } }
            tr { th { "realized loss" } td id="preview-loss" { (format!("{:.4}", r.loss_rate)) }
                 th { "95% interval" } td { (format!("[{lo:.4}, {hi:.4}]")) } }
            tr { th { "mean loss run" } td { (format!("{:.2} frames", r.loss_run_mean)) }
                 th { "outages" } td { (r.outages.count) } }
            tr { th { "delay p50 / p99" } td { (format!("{:.3} / {:.3} ms", r.delay_ms.p50, r.delay_ms.p99)) }
                 th { "reordered" } td { (format!("{:.4}", r.reordered_fraction)) } }
        }
        @for p in plots.iter().flatten() { div class="plot" { (PreEscaped(p)) } }
    }
    .into_string())
}

/// The first frames' fates, a row of [`RASTER_ROW`] frames per line: a
/// dark cell is a dropped frame.
fn raster(dropped: &[bool]) -> String {
    let rows = (dropped.len() as u64).div_ceil(RASTER_ROW).max(1);
    let (cell, w) = (4u64, RASTER_ROW * 4);
    let mut svg = format!(
        "<svg id=\"plot-loss-raster\" xmlns=\"http://www.w3.org/2000/svg\" width=\"{w}\" height=\"{}\" viewBox=\"0 0 {w} {}\"><title>Loss raster: the first {} frames, {RASTER_ROW} a row; dark = dropped</title><rect width=\"100%\" height=\"100%\" fill=\"#eef5ee\"/>",
        rows * cell + 2,
        rows * cell + 2,
        dropped.len()
    );
    for (i, _) in dropped.iter().enumerate().filter(|(_, d)| **d) {
        let (x, y) = ((i as u64 % RASTER_ROW) * cell, (i as u64 / RASTER_ROW) * cell);
        svg += &format!("<rect class=\"drop\" x=\"{x}\" y=\"{y}\" width=\"{cell}\" height=\"{cell}\" fill=\"#b2182b\"/>");
    }
    svg + "</svg>"
}

/// Outage windows on the time axis.
fn outage_timeline(windows: &[(f64, f64)], end_s: f64) -> Result<Option<String>, HtmlError> {
    if windows.is_empty() {
        return Ok(None);
    }
    let bars = windows.iter().map(|(a, b)| (*a, b.max(a + 1e-3), 1.0)).collect();
    plot::svg(&Figure {
        id: "plot-outages",
        title: "Outage timeline",
        x_desc: "time (s)",
        y_desc: "outage",
        x: Scale::linear(0.0..end_s.max(1e-3)),
        y: Scale::linear(0.0..1.0),
        x_fmt: &plot::short,
        y_fmt: &|_| String::new(),
        lines: Vec::new(),
        bars: vec![Bars { label: "outage".into(), color: plot::PURPLE, bars }],
        legend: plotters::prelude::SeriesLabelPosition::UpperRight,
    })
    .map(Some)
}
