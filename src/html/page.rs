//! The page's markup (maud: checked at compile time, text escaped by
//! default). Plots come in as finished `<svg>` elements.
//!
//! Ordered for the experimenter who reads it: the condition and what it
//! realized first (the scenario, each stretch of the run under one
//! condition, the frames and the loss, the delay against its law), then
//! what the robot did (the kinematics, the feedback round trip, the
//! video), then what netfi itself added, the host, and where the run comes
//! from.

use super::added;
use super::figures;
use super::inputs::RunInputs;
use super::plot::Mark;
use super::{none, HtmlError};
use crate::service::report::{phase_title, RunReport};
use maud::{html, Markup, PreEscaped, DOCTYPE};

const CSS: &str = "
body { font-family: system-ui, sans-serif; margin: 0 auto; max-width: 62rem; padding: 1rem 1.5rem; color: #222; }
h1 { font-size: 1.5rem; } h2 { font-size: 1.2rem; border-bottom: 1px solid #ccc; padding-bottom: .2rem; margin-top: 2rem; }
h2.part { font-size: 1.4rem; border-bottom: 2px solid #1d3557; color: #1d3557; margin-top: 2.5rem; }
table { border-collapse: collapse; margin: .5rem 0; } td, th { padding: .15rem .6rem; text-align: right; border-bottom: 1px solid #eee; }
th:first-child, td:first-child { text-align: left; }
dl { display: grid; grid-template-columns: max-content auto; gap: .2rem 1rem; } dt { font-weight: 600; } dd { margin: 0; }
code { font-family: ui-monospace, monospace; font-size: .9em; word-break: break-all; }
pre { background: #f6f6f6; padding: .5rem; overflow-x: auto; font-size: .85em; }
svg.plot { width: 100%; height: auto; display: block; margin: .5rem 0; }
.none { color: #777; font-style: italic; } .fault { color: #a00; font-weight: 600; }
.ended { background: #eef4fb; border-left: 4px solid #1d3557; padding: .4rem .8rem; }
tr.paused td { color: #666; background: #f4f4f4; }
";

/// The whole page.
pub fn page(inp: &RunInputs) -> Result<String, HtmlError> {
    let r = &inp.report;
    let marks = marks(r);
    let page = html! {
        (DOCTYPE)
        html lang="en" {
            head {
                meta charset="utf-8";
                meta name="viewport" content="width=device-width, initial-scale=1";
                title { "netfi run " (r.run_id) ": " (r.scenario) }
                style { (PreEscaped(CSS)) }
            }
            body {
                h1 { "netfi run " span #run-id { (r.run_id) } ": " span #scenario { (r.scenario) } }
                (ending(r))
                h2.part { "The condition and what it realized" }
                (condition(inp))
                (summary(r))
                (phases(inp)?)
                (delay_law(inp)?)
                (over_time(inp, &marks)?)
                (loss_runs(inp)?)
                (links(r, &marks)?)
                h2.part { "What the robot and the operator got" }
                (added::kinematics(r)?)
                (added::feedback(r))
                (super::video::section(r))
                h2.part { "What netfi itself added" }
                (added::latency(inp, &marks)?)
                (added::host(r))
                (added::provenance(r))
            }
        }
    };
    Ok(page.into_string())
}

/// How the run ended, in one line: a stop is a normal end; faults are
/// listed with the frames.
fn ending(r: &RunReport) -> Markup {
    html! {
        p #ended.ended {
            @if r.stopped {
                "Stopped on request after " (format!("{:.2}", r.duration_s)) " s (Ctrl-C, SIGTERM or the UI's stop): a normal end; "
                "what was in flight at the stop is accounted for below."
            } @else {
                "Ran " (format!("{:.2}", r.duration_s)) " s."
            }
            " "
            @if r.faults.is_empty() { "No fault." } @else { span.fault { (r.faults.len()) " fault" @if r.faults.len() > 1 { "s" } " (below)." } }
        }
    }
}

/// Each switch (a phase starting) and each pause of the run, on the time
/// axis of the plots (s from the first frame): from the run's stretches,
/// or for a report without them, from its control events.
fn marks(r: &RunReport) -> Vec<Mark> {
    let mut out = Vec::new();
    if !r.phases.is_empty() {
        for (i, p) in r.phases.iter().enumerate() {
            let x = p.from_ns as f64 / 1e9;
            if p.paused {
                out.push(Mark::Paused { x, to: p.to_ns.map(|t| t as f64 / 1e9) });
            } else if i > 0 && r.phases[i - 1].run_phase != p.run_phase {
                let name = match &p.phase_name {
                    Some(n) => format!("{}: {n}", p.scenario),
                    None => p.scenario.clone(),
                };
                out.push(Mark::At { x, label: name });
            }
        }
        return out;
    }
    let mut paused_from = None;
    for e in &r.events {
        match e.what.as_str() {
            w if w.starts_with("pause") => paused_from = paused_from.or(Some(e.t_s)),
            "resume" => {
                if let Some(x) = paused_from.take() {
                    out.push(Mark::Paused { x, to: Some(e.t_s) });
                }
            }
            w => out.push(Mark::At { x: e.t_s, label: w.strip_prefix("switch to ").unwrap_or(w).to_string() }),
        }
    }
    if let Some(x) = paused_from {
        out.push(Mark::Paused { x, to: None });
    }
    out
}

/// The scenario as the run read it, and its control events.
fn condition(inp: &RunInputs) -> Markup {
    html! {
        section #condition {
            h2 { "The scenario" }
            @match &inp.scenario_toml {
                Some(text) => { p { "As the run read it (" code { "scenario.toml" } "):" } pre #scenario-toml { (text) } }
                None => (none("not known: the run's directory has no copy, and it names no preset")),
            }
            (events(inp))
        }
    }
}

fn events(inp: &RunInputs) -> Markup {
    html! {
        section #events {
            h2 { "Live control" }
            @if inp.report.events.is_empty() {
                p #no-events.none { "no control events" }
            } @else {
                p { "What was done while the run went on; each took effect at its time from the run's first frame." }
                table #event-list {
                    tr { th { "t (s)" } th { "what" } }
                    @for e in &inp.report.events { tr.event { td { (format!("{:.3}", e.t_s)) } td { (e.what) } } }
                }
            }
        }
    }
}

fn summary(r: &RunReport) -> Markup {
    let f = &r.frames;
    let opt = |v: Option<u64>| v.map_or("?".to_string(), |x| x.to_string());
    html! {
        section #summary {
            h2 { "Frames and loss" }
            table #frames {
                tr { th { "sent" } th { "entered" } th { "delivered" } th { "received" } th { "held at end" } }
                tr { td { (opt(f.sent)) } td { (opt(f.entered)) } td { (opt(f.delivered)) } td { (opt(f.received)) } td { (opt(f.held_at_end)) } }
            }
            p {
                "Dropped: "
                @if f.dropped.is_empty() { "none" }
                @for (i, (by, n)) in f.dropped.iter().enumerate() { @if i > 0 { ", " } (n) " by " (by) }
                ". Accounting: "
                @if f.balanced { span #balanced { "balanced" } } @else { span #balanced.fault { "NOT balanced" } }
                "."
            }
            @if let Some(loss) = r.loss_rate {
                p {
                    "Realized loss over the whole run: "
                    strong { span #realized-loss data-value=(loss) { (format!("{loss:.4}")) } }
                    @if let Some([lo, hi]) = r.loss_rate_ci95 { (format!(", 95% CI [{lo:.4}, {hi:.4}]")) }
                    @if !r.phases.is_empty() { " (it mixes the run's conditions: each is below)" }
                    "."
                }
            } @else {
                (none("no realized loss (the emulator left no report)"))
            }
            (stages(r))
            @if !r.faults.is_empty() {
                ul #faults { @for fault in &r.faults { li.fault { (fault) } } }
            }
            @for (scheme, line) in r.transports.lines() {
                p id=(scheme) { (scheme.to_uppercase()) ": " (line) "." }
            }
            @if !r.missing.is_empty() {
                p #missing.none { "Not in the run's directory: " (r.missing.join(", ")) " (the figures that need them are unknown)." }
            }
        }
    }
}

/// Each stage's model against what it realized.
fn stages(r: &RunReport) -> Markup {
    if r.stages.is_empty() {
        return html! {};
    }
    let fmt = |v: Option<f64>, digits: usize| v.map_or("-".to_string(), |v| format!("{v:.digits$}"));
    html! {
        table #stages {
            tr { th { "phase" } th { "stage" } th { "model" } th { "reached" } th { "dropped" } th { "loss" } th { "model's loss" } th { "model's mean delay (ms)" } }
            @for s in &r.stages {
                tr.stage {
                    td { (s.phase) } td { (s.stage) " " (s.label) } td { (s.preset.as_deref().unwrap_or(&s.model)) }
                    td { (s.reached) } td { (s.dropped) } td.loss data-value=(s.loss_rate) { (format!("{:.4}", s.loss_rate)) }
                    td { (fmt(s.loss_rate_model, 4)) } td { (fmt(s.delay_ms_model, 3)) }
                }
            }
        }
    }
}

/// Each stretch of the run under one condition: its loss with its interval
/// against its model, its delays against its own law.
fn phases(inp: &RunInputs) -> Result<Markup, HtmlError> {
    let r = &inp.report;
    if r.phases.is_empty() {
        return Ok(match &r.phases_unknown {
            Some(why) => html! { section #phases { h2 { "Each condition" } p #phases-unknown.none { "Not told apart: " (why) } } },
            None => html! {},
        });
    }
    let mut plots = Vec::new();
    if let Some(t) = &inp.trace {
        for (k, (p, d)) in r.phases.iter().zip(&t.stretches).enumerate() {
            let title = format!("Delay in {}", phase_title(p));
            let law = inp.phase_laws.get(k).and_then(Option::as_ref);
            plots.extend(figures::delay_law(d, law, &format!("plot-delay-law-phase-{}", k + 1), &title)?);
        }
    }
    let ms = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.3}"));
    Ok(html! {
        section #phases {
            h2 { "Each condition" }
            p { "The run cut at each phase start, live switch and pause; times from the run's first frame. "
                "The loss interval is over that stretch's frames alone; its delays are held against its own law." }
            table #phase-table {
                tr { th { "from (s)" } th { "to (s)" } th { "condition" } th { "frames" } th { "dropped" } th { "loss" } th { "95% interval" }
                     th { "model's loss" } th { "delay q0.5 drawn (ms)" } th { "law q0.5 (ms)" } th { "within the law's band" } }
                @for p in &r.phases {
                    @let q50 = p.delay_check.as_ref().and_then(|d| d.quantiles.iter().find(|q| q.q == 0.5));
                    tr.phase.paused[p.paused] data-run-phase=(p.run_phase) data-loss=(p.loss_rate) {
                        td { (format!("{:.3}", p.from_ns as f64 / 1e9)) }
                        td { (p.to_ns.map_or("end".to_string(), |t| format!("{:.3}", t as f64 / 1e9))) }
                        td.condition { (phase_title(p)) }
                        td { (p.frames) } td { (p.dropped) }
                        td.loss { (format!("{:.4}", p.loss_rate)) }
                        td { (format!("[{:.4}, {:.4}]", p.loss_rate_ci95[0], p.loss_rate_ci95[1])) }
                        td.model { (p.loss_rate_model.map_or("-".to_string(), |m| format!("{m:.4}"))) }
                        td { (ms(q50.map(|q| q.injected_ms))) }
                        td { (ms(q50.and_then(|q| q.model_ms))) }
                        td { (match p.delay_check.as_ref().and_then(|d| d.injected_within_model_band) { Some(true) => "yes", Some(false) => "NO", None => "-" }) }
                    }
                }
            }
            @for svg in &plots { (PreEscaped(svg)) }
        }
    })
}

fn delay_law(inp: &RunInputs) -> Result<Markup, HtmlError> {
    let plot = match &inp.trace {
        Some(t) => figures::delay_law(&t.delays, inp.law.as_ref(), "plot-delay-law", "Delay: seen, drawn and the law")?,
        None => None,
    };
    Ok(html! {
        section #delay-law {
            h2 { "Delay: seen, drawn and the analytic law" }
            @match plot {
                Some(svg) => {
                    (PreEscaped(svg))
                    @match &inp.law {
                        None if !inp.report.phases.is_empty() => p.none { "The whole run mixes its conditions: each one's law is above." },
                        None => (none("no analytic law: the scenario is not one phase with one delay stage")),
                        Some(law) if law.in_order() => p #delay-law-fifo {
                            "Frames keep their order: one may wait for the frame before it, so the delays drawn "
                            "lie at or above the law, which is the draw without that wait."
                        },
                        Some(_) => {}
                    }
                }
                None => (none("the run injected no delay")),
            }
            @if let Some(dc) = &inp.report.delay_check {
                table #delay-quantiles {
                    tr { th { "quantile" } th { "law (ms)" } th { "95% band (ms)" } th { "drawn (ms)" } th { "seen (ms)" } th { "seen − drawn (µs)" } }
                    @for q in &dc.quantiles {
                        tr {
                            td { (q.q) }
                            td { (q.model_ms.map_or("-".into(), |m| format!("{m:.3}"))) }
                            td { (q.model_band_ms.map_or("-".into(), |[lo, hi]| format!("[{lo:.3}, {hi:.3}]"))) }
                            td { (format!("{:.3}", q.injected_ms)) } td { (format!("{:.3}", q.seen_ms)) }
                            td { (format!("{:+.1}", q.seen_minus_injected_us)) }
                        }
                    }
                }
            }
        }
    })
}

fn over_time(inp: &RunInputs, marks: &[Mark]) -> Result<Markup, HtmlError> {
    let (loss, delay) = match &inp.trace {
        Some(t) => (figures::loss_over_time(t, marks)?, figures::delay_over_time(t, marks)?),
        None => (None, None),
    };
    Ok(html! {
        section #over-time {
            h2 { "Loss and delay over time" }
            @if inp.trace.is_none() { (none("no trace was written")) }
            @if let Some(svg) = loss { (PreEscaped(svg)) }
            @if let Some(svg) = delay { (PreEscaped(svg)) }
        }
    })
}

fn loss_runs(inp: &RunInputs) -> Result<Markup, HtmlError> {
    let runs = inp.trace.as_ref().map(|t| &t.loss_runs);
    let plot = match runs {
        Some(r) => figures::loss_runs(r)?,
        None => None,
    };
    let count: u64 = runs.map_or(0, |r| r.values().sum());
    let frames: u64 = runs.map_or(0, |r| r.iter().map(|(l, n)| l * n).sum());
    Ok(html! {
        section #loss-runs {
            h2 { "Loss-run lengths" }
            @match plot {
                Some(svg) => {
                    (PreEscaped(svg))
                    p { span #loss-run-count { (count) } " runs, mean length " (format!("{:.2}", frames as f64 / count as f64))
                        " frames, longest " (runs.and_then(|r| r.keys().next_back()).copied().unwrap_or(0)) "." }
                }
                None => (none("no frame was dropped")),
            }
        }
    })
}

/// The link stages (`rate`, `trace`): utilisation, queueing delay
/// percentiles and the queue over time, per stage.
fn links(r: &RunReport, marks: &[Mark]) -> Result<Markup, HtmlError> {
    if r.links.is_empty() {
        return Ok(html! {});
    }
    let mut plots = Vec::new();
    for (i, l) in r.links.iter().enumerate() {
        plots.extend(figures::link_occupancy(l, &format!("plot-link-occupancy-{}", i + 1), marks)?);
    }
    Ok(html! {
        section #links {
            h2 { "Link stages: utilisation, queue, queueing delay" }
            p { "Utilisation: the share of the link's time (rate) or of its delivery opportunities' bytes (trace) used. "
                "Time at stage: arrival to the last packet's departure (queueing and serialization)." }
            table #link-table {
                tr { th { "phase" } th { "stage" } th { "utilisation" } th { "capacity (bit/s)" } th { "carried (bit/s)" }
                     th { "queue max (packets)" } th { "queue max (bytes)" } th { "p50 (ms)" } th { "p90 (ms)" } th { "p99 (ms)" } th { "max (ms)" }
                     th { "dropped for the queue" } }
                @for l in &r.links {
                    tr.link {
                        td { (l.phase) } td { (l.label) }
                        td.utilisation data-value=(l.utilisation) { (format!("{:.3}", l.utilisation)) }
                        td { (format!("{:.0}", l.capacity_bit_s)) } td { (format!("{:.0}", l.carried_bit_s)) }
                        td { (l.queue_packets_max) } td { (l.queue_bytes_max) }
                        @for v in [l.delay_ms.p50, l.delay_ms.p90, l.delay_ms.p99, l.delay_ms.max] { td { (format!("{v:.3}")) } }
                        td { (l.frames_dropped) " of " (l.frames + l.frames_dropped) }
                    }
                }
            }
            @for svg in &plots { (PreEscaped(svg)) }
        }
    })
}
