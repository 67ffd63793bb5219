//! The throughput search: `netfi run --no-direct` at rising rates
//! (doubling, then bisection); a rate is sustained when every frame is
//! delivered or dropped by the scenario, nothing else.

use crate::args::Settings;
use crate::host::{HostTimer, HostWindow};
use crate::product::netfi_run;
use crate::{check_interrupted, Results, PLM2_DLM2};
use anyhow::Result;
use netfi::service::report::RunReport;
use serde::Serialize;
use serde_json::{json, Value};
use std::collections::BTreeMap;
use std::path::PathBuf;

/// One throughput trial.
#[derive(Debug, Clone, Serialize)]
pub struct Trial {
    rate_hz: f64,
    sustained: bool,
    /// Why not, or what limited it.
    verdict: String,
    console_rate_hz: Option<f64>,
    sent: Option<u64>,
    entered: Option<u64>,
    delivered: Option<u64>,
    received: Option<u64>,
    dropped: BTreeMap<String, u64>,
    console_send_errors: Option<u64>,
    emulator_send_errors: Option<u64>,
    ingress_wait_p99_ns: Option<u64>,
    /// The console's send lateness (behind its pacing), p99: the console
    /// keeps up while this stays small.
    console_send_lateness_p99_ns: Option<u64>,
    /// The emulator loop's turns and their mean length.
    emulator_turns: Option<u64>,
    emulator_turn_ns_mean: Option<f64>,
    /// The share of the emulator's core spent on frames rather than in
    /// empty turns: `1 − (empty turn) / (mean turn)`, the empty turn's cost
    /// being the shortest mean turn of the search (its slowest rate is
    /// nearly all empty turns). Filled in after the search.
    emulator_busy_share: Option<f64>,
    /// The emulator loop's own measure of its time on frames
    /// (`emulator.json`'s `busy`: busy turns' time over frames taken; an
    /// upper bound on the cost, see `netfi::service::emulator::LoopBusy`),
    /// and the rate it implies: what the emulator could carry with its core
    /// to itself, whatever the console managed to offer.
    emulator_busy_ns_per_frame: Option<f64>,
    emulator_capacity_fps: Option<f64>,
    /// The same without the busy turns over 200 µs (the loop most likely
    /// lost its core in them): the figure to read where the core is shared.
    emulator_short_turns_ns_per_frame: Option<f64>,
    emulator_short_turns_capacity_fps: Option<f64>,
    /// The emulator's busy turns and all its turns.
    emulator_busy_turns: Option<u64>,
    release_lateness_p99_ns: Option<u64>,
    steal_fraction: f64,
    host: HostWindow,
    out_dir: PathBuf,
}

/// Runs one trial and judges it: sustained when the console offered the
/// rate, the run balanced (every frame delivered or dropped by the scenario)
/// and nothing was refused or dropped for want of room.
fn trial(s: &Settings, label: &str, scenario: &str, rate_hz: f64) -> Result<Trial> {
    check_interrupted()?;
    let dir = s.out_dir.join("runs").join(format!("throughput-{label}-{}", rate_hz as u64));
    // The release queue holds one second of frames, so a delay scenario
    // tests the emulator's speed rather than the queue's size.
    let queue = (rate_hz as u64).max(1 << 16).to_string();
    let host = HostTimer::start(s.quiet);
    let r = netfi_run(&dir, scenario, rate_hz, s.throughput_trial_s, &["--no-direct", "--queue-capacity", &queue])?;
    let host = host.stop();
    let f = &r.frames;
    let console_rate = r.console.as_ref().map(|c| c.rate_hz);
    let verdict = verdict(&r, rate_hz);
    let busy = r.emulator.as_ref().and_then(|e| e.busy.as_ref());
    Ok(Trial {
        rate_hz,
        sustained: verdict == "sustained",
        verdict,
        console_rate_hz: console_rate,
        sent: f.sent,
        entered: f.entered,
        delivered: f.delivered,
        received: f.received,
        dropped: f.dropped.clone(),
        console_send_errors: r.console.as_ref().map(|c| c.send_errors),
        emulator_send_errors: r.emulator.as_ref().map(|e| e.send_errors),
        ingress_wait_p99_ns: r.overhead_ns.ingress_wait.map(|p| p.p99),
        console_send_lateness_p99_ns: r.console.as_ref().map(|c| c.send_lateness_ns.p99),
        emulator_turns: r.emulator.as_ref().map(|e| e.loop_iterations),
        emulator_turn_ns_mean: r.emulator.as_ref().map(|e| e.loop_iteration_ns_mean),
        emulator_busy_share: None,
        emulator_busy_ns_per_frame: busy.and_then(|b| b.busy_ns_per_frame),
        emulator_capacity_fps: busy.and_then(|b| b.capacity_frames_per_s),
        emulator_short_turns_ns_per_frame: busy.and_then(|b| b.short_turns_ns_per_frame),
        emulator_short_turns_capacity_fps: busy.and_then(|b| b.short_turns_capacity_frames_per_s),
        emulator_busy_turns: busy.map(|b| b.busy_turns),
        release_lateness_p99_ns: r.overhead_ns.release_lateness.map(|p| p.p99),
        steal_fraction: r.steal.fraction,
        host,
        out_dir: dir,
    })
}

/// Why a trial at `rate_hz` was not sustained, or "sustained".
fn verdict(r: &RunReport, rate_hz: f64) -> String {
    let f = &r.frames;
    let console_rate = r.console.as_ref().map(|c| c.rate_hz);
    let unintended = unintended(&f.dropped);
    if !r.faults.is_empty() && !f.balanced {
        format!("lost frames: {}", r.faults.join("; "))
    } else if !r.faults.is_empty() {
        format!("fault: {}", r.faults.join("; "))
    } else if !unintended.is_empty() {
        format!("dropped outside the scenario: {}", unintended.join(", "))
    } else if !f.balanced {
        "not balanced".to_string()
    } else if console_rate.is_some_and(|c| c < 0.98 * rate_hz) {
        format!("the console paced only {:.0} frames/s", console_rate.unwrap_or(0.0))
    } else {
        "sustained".to_string()
    }
}

/// The drops no scenario asked for ("N reason" each): the queue full, or
/// frames malformed on the way.
pub fn unintended(dropped: &BTreeMap<String, u64>) -> Vec<String> {
    dropped.iter().filter(|(k, _)| matches!(k.as_str(), "queue_full" | "wrong_size" | "bad_checksum")).map(|(k, v)| format!("{v} {k}")).collect()
}

/// Doubling from `start_hz` until a rate fails, then bisection to 5%.
fn search(s: &Settings, label: &str, scenario: &str, start_hz: f64, max_hz: f64) -> Result<(f64, Vec<Trial>)> {
    let mut trials = Vec::new();
    let run = |rate: f64, trials: &mut Vec<Trial>| -> Result<bool> {
        let t = trial(s, label, scenario, rate)?;
        println!(
            "  throughput {label} {:>9.0} frames/s: {} (console {:.0}/s, send lateness p99 {} ns; emulator turn {:.0} ns, busy {:.0} ns a frame, capacity {:.0} frames/s; steal {:.2}%, others {:.2} cores)",
            rate,
            t.verdict,
            t.console_rate_hz.unwrap_or(0.0),
            t.console_send_lateness_p99_ns.unwrap_or(0),
            t.emulator_turn_ns_mean.unwrap_or(0.0),
            t.emulator_busy_ns_per_frame.unwrap_or(f64::NAN),
            t.emulator_capacity_fps.unwrap_or(f64::NAN),
            t.steal_fraction * 100.0,
            t.host.others_busy_cores
        );
        let ok = t.sustained;
        trials.push(t);
        Ok(ok)
    };
    let best = search_rates(start_hz, max_hz, |rate| run(rate, &mut trials))?;
    busy_shares(&mut trials);
    Ok((best.unwrap_or(0.0), trials))
}

/// The highest rate `run` sustains: doubling from `start_hz` (at most
/// `max_hz`) until a rate fails, or halving (down to 1 000/s) until one
/// passes, then bisection to 5% (rates rounded to 1 000/s). `None` if no
/// rate passed.
pub fn search_rates(start_hz: f64, max_hz: f64, mut run: impl FnMut(f64) -> Result<bool>) -> Result<Option<f64>> {
    let (mut lo, mut hi): (Option<f64>, Option<f64>) = (None, None);
    let mut rate = start_hz;
    loop {
        if run(rate)? {
            lo = Some(rate);
            if rate >= max_hz {
                break;
            }
            rate = (rate * 2.0).min(max_hz);
        } else {
            hi = Some(rate);
            break;
        }
    }
    if lo.is_none() {
        let mut r = start_hz / 2.0;
        while r >= 1000.0 {
            if run(r)? {
                lo = Some(r);
                break;
            }
            hi = Some(r);
            r /= 2.0;
        }
    }
    while let (Some(l), Some(h)) = (lo, hi) {
        if (h - l) / l <= 0.05 {
            break;
        }
        let mid = ((l + h) / 2.0 / 1000.0).round() * 1000.0;
        if mid <= l || mid >= h {
            break;
        }
        if run(mid)? {
            lo = Some(mid);
        } else {
            hi = Some(mid);
        }
    }
    Ok(lo)
}

/// Fills in each trial's emulator busy share (see [`Trial`]): with `turns`
/// turns of mean length `m` over the wall time, of which each costs at least
/// an empty turn `e`, the core spent `1 − e / m` of its time beyond that.
fn busy_shares(trials: &mut [Trial]) {
    let empty_turn_ns = trials.iter().filter_map(|t| t.emulator_turn_ns_mean).filter(|&m| m > 0.0).fold(f64::INFINITY, f64::min);
    if !empty_turn_ns.is_finite() {
        return;
    }
    for t in trials.iter_mut() {
        t.emulator_busy_share = t.emulator_turn_ns_mean.filter(|&m| m > 0.0).map(|m| 1.0 - empty_turn_ns / m);
        println!("  {:>9.0} frames/s: emulator busy {:.0}% of its core (mean turn {:.0} ns, empty turn {empty_turn_ns:.0} ns)", t.rate_hz, t.emulator_busy_share.unwrap_or(0.0) * 100.0, t.emulator_turn_ns_mean.unwrap_or(0.0));
    }
}

/// The emulator's capacity over a search: the one measured in the trial
/// whose emulator took in the most frames a second (the most batched, the
/// nearest to the load the capacity speaks of; a slow trial's frames each
/// pay a turn of their own), and the range over every trial.
fn capacity(trials: &[Trial], trial_s: f64) -> Value {
    let measured: Vec<&Trial> = trials.iter().filter(|t| t.emulator_capacity_fps.is_some()).collect();
    let Some(top) = measured.iter().max_by(|a, b| a.entered.unwrap_or(0).cmp(&b.entered.unwrap_or(0))) else {
        return Value::Null;
    };
    let caps = measured.iter().filter_map(|t| t.emulator_capacity_fps);
    let (lo, hi) = caps.fold((f64::INFINITY, 0.0f64), |(lo, hi), c| (lo.min(c), hi.max(c)));
    json!({
        "capacity_fps": top.emulator_capacity_fps,
        "busy_ns_per_frame": top.emulator_busy_ns_per_frame,
        "at_rate_hz": top.rate_hz,
        "entered_fps": top.entered.map(|e| e as f64 / trial_s),
        "range_fps": [lo, hi],
        "short_turns_capacity_fps": top.emulator_short_turns_capacity_fps,
        "short_turns_ns_per_frame": top.emulator_short_turns_ns_per_frame,
    })
}

/// The throughput part: the search for Normal and for PLM-2 + DLM-2, and
/// beside each the emulator's own capacity against the scale bar (issue:
/// 10⁶ frames/s with Normal, 7·10⁵ with PLM-2 + DLM-2).
pub fn throughput_part(s: &Settings, res: &mut Results) -> Result<()> {
    for (label, key, scenario, bar) in [("normal", "Normal", "Normal", 1_000_000.0), ("plm2_dlm2", "PLM-2 + DLM-2", PLM2_DLM2, 700_000.0)] {
        let (best, trials) = search(s, label, scenario, s.throughput_from_hz, 3_200_000.0)?;
        let mut cap = capacity(&trials, s.throughput_trial_s);
        let c = cap["capacity_fps"].as_f64();
        if let Some(m) = cap.as_object_mut() {
            m.insert("bar_fps".into(), json!(bar));
            m.insert("met".into(), json!(c.is_some_and(|c| c >= bar)));
        }
        println!(
            "  throughput {key}: {best:.0} frames/s sustained for {} s; emulator capacity {:.0} frames/s ({:.0} ns a frame at {:.0} frames/s; bar {bar:.0})",
            s.throughput_trial_s,
            c.unwrap_or(f64::NAN),
            cap["busy_ns_per_frame"].as_f64().unwrap_or(f64::NAN),
            cap["at_rate_hz"].as_f64().unwrap_or(f64::NAN)
        );
        let first_fail = trials.iter().filter(|t| !t.sustained).min_by(|a, b| a.rate_hz.total_cmp(&b.rate_hz)).map(|t| t.verdict.clone());
        res.throughput_fps.insert(key.to_string(), best);
        res.throughput.insert(key.to_string(), json!({"best_fps": best, "first_failure": first_fail, "emulator_capacity": cap, "trials": trials}));
    }
    Ok(())
}
