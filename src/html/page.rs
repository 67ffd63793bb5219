//! The page's markup (maud: checked at compile time, text escaped by
//! default). Plots come in as finished `<svg>` elements.

use super::figures;
use super::inputs::RunInputs;
use super::HtmlError;
use crate::metrics::fmt_ns;
use crate::service::report::RunReport;
use maud::{html, Markup, PreEscaped, DOCTYPE};

const CSS: &str = "
body { font-family: system-ui, sans-serif; margin: 0 auto; max-width: 62rem; padding: 1rem 1.5rem; color: #222; }
h1 { font-size: 1.5rem; } h2 { font-size: 1.2rem; border-bottom: 1px solid #ccc; padding-bottom: .2rem; margin-top: 2rem; }
table { border-collapse: collapse; margin: .5rem 0; } td, th { padding: .15rem .6rem; text-align: right; border-bottom: 1px solid #eee; }
th:first-child, td:first-child { text-align: left; }
dl { display: grid; grid-template-columns: max-content auto; gap: .2rem 1rem; } dt { font-weight: 600; } dd { margin: 0; }
code { font-family: ui-monospace, monospace; font-size: .9em; word-break: break-all; }
svg.plot { width: 100%; height: auto; display: block; margin: .5rem 0; }
.none { color: #777; font-style: italic; } .fault { color: #a00; font-weight: 600; }
";

/// The whole page.
pub fn page(inp: &RunInputs) -> Result<String, HtmlError> {
    let r = &inp.report;
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
                (provenance(r))
                (summary(r))
                (latency(inp)?)
                (links(r)?)
                (delay_law(inp)?)
                (over_time(inp)?)
                (loss_runs(inp)?)
                (kinematics(r)?)
                (super::video::section(r))
                (events(inp))
            }
        }
    };
    Ok(page.into_string())
}

fn none(text: &str) -> Markup {
    html! { p.none { (text) } }
}

fn provenance(r: &RunReport) -> Markup {
    html! {
        section #provenance {
            h2 { "Provenance" }
            @if let Some(p) = &r.provenance {
                dl {
                    dt { "netfi version" } dd #prov-version { (p.version) }
                    dt { "command line" } dd { code #prov-command { (p.command_line) } }
                    dt { "started (UTC)" } dd #prov-started { (p.started_utc) }
                    dt { "seed" } dd #prov-seed { (p.seed) }
                    dt { "host" } dd #prov-host { (p.host) }
                    dt { "duration" } dd { (format!("{:.2} s", r.duration_s)) }
                }
            } @else {
                (none("not recorded (a report written before netfi recorded provenance)"))
                dl { dt { "seed" } dd #prov-seed { (r.seed) } }
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
                    "Realized loss: "
                    strong { span #realized-loss data-value=(loss) { (format!("{loss:.4}")) } }
                    @if let Some([lo, hi]) = r.loss_rate_ci95 { (format!(", 95% CI [{lo:.4}, {hi:.4}]")) }
                }
            } @else {
                (none("no realized loss (the emulator left no report)"))
            }
            @if !r.faults.is_empty() {
                ul #faults { @for fault in &r.faults { li.fault { (fault) } } }
            }
            @if let Some(u) = &r.udp {
                p #udp { "UDP: " (crate::service::report::udp_line(u)) "." }
            }
            @if !r.missing.is_empty() {
                p #missing.none { "Not in the run's directory: " (r.missing.join(", ")) " (the figures that need them are unknown)." }
            }
        }
    }
}

fn latency(inp: &RunInputs) -> Result<Markup, HtmlError> {
    let plot = figures::percentiles(&inp.latency)?;
    let mut over_time = Vec::new();
    for s in &inp.latency {
        let id = format!("plot-latency-over-time-{}", s.file.trim_end_matches(".hlog").replace('_', "-"));
        over_time.extend(figures::percentiles_over_time(s, &id)?);
    }
    Ok(html! {
        section #latency {
            h2 { "What netfi adds: latency percentiles" }
            p { "From the HdrHistogram logs. Emulator added: receive − send − injected delay through the emulator; "
                "direct hop: the same frames sent straight to the simulator; release lateness: actual − scheduled release." }
            @match plot { Some(svg) => (PreEscaped(svg)), None => (none("no latency recorded")) }
            @if !over_time.is_empty() {
                p { "Over time, from the logs' one interval per second:" }
                @for svg in &over_time { (PreEscaped(svg)) }
            }
            table #latency-table {
                tr { th { "" } th { "file" } th { "frames" } th { "p50" } th { "p90" } th { "p99" } th { "p99.9" } th { "max" } }
                @for s in &inp.latency {
                    tr {
                        td { (s.label) } td { code { (s.file) } }
                        @match s.histogram.as_ref().filter(|h| !h.is_empty()) {
                            Some(h) => {
                                td { (h.len()) }
                                @for q in [0.5, 0.9, 0.99, 0.999] { td { (fmt_ns(h.value_at_quantile(q))) } }
                                td { (fmt_ns(h.max())) }
                            }
                            None => { td colspan="6" { span.none { "not recorded" } } }
                        }
                    }
                }
            }
        }
    })
}

/// The link stages (`rate`, `trace`): utilisation, queueing delay
/// percentiles and the queue over time, per stage.
fn links(r: &RunReport) -> Result<Markup, HtmlError> {
    if r.links.is_empty() {
        return Ok(html! {});
    }
    let mut plots = Vec::new();
    for (i, l) in r.links.iter().enumerate() {
        plots.extend(figures::link_occupancy(l, &format!("plot-link-occupancy-{}", i + 1))?);
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

fn delay_law(inp: &RunInputs) -> Result<Markup, HtmlError> {
    let plot = match &inp.trace {
        Some(t) => figures::delay_law(t, inp.law.as_ref())?,
        None => None,
    };
    Ok(html! {
        section #delay-law {
            h2 { "Delay: seen, drawn and the analytic law" }
            @match plot {
                Some(svg) => {
                    (PreEscaped(svg))
                    @match &inp.law {
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

fn over_time(inp: &RunInputs) -> Result<Markup, HtmlError> {
    let (loss, delay) = match &inp.trace {
        Some(t) => (figures::loss_over_time(t)?, figures::delay_over_time(t)?),
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

fn kinematics(r: &RunReport) -> Result<Markup, HtmlError> {
    let Some(k) = &r.kinematics else {
        return Ok(html! { section #kinematics { h2 { "Kinematics" } (none("no kinematics recorded")) } });
    };
    let f = |v: &serde_json::Value| v.as_f64().unwrap_or(f64::NAN);
    let arm = |key: &str| [f(&k["divergence"][0][key]), f(&k["divergence"][1][key])];
    let (final_mm, max_mm) = (arm("final_mm"), arm("max_mm"));
    let plot = figures::divergence(final_mm, max_mm)?;
    let live = r.feedback.as_ref().and_then(|fb| fb.divergence_final_mm.zip(fb.divergence_max_mm));
    Ok(html! {
        section #kinematics {
            h2 { "Kinematics: console vs robot, per arm" }
            (PreEscaped(plot))
            table #divergence {
                tr { th { "arm" } th { "console motion (mm)" } th { "robot motion (mm)" } th { "divergence at end (mm)" } th { "most (mm)" }
                     @if live.is_some() { th { "live, at end (mm)" } th { "live, most (mm)" } } }
                @for a in 0..2 {
                    tr {
                        td { (a) }
                        td { (format!("{:.1}", f(&k["console"]["length_mm"][a]))) }
                        td { (format!("{:.1}", f(&k["robot"]["length_mm"][a]))) }
                        td { (format!("{:.2}", final_mm[a])) } td { (format!("{:.2}", max_mm[a])) }
                        @if let Some((lf, lm)) = live { td { (format!("{:.2}", lf[a])) } td { (format!("{:.2}", lm[a])) } }
                    }
                }
            }
            p { "Robot stalls: " (k["robot"]["stalls"]["count"]) ", longest "
                (format!("{:.1} ms", f(&k["robot"]["stalls"]["longest_ns"]) / 1e6)) "." }
        }
    })
}

fn events(inp: &RunInputs) -> Markup {
    html! {
        section #events {
            h2 { "Control events" }
            @if inp.report.events.is_empty() {
                p #no-events.none { "no control events" }
            } @else {
                table #event-list {
                    tr { th { "t (s)" } th { "what" } }
                    @for e in &inp.report.events { tr.event { td { (format!("{:.3}", e.t_s)) } td { (e.what) } } }
                }
            }
        }
    }
}
