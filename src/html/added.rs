//! The page's later parts: what the robot and the operator got (the
//! kinematics, the feedback round trip), what netfi itself added (its
//! latency over the direct hop), the host, and where the run comes from.

use super::figures;
use super::inputs::RunInputs;
use super::plot::Mark;
use super::{none, HtmlError};
use crate::metrics::{fmt_ns, Summary};
use crate::service::report::RunReport;
use maud::{html, Markup, PreEscaped};

pub(super) fn kinematics(r: &RunReport) -> Result<Markup, HtmlError> {
    let Some(k) = &r.kinematics else {
        return Ok(html! { section #kinematics { h2 { "Kinematics" } (none("no kinematics recorded")) } });
    };
    let f = |v: &serde_json::Value| v.as_f64().unwrap_or(f64::NAN);
    let arm = |key: &str| [f(&k["divergence"][0][key]), f(&k["divergence"][1][key])];
    let (final_mm, max_mm) = (arm("final_mm"), arm("max_mm"));
    let plot = figures::divergence(final_mm, max_mm)?;
    let live = r.channels.feedback.as_ref().and_then(|fb| fb.divergence_final_mm.zip(fb.divergence_max_mm));
    Ok(html! {
        section #kinematics {
            h2 { "Kinematics: console vs robot, per arm" }
            (PreEscaped(plot))
            table #divergence {
                tr { th { "arm" } th { "console motion (mm)" } th { "robot motion (mm)" } th { "divergence at end (mm)" } th { "max (mm)" }
                     @if live.is_some() { th { "live, at end (mm)" } th { "live, max (mm)" } } }
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

/// Percentiles of a distribution in one table row (ns, formatted).
fn percentile_cells(p: Option<&Summary>) -> Markup {
    html! {
        @match p {
            Some(p) => { td { (p.count) } @for v in [p.p50, p.p90, p.p99, p.p999, p.max] { td { (fmt_ns(v)) } } }
            None => { td colspan="6" { span.none { "not measured" } } }
        }
    }
}

const PERCENTILE_HEADER: [&str; 6] = ["frames", "p50", "p90", "p99", "p99.9", "max"];

/// The feedback loop robot → emulator → console, and its round trip.
pub(super) fn feedback(r: &RunReport) -> Markup {
    let Some(fb) = &r.channels.feedback else {
        return html! { section #feedback { h2 { "Feedback round trip" } (none("no feedback path in this run")) } };
    };
    let opt = |v: Option<u64>| v.map_or("?".to_string(), |x| x.to_string());
    html! {
        section #feedback {
            h2 { "Feedback round trip: robot → console through " (fb.return_scenario) }
            table #feedback-frames {
                tr { th { "sent by the robot" } th { "entered" } th { "delivered" } th { "received by the console" } th { "dropped" } th { "held at end" }
                     @if r.stopped { th { "in flight at the stop" } } }
                tr { td { (opt(fb.sent_by_robot)) } td { (fb.entered) } td { (fb.delivered) } td { (opt(fb.received_by_console)) }
                     td { (crate::service::report::dropped_list(&fb.dropped)) } td { (fb.held_at_end) }
                     @if r.stopped { td #feedback-in-flight { (fb.not_taken_at_stop + fb.unread_at_stop) } } }
            }
            p { "Accounting: " @if fb.balanced { span #feedback-balanced { "balanced" } } @else { span #feedback-balanced.fault { "NOT balanced" } }
                (format!("; loss {:.4}, 95% CI [{:.4}, {:.4}].", fb.loss_rate, fb.loss_rate_ci95[0], fb.loss_rate_ci95[1])) }
            table #round-trip {
                tr { th { "" } @for h in PERCENTILE_HEADER { th { (h) } } }
                tr { td { "round trip: command sent → its feedback received" } (percentile_cells(fb.round_trip_ns.as_ref())) }
                tr { td { "the emulator's share of it" } (percentile_cells(fb.emulator_share_ns.as_ref())) }
            }
        }
    }
}

pub(super) fn latency(inp: &RunInputs, marks: &[Mark]) -> Result<Markup, HtmlError> {
    let r = &inp.report;
    let plot = figures::percentiles(&inp.latency)?;
    let added = match &inp.trace {
        Some(t) => figures::added_over_time(t, marks)?,
        None => None,
    };
    let o = &r.overhead_ns;
    let busy = r.emulator.as_ref().and_then(|e| e.busy.as_ref()).map(crate::service::report::busy_text);
    Ok(html! {
        section #latency {
            h2 { "Latency netfi adds" }
            table #overhead {
                tr { th { "" } @for h in PERCENTILE_HEADER { th { (h) } } }
                tr { td { "ingress wait: console send → taken by the emulator" } (percentile_cells(o.ingress_wait.as_ref())) }
                tr { td { "decision: taken → fate decided" } (percentile_cells(o.decision.as_ref())) }
                tr { td { "release lateness: actual − scheduled release" } (percentile_cells(o.release_lateness.as_ref())) }
                tr { td { "end to end: receive − send − injected delay" } (percentile_cells(o.end_to_end_extra.as_ref())) }
                tr { td { "direct hop: the same frames sent straight to the robot" } (percentile_cells(o.direct_hop.as_ref())) }
            }
            @if let Some(b) = busy { pre #busy { (b.trim_start()) } }
            @if let Some(svg) = added { (PreEscaped(svg)) }
            p { "From the HdrHistogram logs. Emulator added: receive − send − injected delay through the emulator; "
                "direct hop: the same frames sent straight to the simulator; release lateness: actual − scheduled release." }
            @match plot { Some(svg) => (PreEscaped(svg)), None => (none("no latency recorded")) }
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

/// The host: steal time, the emulator's core and how each process ended.
pub(super) fn host(r: &RunReport) -> Markup {
    let isolation = r.emulator.as_ref().and_then(|e| e.isolation.as_ref());
    html! {
        section #host {
            h2 { "The host" }
            p { "Steal time (the hypervisor's): " span #steal { (r.steal.ms) " ms" } (format!(" ({:.3}% of CPU time).", r.steal.fraction * 100.0)) }
            p { "The emulator's core: " span #isolation { @match isolation { Some(i) => (i.to_string()), None => "not cleared (--no-isolate, or not pinned)" } } "." }
            @if !r.processes.is_empty() {
                table #processes {
                    tr { th { "process" } th { "pid" } th { "core" } th { "ended" } }
                    @for p in &r.processes {
                        tr { td { (p.role) } td { (p.pid) } td { (p.core.map_or("-".to_string(), |c| c.to_string())) } td { (p.status) } }
                    }
                }
            }
        }
    }
}

pub(super) fn provenance(r: &RunReport) -> Markup {
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
