//! What a scenario will realize, before it runs: the checker
//! ([`crate::check`]) in simulated time, every frame's fate summarized as a
//! run's trace is ([`crate::html::trace::TraceSummary`]) and drawn with the
//! report's own figures: a loss raster, the loss-run (burst) lengths, the
//! delay against the analytic law, loss over time (its phases marked), and
//! the outage timeline. In brief ([`render_brief`]), for the figures beside
//! one stage's parameters: its loss, mean burst and the burst lengths.

use crate::check::{self, Arrivals, CheckReport};
use crate::html::inputs::Law;
use crate::html::plot::{self, Bars, Figure, Mark, Scale};
use crate::html::trace::TraceSummary;
use crate::html::{figures, HtmlError};
use crate::injector::{DropCause, Entered, Fate};
use crate::model::ModelKind;
use crate::scenario::{Scenario, ScenarioSpec};
use maud::{html, PreEscaped};

/// Frames drawn in the raster: the first 10 000, a row of 100 each.
const RASTER_FRAMES: u64 = 10_000;
const RASTER_ROW: u64 = 100;

/// The scenario of `text` simulated over `frames` at `rate_hz`.
fn simulate(text: &str, frames: u64, rate_hz: f64) -> Result<(ScenarioSpec, CheckReport, Seen, Option<Law>, u64), String> {
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
    Ok((spec, report, seen, law, seed))
}

/// The preview of the scenario in `text` over `frames` at `rate_hz`, as an
/// HTML fragment; an error is the parser's or the checker's message.
pub fn render(text: &str, frames: u64, rate_hz: f64) -> Result<String, String> {
    let (spec, report, seen, law, seed) = simulate(text, frames, rate_hz)?;
    let marks: Vec<Mark> = spec
        .phases
        .iter()
        .skip(1)
        .map(|p| Mark::At { x: p.start_ms / 1e3, label: p.name.clone().unwrap_or_else(|| format!("from {} s", plot::short(&(p.start_ms / 1e3)))) })
        .collect();
    page(&report, &seen, law.as_ref(), seed, &marks).map_err(|e| e.to_string())
}

/// What the stage `text` (a scenario of one stage) realizes, in brief: its
/// loss with its interval, the model's, the mean and longest burst, and the
/// burst lengths; the figures' ids end in `-{stage}`.
pub fn render_brief(text: &str, frames: u64, rate_hz: f64, stage: u32) -> Result<String, String> {
    let (_, r, seen, _, _) = simulate(text, frames, rate_hz)?;
    let runs = &seen.summary.loss_runs;
    let id = format!("plot-stage-bursts-{stage}");
    let plot = figures::loss_runs_as(runs, &id, "Burst lengths (consecutive frames dropped)").map_err(|e| e.to_string())?;
    let model = r.stages.iter().map(|s| s.loss_rate_model).try_fold(1.0, |pass, m| Some(pass * (1.0 - m?))).map(|pass| 1.0 - pass);
    let [lo, hi] = r.loss_rate_ci95;
    Ok(html! {
        div.realized {
            p {
                "Realizes " b id={ "stage-loss-" (stage) } data-value=(r.loss_rate) data-lo=(lo) data-hi=(hi) data-model=[model] { (format!("{:.1}%", r.loss_rate * 100.0)) } " loss "
                (format!("[{:.1}, {:.1}]%", lo * 100.0, hi * 100.0))
                @if let Some(m) = model { " (model " span id={ "stage-model-" (stage) } { (format!("{:.1}%", m * 100.0)) } ")" }
                "; bursts of " b id={ "stage-burst-" (stage) } { (format!("{:.2}", r.loss_run_mean)) } " frames on average, the longest "
                (runs.keys().next_back().copied().unwrap_or(0)) "; over " (r.frames) " simulated frames at " (plot::short(&rate_hz)) " Hz."
            }
            @if let Some(svg) = plot { div.plot.small { (PreEscaped(svg)) } }
        }
    }
    .into_string())
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

fn page(r: &CheckReport, seen: &Seen, law: Option<&Law>, seed: u64, marks: &[Mark]) -> Result<String, HtmlError> {
    let s = &seen.summary;
    let plots = [
        Some(raster(&seen.raster)),
        figures::loss_runs(&s.loss_runs)?,
        figures::delay_law(&s.delays, law, "plot-delay-law", "Delay: drawn and the law")?,
        figures::loss_over_time(s, marks)?,
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
        table id="preview-stages" class="figures" {
            tr { th { "phase" } th { "stage" } th { "reached" } th { "dropped" } th { "loss" } th { "model's loss" } th { "model's mean delay" } }
            @for st in &r.stages {
                tr {
                    td { (st.phase) } td { (st.stage) " " (st.label) } td { (st.reached) } td { (st.dropped) }
                    td { (format!("{:.4}", st.loss_rate)) }
                    td { (st.loss_rate_model.map_or("-".to_string(), |m| format!("{m:.4}"))) }
                    td { (st.delay_ms_model.map_or("-".to_string(), |m| format!("{m:.3} ms"))) }
                }
            }
        }
        @for p in plots.iter().flatten() { div class="plot" { (PreEscaped(p)) } }
    }
    .into_string())
}

/// The first frames' fates, a row of [`RASTER_ROW`] frames per line, with
/// its axes (the frame within its row; the row's first frame) and legend.
fn raster(dropped: &[bool]) -> String {
    let rows = (dropped.len() as u64).div_ceil(RASTER_ROW).max(1);
    let cell = 4u64;
    // The grid, and room for the title (top), the row axis (left), the
    // column axis (below) and the legend (below it).
    let (left, top, grid_w, grid_h) = (64u64, 28u64, RASTER_ROW * cell, rows * cell);
    let (w, h) = (left + grid_w + 20, top + grid_h + 64);
    let mut svg = format!(
        "<svg id=\"plot-loss-raster\" class=\"plot raster\" viewBox=\"0 0 {w} {h}\" role=\"img\" aria-label=\"Loss raster\" font-family=\"sans-serif\" font-size=\"11\">\
         <text x=\"{}\" y=\"16\" font-size=\"14\" text-anchor=\"middle\">Loss raster: frames 0 to {}, {RASTER_ROW} a row</text>\
         <rect class=\"grid\" x=\"{left}\" y=\"{top}\" width=\"{grid_w}\" height=\"{grid_h}\" fill=\"#eef5ee\" stroke=\"#999\"/>",
        w / 2,
        dropped.len().saturating_sub(1)
    );
    for (i, _) in dropped.iter().enumerate().filter(|(_, d)| **d) {
        let (x, y) = (left + (i as u64 % RASTER_ROW) * cell, top + (i as u64 / RASTER_ROW) * cell);
        svg += &format!("<rect class=\"drop\" x=\"{x}\" y=\"{y}\" width=\"{cell}\" height=\"{cell}\" fill=\"#b2182b\"/>");
    }
    // The frame within its row, every 10 frames.
    for k in (0..=RASTER_ROW).step_by(10) {
        let x = left + k * cell;
        svg += &format!("<line x1=\"{x}\" y1=\"{}\" x2=\"{x}\" y2=\"{}\" stroke=\"#555\"/><text x=\"{x}\" y=\"{}\" text-anchor=\"middle\">{k}</text>", top + grid_h, top + grid_h + 4, top + grid_h + 16);
    }
    svg += &format!("<text x=\"{}\" y=\"{}\" text-anchor=\"middle\">frame within its row</text>", left + grid_w / 2, top + grid_h + 30);
    // The row's first frame, every 10 rows.
    for row in (0..rows).step_by(10) {
        let y = top + row * cell;
        svg += &format!("<line x1=\"{}\" y1=\"{y}\" x2=\"{left}\" y2=\"{y}\" stroke=\"#555\"/><text x=\"{}\" y=\"{}\" text-anchor=\"end\">{}</text>", left - 4, left - 6, y + 4, row * RASTER_ROW);
    }
    svg += &format!("<text transform=\"translate(12 {}) rotate(-90)\" text-anchor=\"middle\">first frame of the row</text>", top + grid_h / 2);
    let ly = top + grid_h + 46;
    svg += &format!(
        "<g class=\"legend\"><rect x=\"{left}\" y=\"{}\" width=\"10\" height=\"10\" fill=\"#b2182b\"/><text x=\"{}\" y=\"{}\">dropped</text>\
         <rect x=\"{}\" y=\"{}\" width=\"10\" height=\"10\" fill=\"#eef5ee\" stroke=\"#999\"/><text x=\"{}\" y=\"{}\">delivered</text></g>",
        ly - 9, left + 14, ly, left + 84, ly - 9, left + 98, ly
    );
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
        marks: &[],
    })
    .map(Some)
}
