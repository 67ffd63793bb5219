//! The stand-alone emulator's own report as a person reads it: what it
//! knows of the run (its frames and whether they balance as far as it can
//! tell, the forward stream's loss, delays and overhead, each reverse
//! path's account, its files), in the run report's words.

use super::text::{balanced_in, busy_text_in, dropped_list, emulator_overhead_text, happenings_text, injected_text, opt, stages_text, LossLine, Words};
use crate::service::schema::{EmulatorFrames, EmulatorReport, LinkMeasures, LoopBusy, PathReport};

/// The stand-alone emulator's own report as a person reads it: its frames and whether they
/// balance as far as it can tell, the loss, delays and overhead of the
/// forward stream, each reverse path's account, and its files. What only
/// the console and the robot know (received frames, the end-to-end
/// figures) is in the run's report (`netfi report DIR`).
///
/// `w`: the words of its stream (ITP frames, or ROS 2 messages).
pub fn emulator_text(r: &EmulatorReport, w: &Words) -> String {
    let (p, l, f) = (&r.process, &r.shaping.link, &r.process.frames);
    let a = &f.account;
    let mut s = format!("netfi emulator: {}scenario {} (seed {}), {:.2} s, ended by {}\n", w.stream, p.scenario, p.seed, p.duration_s, p.ended_by);
    let sent = if w.ros2 { w.sent.to_string() } else { format!("{} by console", w.sent) };
    s += &format!("{:<10} {sent} {}  entered {}  delivered {}  held at end {}\n", w.unit, opt(f.sent_by_console), a.entered, a.delivered, a.held_at_end);
    if let Some(n) = f.sent_by_console.filter(|_| w.ros2).map(|s| s.saturating_sub(a.entered)).filter(|n| *n > 0) {
        s += &format!("           {n} of the published did not enter: sent before the emulator subscribed, or lost on the way (ros2.json tells which)\n");
    }
    if f.delivered_unsubscribed > 0 {
        s += &format!("           {} of the delivered released while {}: they went nowhere\n", f.delivered_unsubscribed, w.unsubscribed);
    }
    if a.duplicated > 0 {
        s += &format!("duplicated {} copies made (each delivered, dropped or held like a frame: delivered may exceed entered by these)\n", a.duplicated);
    }
    s += &format!("dropped    {}\n", dropped_list(&a.dropped));
    if a.corrupted > 0 {
        s += &format!("corrupted  {} queued with flipped bits, {} delivered\n", a.corrupted, a.corrupted_delivered);
    }
    if f.bad_input.total() > 0 {
        let b = &f.bad_input;
        s += &format!(
            "bad input  {} (empty {}, short {}, oversize {}, bad flags {}) from {}\n",
            b.total(),
            b.len_zero,
            b.len_short,
            b.len_oversize,
            b.bad_flags,
            b.from.join(", ")
        );
    }
    s += &emulator_accounting_text(f, w);
    s += &LossLine { rate: l.loss_rate, ci95: l.loss_rate_ci95, unseen: l.loss_rate_unseen_model, entered: Some(a.entered), dropped: &a.dropped, stages: &l.stages }.text_in(w);
    s += &emulator_shaping_text(l, p.busy.as_ref(), w);
    for (name, path) in p.paths.keys().filter_map(|n| Some((n, p.path::<serde_json::Map<String, serde_json::Value>>(n)?))) {
        s += &path_text(name, &path);
    }
    s += &happenings_text(&r.shaping.peer_events, &r.shaping.events, w);
    for d in &p.dead_peers {
        s += &format!("dead peer  {d}\n");
    }
    s += &format!("host steal {} ms ({:.3}% of CPU time)\n", p.steal_ms, p.steal_fraction * 100.0);
    s += &emulator_files_text(r);
    s
}

/// Whether the emulator's frames balance, and why not.
fn emulator_accounting_text(f: &EmulatorFrames, w: &Words) -> String {
    let a = &f.account;
    // The publishers' count (their sequence numbers) includes what they
    // sent before the emulator subscribed and what was lost on the way
    // (said above): only a count below what entered is wrong.
    let word_wrong = |n: &u64| if w.ros2 { *n < a.entered } else { *n != a.entered };
    if a.closes() && !f.sent_by_console.is_some_and(|n| word_wrong(&n)) {
        return format!("accounting {}\n", balanced_in(w));
    }
    let mut why = Vec::new();
    if !a.closes() {
        why.push(format!("entered {} + copies {} is not delivered {} + dropped {} + held {}", a.entered, a.duplicated, a.delivered, a.dropped_total(), a.held_at_end));
    }
    if let Some(n) = f.sent_by_console.filter(word_wrong) {
        let said = if w.ros2 { "said they sent" } else { "said it sent" };
        why.push(format!("{} {said} {n}, {} entered", w.sender, a.entered));
    }
    format!("accounting NOT balanced ({})\n", why.join("; "))
}

/// The forward stream's stages, delays and overhead, as the emulator measured them.
fn emulator_shaping_text(l: &LinkMeasures, busy: Option<&LoopBusy>, w: &Words) -> String {
    let mut s = stages_text(&l.stages, &l.links);
    s += &injected_text(&Some(l.injected_delay_ns));
    s += &emulator_overhead_text(&Some(l.ingress_wait_ns), &Some(l.decision_ns), &Some(l.release_lateness_ns));
    if let Some(b) = busy {
        s += &busy_text_in(b, w);
    }
    s
}

/// One reverse path's account, as its channel reported it.
fn path_text<X>(name: &str, p: &PathReport<X>) -> String {
    let a = &p.account;
    format!(
        "path       {name}: scenario {} (seed {}): entered {}  delivered {}  held at end {}; dropped {}; {}\n",
        p.scenario,
        p.seed,
        a.entered,
        a.delivered,
        a.held_at_end,
        dropped_list(&a.dropped),
        if p.balanced { "balanced" } else { "NOT balanced" }
    )
}

/// The emulator's files: the forward trace, the histograms, each path's trace.
fn emulator_files_text(r: &EmulatorReport) -> String {
    let mut s = String::new();
    let sh = &r.shaping;
    for t in sh.trace_path.iter() {
        s += &format!("  trace     {}\n", t.display());
    }
    for h in [&sh.decision_hlog, &sh.lateness_hlog].into_iter().flatten() {
        s += &format!("  histogram {}\n", h.display());
    }
    for (name, v) in &r.process.paths {
        if let Some(t) = v.get("trace_path").and_then(|t| t.as_str()) {
            s += &format!("  {name:<9} {t}\n");
        }
    }
    if s.is_empty() {
        s
    } else {
        format!("files\n{s}")
    }
}

#[cfg(test)]
mod tests {
    use super::super::join::tests::emulator;
    use super::*;
    use crate::metrics::Summary;
    use crate::service::schema::{EmulatorReport, Shaping};

    fn report(sent_by_console: Option<u64>, held: u64) -> EmulatorReport {
        let shaping: Shaping = serde_json::from_value(serde_json::json!({
            "loss_rate": 0.3, "loss_rate_ci95": [0.1, 0.5], "stages": [], "injected_delay_ns": Summary::default(),
            "ingress_wait_ns": Summary::default(), "decision_ns": Summary::default(), "release_lateness_ns": Summary::default(),
            "peer_events": [{"t_s": 0.5, "peer": "console", "connected": 1}], "trace_path": "/run/trace_emulator.csv",
            "decision_hlog": null, "lateness_hlog": null
        }))
        .unwrap();
        let mut process = crate::service::schema::WithPaths { inner: emulator(10, 6, 3, held, sent_by_console), paths: Default::default() };
        let feedback = serde_json::json!({
            "scenario": "Normal", "seed": 3, "queue_order": "fifo", "queue_capacity": 16, "entered": 6, "delivered": 5,
            "dropped": {}, "held_at_end": 0, "delivered_unsubscribed": 0, "balanced": false, "loss_rate": 0.0,
            "loss_rate_ci95": [0.0, 0.1], "stages": [], "injected_delay_ns": Summary::default(), "ingress_wait_ns": Summary::default(),
            "decision_ns": Summary::default(), "release_lateness_ns": Summary::default(), "send_errors": 0, "receive_errors": 0,
            "trace_path": "/run/trace_feedback.csv", "sent_by_robot": 6
        });
        process.paths.insert("feedback".into(), feedback);
        EmulatorReport { shaping, process }
    }

    fn emulator_text_itp(r: &EmulatorReport) -> String {
        emulator_text(r, &Words::itp())
    }

    #[test]
    fn the_emulators_own_report_says_what_it_knows_and_whether_it_balances() {
        let text = emulator_text_itp(&report(Some(10), 1));
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines[0], "netfi emulator: scenario PLM-2 (seed 7), 1.00 s, ended by end_marker");
        assert_eq!(lines[1], "frames     sent by console 10  entered 10  delivered 6  held at end 1");
        assert_eq!(lines[2], "dropped    3 by ge_lomax");
        assert_eq!(lines[3], format!("accounting {}", super::super::text::BALANCED));
        assert!(text.contains("loss       0.3000 realized: the scenario's drops of the 10 frames it decided, 95% CI [0.1000, 0.5000]\n"), "{text}");
        assert!(text.contains("path       feedback: scenario Normal (seed 3): entered 6  delivered 5  held at end 0; dropped none; NOT balanced\n"), "{text}");
        assert!(text.contains("peer       t=0.500s console connected: 1\n"), "{text}");
        assert!(text.contains("  trace     /run/trace_emulator.csv\n") && text.contains("  feedback  /run/trace_feedback.csv\n"), "{text}");
        let lost = emulator_text_itp(&report(Some(12), 0));
        assert!(
            lost.contains("accounting NOT balanced (entered 10 + copies 0 is not delivered 6 + dropped 3 + held 0; the console said it sent 12, 10 entered)\n"),
            "{lost}"
        );
        // A ROS 2 lane: its topics and messages; the publishers' count
        // above what entered is what they sent before the emulator
        // subscribed or lost on the way, not an unbalanced account.
        let ros2 = emulator_text(&report(Some(12), 1), &Words::ros2("/x", "/y"));
        let lines: Vec<&str> = ros2.lines().collect();
        assert_eq!(lines[0], "netfi emulator: ROS 2 /x → /y, scenario PLM-2 (seed 7), 1.00 s, ended by end_marker");
        assert_eq!(lines[1], "messages   published 12  entered 10  delivered 6  held at end 1");
        assert!(lines[2].contains("2 of the published did not enter"), "{ros2}");
        assert!(ros2.contains("accounting balanced: every message that entered"), "{ros2}");
        assert!(ros2.contains("peer       t=0.500s publishers of /x connected: 1\n"), "{ros2}");
        assert!(!ros2.contains("frame") && !ros2.contains("console"), "{ros2}");
        let no_word = emulator_text_itp(&report(None, 1));
        assert!(no_word.contains("sent by console ?") && no_word.contains(&format!("accounting {}", super::super::text::BALANCED)), "{no_word}");
    }
}
