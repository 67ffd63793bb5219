//! The capacity search: what the emulator itself sustains. The throughput
//! search runs the product's own console and simulator, which share a core
//! on two cores and cannot offer 10⁵ frames/s; here the benchmark plays
//! both ends in one thread (as in the latency intervals, but every frame
//! through the emulator), so the rate stops where the emulator, not its
//! peers, stops keeping up. The emulator is the real `netfi emulator`,
//! trace and histograms on, its core cleared as in every interval.

use crate::args::Settings;
use crate::chain::{capacity_interval, ChainResult};
use crate::drive::WARMUP_S;
use crate::host::{pin, speed, Speed};
use crate::throughput::{search_rates, unintended};
use crate::{Results, PLM2_DLM2};
use anyhow::Result;
use netfi::metrics::fmt_ns;
use serde_json::{json, Value};

/// Why a capacity trial was not sustained, or "sustained": every frame the
/// thread sent entered the emulator, every one the emulator delivered came
/// back, nothing was dropped outside the scenario (or lost from the trace),
/// and the thread really offered the rate.
pub fn verdict(c: &ChainResult, trial_s: f64) -> String {
    let e = &c.emulator;
    let unintended = unintended(&e.dropped);
    let offered = offered_fps(c, trial_s);
    if c.refused > 0 {
        format!("the emulator's port refused {} frames", c.refused)
    } else if e.entered < c.chain_sent {
        format!("{} frames sent never entered the emulator", c.chain_sent - e.entered)
    } else if !unintended.is_empty() {
        format!("dropped outside the scenario: {}", unintended.join(", "))
    } else if c.chain_received < e.delivered {
        format!("{} frames delivered but not received", e.delivered - c.chain_received)
    } else if e.held_at_end > 0 {
        format!("{} frames still held at the end", e.held_at_end)
    } else if e.trace_overflowed > 0 {
        format!("{} trace rows lost", e.trace_overflowed)
    } else if offered < 0.98 * c.rate_hz {
        format!("the driving thread offered only {offered:.0} frames/s")
    } else {
        "sustained".to_string()
    }
}

/// The rate the driving thread really offered after its warm-up: the
/// frames it sent then over the time it took to send them.
fn offered_fps(c: &ChainResult, trial_s: f64) -> f64 {
    let frames = (c.rate_hz * trial_s).round();
    if c.send_seconds > 0.0 {
        frames / c.send_seconds
    } else {
        0.0
    }
}

/// [`speed`] of the driving thread's core, measured there.
fn speed_on(core: Option<usize>) -> Speed {
    std::thread::scope(|sc| {
        sc.spawn(|| {
            pin(core, None);
            speed()
        })
        .join()
        .expect("the speed measurement does not panic")
    })
}

/// One trial as JSON, with its verdict, and its line on the console.
fn trial(s: &Settings, label: &str, scenario: &str, rate_hz: f64) -> Result<(bool, Value)> {
    let before = speed_on(s.driver_core);
    let c = capacity_interval(s, scenario, label, rate_hz, s.throughput_trial_s)?;
    let after = speed_on(s.driver_core);
    let verdict = verdict(&c, s.throughput_trial_s);
    let busy = c.emulator.busy.as_ref();
    println!(
        "  capacity {label} {:>9.0} frames/s: {verdict} (offered {:.0}/s; sent {}, entered {}, delivered {}, received {}; emulator busy {} ns a frame, {} without turns over 200 µs; release lateness p50 {} p99 {}; steal {:.2}%, others {:.2} cores; host speed before/after: {:.2}/{:.2} ns a step, memory {:.0}/{:.0} ns)",
        rate_hz,
        offered_fps(&c, s.throughput_trial_s),
        c.chain_sent,
        c.emulator.entered,
        c.emulator.delivered,
        c.chain_received,
        busy.and_then(|b| b.busy_ns_per_frame).map_or("-".into(), |v| format!("{v:.0}")),
        busy.and_then(|b| b.short_turns_ns_per_frame).map_or("-".into(), |v| format!("{v:.0}")),
        fmt_ns(c.emulator.release_lateness_ns.p50),
        fmt_ns(c.emulator.release_lateness_ns.p99),
        c.host.steal_fraction * 100.0,
        c.host.others_busy_cores,
        before.alu_ns,
        after.alu_ns,
        before.chase_ns,
        after.chase_ns
    );
    let sustained = verdict == "sustained";
    let mut v = serde_json::to_value(&c)?;
    if let Some(m) = v.as_object_mut() {
        m.insert("verdict".into(), json!(verdict));
        m.insert("sustained".into(), json!(sustained));
        m.insert("offered_fps".into(), json!(offered_fps(&c, s.throughput_trial_s)));
        m.insert("warmup_s".into(), json!(WARMUP_S));
        m.insert("host_speed_before".into(), serde_json::to_value(before)?);
        m.insert("host_speed_after".into(), serde_json::to_value(after)?);
    }
    Ok((sustained, v))
}

/// The capacity part, per scenario: the scale bar's rate (10⁶ frames/s with
/// Normal, 7·10⁵ with PLM-2 + DLM-2) tried once per repetition, then the
/// search from it up to twice it, or down from it, to 5%. Every trial at
/// the bar's rate counts towards "sustained in k of n".
pub fn capacity_part(s: &Settings, res: &mut Results) -> Result<()> {
    for (label, key, scenario, bar) in [("normal", "Normal", "Normal", 1_000_000.0), ("plm2_dlm2", "PLM-2 + DLM-2", PLM2_DLM2, 700_000.0)] {
        let mut trials = Vec::new();
        for _ in 1..s.repetitions {
            trials.push(trial(s, label, scenario, bar)?.1);
        }
        let best = search_rates(bar, 2.0 * bar, |rate| {
            let (ok, v) = trial(s, label, scenario, rate)?;
            trials.push(v);
            Ok(ok)
        })?
        .unwrap_or(0.0);
        let at_bar: Vec<&Value> = trials.iter().filter(|t| t["rate_hz"].as_f64() == Some(bar)).collect();
        let passed = at_bar.iter().filter(|t| t["sustained"] == true).count();
        println!(
            "  capacity {key}: {best:.0} frames/s sustained for {} s through the emulator; the bar ({bar:.0}) sustained in {passed} of {} trials",
            s.throughput_trial_s,
            at_bar.len()
        );
        let first_fail = trials.iter().filter(|t| t["sustained"] == false).min_by(|a, b| a["rate_hz"].as_f64().unwrap_or(0.0).total_cmp(&b["rate_hz"].as_f64().unwrap_or(0.0))).map(|t| t["verdict"].clone());
        res.capacity.insert(
            key.to_string(),
            json!({"best_fps": best, "bar_fps": bar, "at_bar_sustained": passed, "at_bar_trials": at_bar.len(), "met": passed * 2 > at_bar.len(), "trial_s": s.throughput_trial_s, "first_failure": first_fail, "trials": trials}),
        );
    }
    Ok(())
}
