//! The run report as a person reads it, section by section: each section
//! a function of what it shows, so that the stand-alone emulator's own
//! report (`emulator_text`) shares those the emulator knows.

use super::{DelayCheck, FrameAccount, Overhead, PhaseFigures, Provenance, RunReport, RunStreams};
use crate::check::{LinkReport, StageReport};
pub use crate::metrics::text::{dropped_list, line, opt};
use crate::metrics::{fmt_ns, fmt_ns_signed, fmt_rate, Summary};
use crate::service::control::ControlEvent;
use crate::service::schema::{LoopBusy, PeerEvent};
use std::collections::BTreeMap;


impl RunReport {
    /// The report as a person reads it.
    pub fn to_text(&self) -> String {
        let w = self.words();
        let what = match &self.ros2 {
            Some(t) => format!("ROS 2 {} → {} ({}), ", t.from, t.to, t.type_name),
            None => String::new(),
        };
        let mut s = match self.by_hand {
            true => format!(
                "netfi emulator {}: {what}scenario {} (seed {}), {:.2} s; started without `netfi run`: reported from what the emulator and its clients left\n",
                self.run_id, self.scenario, self.seed, self.duration_s
            ),
            false => format!("netfi run {}: {what}scenario {} (seed {}), {:.2} s\n", self.run_id, self.scenario, self.seed, self.duration_s),
        };
        if self.stopped {
            s += &format!("ended      stopped on request after {:.2} s (Ctrl-C, SIGTERM or the UI's stop): a normal end\n", self.duration_s);
        }
        if self.interrupted {
            s += "ended      INTERRUPTED: the runner did not finish this run (killed, or failed before its report); rebuilt from what its processes left\n";
        }
        if let Some(p) = &self.provenance {
            s += &p.to_text();
        }
        s += &frames_text(&self.frames, &w);
        if let Some(t) = self.ros2.as_ref().filter(|t| t.lost_before_ingress + t.sent_before_emulator > 0) {
            s += &format!(
                "           of the published, {} before the emulator subscribed and {} lost before it (gaps in the publishers' sequence numbers)\n",
                t.sent_before_emulator, t.lost_before_ingress
            );
        }
        for (scheme, line) in self.transports.lines() {
            s += &format!("{scheme:<10} {line}\n");
        }
        if let Some((rate, ci95)) = self.loss_rate.zip(self.loss_rate_ci95) {
            let f = &self.frames;
            s += &LossLine { rate, ci95, unseen: self.loss_rate_unseen_model, entered: f.entered, dropped: &f.dropped, stages: &self.stages }.text_in(&w);
        }
        s += &stages_text(&self.stages, &self.links);
        if !self.phases.is_empty() {
            s += &phases_text(&self.phases, &w);
        }
        if let Some(why) = &self.phases_unknown {
            s += &format!("phases     not told apart: {why}\n");
        }
        s += &injected_text(&self.injected_delay_ns);
        s += &overhead_text(&self.overhead_ns, self.emulator.as_ref().and_then(|e| e.busy.as_ref()), &w);
        if let Some(dc) = &self.delay_check {
            s += &delay_law_text(dc, &w);
        }
        if let Some(k) = &self.kinematics {
            s += &kinematics_text(k);
        }
        s += &self.channels.text();
        s += &self.host_text();
        s += &happenings_text(&self.peer_events, &self.events, &w);
        for fault in &self.faults {
            s += &format!("FAULT      {fault}\n");
        }
        for note in &self.notes {
            s += &format!("note       {note}\n");
        }
        if !self.missing.is_empty() {
            s += &format!("missing    {} (what needs them is shown as ?)\n", self.missing.join(", "));
        }
        s += &self.files_text();
        if let Some(st) = &self.streams {
            s += &st.to_text();
        }
        s
    }

    /// The host's steal time, each process, and what clearing the
    /// emulator's core did.
    fn host_text(&self) -> String {
        let mut s = format!("host steal {} ms ({:.3}% of CPU time)\n", self.steal.ms, self.steal.fraction * 100.0);
        for p in &self.processes {
            s += &format!("process    {:<9} pid {:<7} core {:<5} {}\n", p.role, p.pid, p.core.map_or("-".into(), |c| c.to_string()), p.status);
        }
        if let Some(i) = self.emulator.as_ref().and_then(|e| e.isolation.as_ref()) {
            s += &format!("isolation  {i}\n");
        }
        if let Some(e) = self.emulator.as_ref().filter(|e| !e.threads.is_empty()) {
            let each: Vec<String> = e.threads.iter().map(|t| format!("{}{} on {}", t.name, if t.threads > 1 { format!(" ×{}", t.threads) } else { String::new() }, t.cpus)).collect();
            let moved = match (e.core, e.threads.iter().any(|t| t.moved_off_loop_core)) {
                (Some(c), true) => format!(" (moved off the loop's core {c} for the run)"),
                _ => String::new(),
            };
            s += &format!("threads    the emulator's: {}{moved}\n", each.join(", "));
        }
        s
    }

    /// Where the run's files are.
    fn files_text(&self) -> String {
        let f = &self.files;
        let mut s = format!("files      {}\n", f.out_dir.display());
        if let Some(t) = &f.trace {
            s += &format!("  trace     {}\n", t.display());
        }
        for h in [&f.decision_hlog, &f.lateness_hlog, &f.end_to_end_hlog].into_iter().flatten() {
            s += &format!("  histogram {}\n", h.display());
        }
        for (name, v) in &f.channels {
            let channel = name.split('_').next().unwrap_or(name);
            s += &format!("  {channel:<9} {}\n", v.display());
        }
        // A run no runner started has no run report but the one printed.
        if !self.by_hand {
            s += &format!("  report    {}\n", crate::service::report::files::report_said(&f.report_json));
        }
        s
    }
}

/// The words a report speaks of its stream in: ITP frames a console sends
/// a robot, or ROS 2 messages a topic's publishers send another's
/// subscribers.
#[derive(Debug, Clone)]
pub struct Words {
    /// `frames`, `messages`.
    pub unit: &'static str,
    /// `frame`, `message`.
    pub one: &'static str,
    /// `sent`, `published`.
    pub sent: &'static str,
    /// Who sends: `the console`, `the publishers of /x`.
    pub sender: String,
    /// Who receives: `the robot`, `the subscribers of /y`.
    pub receiver: String,
    /// ROS 2 topics: no robot's figures, and the peers are the topics'
    /// publishers and subscribers.
    pub ros2: bool,
    /// What the stream is, before its scenario in a heading: empty, or
    /// `ROS 2 /x → /y, `.
    pub stream: String,
    /// When a release goes nowhere: `no robot was subscribed`.
    pub unsubscribed: String,
}

impl Words {
    /// ITP frames from a console to a robot.
    pub fn itp() -> Words {
        let (sender, receiver, unsubscribed) = ("the console".into(), "the robot".into(), "no robot was subscribed".into());
        Words { unit: "frames", one: "frame", sent: "sent", sender, receiver, ros2: false, stream: String::new(), unsubscribed }
    }

    /// ROS 2 messages from `from`'s publishers to `to`'s subscribers.
    pub fn ros2(from: &str, to: &str) -> Words {
        Words {
            unit: "messages",
            one: "message",
            sent: "published",
            sender: format!("the publishers of {from}"),
            receiver: format!("the subscribers of {to}"),
            ros2: true,
            stream: format!("ROS 2 {from} → {to}, "),
            unsubscribed: format!("no subscriber of {to} was there"),
        }
    }

    /// A peer event's peer (`console`, `simulator`) in these words.
    fn peer<'a>(&'a self, peer: &'a str) -> &'a str {
        match peer {
            "console" if self.ros2 => &self.sender["the ".len()..],
            "simulator" if self.ros2 => &self.receiver["the ".len()..],
            other => other,
        }
    }
}

impl RunReport {
    /// The words of this run's stream.
    pub fn words(&self) -> Words {
        self.ros2.as_ref().map_or_else(Words::itp, |t| Words::ros2(&t.from, &t.to))
    }
}

/// Every frame from the console to the robot, what was dropped, corrupted,
/// and whether it all balances.
fn frames_text(f: &FrameAccount, w: &Words) -> String {
    let mut s = format!(
        "{:<10} {} {}  entered {}  delivered {}  received {}  held at end {}\n",
        w.unit,
        w.sent,
        opt(f.sent),
        opt(f.entered),
        opt(f.delivered),
        opt(f.received),
        opt(f.held_at_end)
    );
    if let Some(n) = f.duplicated.filter(|n| *n > 0) {
        s += &format!("duplicated {n} copies made (each delivered, dropped or held like a frame: delivered may exceed entered by these)\n");
    }
    s += &format!("dropped    {}\n", dropped_list(&f.dropped));
    if let Some(c) = &f.corruption {
        s += &format!(
            "corrupted  {} queued with flipped bits, {} delivered: {} caught by the robot's checksum, {} passed (the checksum does not cover pactyp, version, the rotations or the grasp byte: a flip there is applied)\n",
            c.corrupted,
            c.delivered,
            opt(c.caught),
            opt(c.passed)
        );
    }
    s += &format!("accounting {}\n", accounting(f, w));
    s
}

/// Whether the frames balance, and where: a balanced account with a count
/// no report gives (a client of another make, the lab's own program)
/// balances at the emulator, and says what is not known.
fn accounting(f: &FrameAccount, w: &Words) -> String {
    if !f.balanced {
        return format!("NOT balanced (lost before emulator {}, after emulator {})", opt(f.lost_before_emulator), opt(f.lost_after_emulator));
    }
    let unknown: Vec<String> = [(f.sent.is_none(), format!("what {} {}", w.sender, w.sent)), (f.received.is_none(), format!("what {} received", w.receiver))]
        .into_iter()
        .filter_map(|(unknown, what)| unknown.then_some(what))
        .collect();
    let balanced = balanced_in(w);
    match unknown.is_empty() {
        true => balanced,
        false => format!("balanced at the emulator{}; not known: {} (no report gives it)", &balanced["balanced".len()..], unknown.join(", ")),
    }
}

/// [`BALANCED`] in `w`'s words.
pub(super) fn balanced_in(w: &Words) -> String {
    BALANCED.replace("every frame", &format!("every {}", w.one))
}

pub(super) const BALANCED: &str = "balanced: every frame that entered (and every copy made) was delivered, dropped by the scenario, or held at the end";

/// The realized loss of a direction: what its scenario dropped of the
/// frames it decided, the figure its models' loss compares with.
pub(super) struct LossLine<'a> {
    pub rate: f64,
    pub ci95: [f64; 2],
    /// The models' loss the interval's upper end adds for bursts longer
    /// than the run likely met.
    pub unseen: Option<f64>,
    /// Frames that entered, and every drop by reason (malformed frames',
    /// dropped before the scenario, among them).
    pub entered: Option<u64>,
    pub dropped: &'a BTreeMap<String, u64>,
    pub stages: &'a [StageReport],
}

impl LossLine<'_> {
    #[cfg(test)]
    pub fn text(&self) -> String {
        self.text_in(&Words::itp())
    }

    /// The line in `w`'s words.
    pub fn text_in(&self, w: &Words) -> String {
        let unit = w.unit;
        let [lo, hi] = self.ci95;
        let malformed: Vec<(&String, &u64)> = self.dropped.iter().filter(|(k, n)| crate::injector::Invalid::of_reason(k).is_some() && **n > 0).collect();
        let refused: u64 = malformed.iter().map(|(_, n)| **n).sum();
        let decided = self.entered.map_or(String::new(), |e| format!(" of the {} {unit} it decided", e.saturating_sub(refused)));
        let model = self.model().map_or(String::new(), |m| format!("; model {m:.4}"));
        let mut s = format!("loss       {:.4} realized: the scenario's drops{decided}, 95% CI [{}, {}]{model}\n", self.rate, fmt_rate(lo, 4), fmt_rate(hi, 4));
        if let Some(u) = self.unseen.filter(|u| *u >= 0.00005) {
            s += &format!("           (the upper end adds the {u:.4} the models lose in bursts longer than a run this long likely meets)\n");
        }
        if refused > 0 {
            let each: Vec<String> = malformed.iter().map(|(k, n)| format!("{n} {k}")).collect();
            s += &format!("           {refused} malformed {unit} ({}) were dropped before the scenario: not in this figure\n", each.join(", "));
        }
        s
    }

    /// The scenario's long-run loss by its models, where it has one phase
    /// and every stage's model loss is known: `1 − Π(1 − m_i)`.
    fn model(&self) -> Option<f64> {
        if self.stages.is_empty() || self.stages.iter().any(|s| s.phase != 1) {
            return None;
        }
        self.stages.iter().try_fold(1.0, |pass, s| Some(pass * (1.0 - s.loss_rate_model?))).map(|pass| 1.0 - pass)
    }
}

/// Each stage's share of the loss (and what a `replay` stage replays), and
/// the link stages.
pub(super) fn stages_text(stages: &[StageReport], links: &[LinkReport]) -> String {
    let mut s = String::new();
    for st in stages {
        let model = match (st.loss_rate_model, st.delay_ms_model) {
            (_, Some(d)) => format!("model mean delay {d:.3} ms"),
            (Some(l), None) => format!("model loss {l:.4}"),
            _ => String::new(),
        };
        s += &format!("  phase {} stage {} {:<14} reached {:>9} dropped {:>9} ({:.4})  {model}\n", st.phase, st.stage, st.label, st.reached, st.dropped, st.loss_rate);
        if let Some(rec) = &st.recording {
            s += &format!("    {}\n", rec.text());
        }
    }
    for l in links {
        s += &format!(
            "  link phase {} {:<14} utilisation {:.3} ({:.0} of {:.0} bit/s); queue max {} packets, {} bytes; time at stage p50 {:.3} ms p99 {:.3} ms max {:.3} ms; {} of {} frames dropped for the queue\n",
            l.phase,
            l.label,
            l.utilisation,
            l.carried_bit_s,
            l.capacity_bit_s,
            l.queue_packets_max,
            l.queue_bytes_max,
            l.delay_ms.p50,
            l.delay_ms.p99,
            l.delay_ms.max,
            l.frames_dropped,
            l.frames + l.frames_dropped
        );
    }
    s
}

/// Each stretch of the run under one condition: its loss with its
/// interval against its model, and its delays against its own law.
fn phases_text(phases: &[PhaseFigures], w: &Words) -> String {
    let unit = w.unit;
    let mut s = "phases     each stretch under one condition (the whole-run loss above mixes them)\n".to_string();
    for p in phases {
        s += &format!("  {}  {}: {} {unit}, dropped {}, loss {:.4} [{}, {}]{}\n",
            span_text(p),
            phase_title(p),
            p.frames,
            p.dropped,
            p.loss_rate,
            fmt_rate(p.loss_rate_ci95[0], 4),
            fmt_rate(p.loss_rate_ci95[1], 4),
            p.loss_rate_model.map_or(String::new(), |m| format!(", model {m:.4}")),
        );
        if let Some(dc) = &p.delay_check {
            let law = |q: f64| dc.quantiles.iter().find(|x| x.q == q);
            let mut parts = Vec::new();
            for q in [0.5, 0.9, 0.99] {
                if let Some(x) = law(q) {
                    let model = x.model_ms.map_or(String::new(), |m| format!(" (law {m:.3})"));
                    parts.push(format!("q{q} drawn {:.3} ms{model}, seen {:.3} ms", x.injected_ms, x.seen_ms));
                }
            }
            let verdict = match dc.injected_within_model_band {
                Some(true) => "; every drawn quantile within the law's 95% band",
                Some(false) => "; NOT every drawn quantile within the law's 95% band",
                None => "",
            };
            s += &format!("      delay {} {unit}: {}{verdict}\n", dc.frames, parts.join("; "));
        }
    }
    s
}

/// `[from, to) s` of a stretch, from the run's first frame.
pub(super) fn span_text(p: &PhaseFigures) -> String {
    let to = p.to_ns.map_or("end".to_string(), |t| format!("{:.3}", t as f64 / 1e9));
    format!("{:>8.3}–{to:<8} s", p.from_ns as f64 / 1e9)
}

/// What a stretch ran: `phase 2: DLM-1` or `paused (phase 2: DLM-1)`.
pub fn phase_title(p: &PhaseFigures) -> String {
    let mut what = format!("phase {}: {}", p.run_phase, p.scenario);
    if p.scenario_phase > 1 || p.phase_name.is_some() {
        what += &format!(" phase {}", p.scenario_phase);
        if let Some(n) = &p.phase_name {
            what += &format!(" ({n})");
        }
    }
    if p.paused {
        format!("paused ({what})")
    } else {
        what
    }
}

/// The injected delay of delivered frames.
pub(super) fn injected_text(d: &Option<Summary>) -> String {
    match d {
        Some(x) => format!("delay      injected mean {:.3} ms; {}\n", x.mean / 1e6, line(d)),
        None => String::new(),
    }
}

/// What netfi itself adds: the emulator's own figures, the end to end
/// ones against the direct hop, and the loop's time on frames.
fn overhead_text(o: &Overhead, busy: Option<&LoopBusy>, w: &Words) -> String {
    let mut s = emulator_overhead_text(&o.ingress_wait, &o.decision, &o.release_lateness);
    // A robot's figures: no ROS 2 subscriber reports them.
    if !w.ros2 || o.end_to_end_extra.is_some() || o.direct_hop.is_some() {
        s += &format!("  end-to-end extra  {}\n", line(&o.end_to_end_extra));
        s += &format!("  direct hop        {}\n", line(&o.direct_hop));
    }
    if let Some(a) = &o.added_over_direct {
        let at = |k: &str| a.get(k).map_or("?".to_string(), |v| fmt_ns_signed(*v));
        s += &format!("  added over direct p50 {}  p99 {}  p99.9 {}\n", at("p50"), at("p99"), at("p999"));
        if a.values().any(|v| *v < 0) {
            s += "    (each a difference of the two lines above at that percentile, not a per-frame figure: negative\n     where the direct hop's own tail is longer; release lateness is the emulator's per-frame cost)\n";
        }
    }
    if let Some(b) = busy {
        s += &busy_text_in(b, w);
    }
    s
}

/// The overhead lines the emulator measures itself.
pub(super) fn emulator_overhead_text(ingress_wait: &Option<Summary>, decision: &Option<Summary>, lateness: &Option<Summary>) -> String {
    let mut s = "overhead (what netfi itself adds)\n".to_string();
    s += &format!("  ingress wait      {}\n", line(ingress_wait));
    s += &format!("  decision          {}\n", line(decision));
    s += &format!("  release lateness  {}\n", line(lateness));
    s
}

/// The emulator loop's time on frames, as a line of the overhead part.
pub fn busy_text(b: &LoopBusy) -> String {
    busy_text_in(b, &Words::itp())
}

/// [`busy_text`] in `w`'s words.
pub(super) fn busy_text_in(b: &LoopBusy, w: &Words) -> String {
    let (one, unit) = (w.one, w.unit);
    let (per, cap) = match (b.busy_ns_per_frame, b.capacity_frames_per_s) {
        (Some(p), Some(c)) => (format!("{p:.0} ns a {one}"), format!("{c:.0} {unit}/s")),
        _ => ("-".into(), "-".into()),
    };
    let mut s = format!(
        "  emulator loop     {} of {} turns busy, {:.3} ms on {} {unit}: {per}, capacity {cap} (busy time is an upper bound on the cost)\n",
        b.busy_turns,
        b.turns,
        b.busy_ns as f64 / 1e6,
        b.frames
    );
    if let (Some(p), Some(c)) = (b.short_turns_ns_per_frame, b.short_turns_capacity_frames_per_s) {
        s += &format!(
            "    without the {} turns over 200 µs ({:.3} ms; the core most likely lost): {p:.0} ns a {one}, capacity {c:.0} {unit}/s\n",
            b.long_turns,
            b.long_ns as f64 / 1e6
        );
    }
    s
}

/// The delays seen against the drawn and the model's law, by quantile.
fn delay_law_text(dc: &DelayCheck, w: &Words) -> String {
    let mut s = format!("delay law  {} {}; quantile  model  [95% band]  drawn  seen  seen−drawn\n", dc.frames, w.unit);
    for q in &dc.quantiles {
        let model = match (q.model_ms, q.model_band_ms) {
            (Some(m), Some([lo, hi])) => format!("{m:9.3} [{lo:.3}, {hi:.3}]"),
            _ => "-".into(),
        };
        s += &format!("  q{:<5} {model}  {:9.3} ms  {:9.3} ms  {:+8.1} µs\n", q.q, q.injected_ms, q.seen_ms, q.seen_minus_injected_us);
    }
    s
}

/// The kinematics: per arm, the motion length on each side and the
/// divergence; clutch activations; stalls at the robot.
fn kinematics_text(k: &serde_json::Value) -> String {
    let f = |v: &serde_json::Value| v.as_f64().unwrap_or(f64::NAN);
    let mut s = String::new();
    for arm in 0..2 {
        s += &format!(
            "kinematics arm {arm}: motion console {:.1} mm, robot {:.1} mm; divergence final {:.2} mm, max {:.2} mm\n",
            f(&k["console"]["length_mm"][arm]),
            f(&k["robot"]["length_mm"][arm]),
            f(&k["divergence"][arm]["final_mm"]),
            f(&k["divergence"][arm]["max_mm"]),
        );
    }
    let st = &k["robot"]["stalls"];
    s += &format!(
        "           clutch activations console {} robot {}; robot stalls {} (longest {:.1} ms, total {:.1} ms)\n",
        k["console"]["clutch_activations"],
        k["robot"]["clutch_activations"],
        st["count"],
        f(&st["longest_ns"]) / 1e6,
        f(&st["total_ns"]) / 1e6,
    );
    s
}

/// Peers coming and going, and live control actions.
pub(super) fn happenings_text(peers: &[PeerEvent], events: &[ControlEvent], w: &Words) -> String {
    let mut s = String::new();
    for e in peers {
        s += &format!("peer       t={:.3}s {} connected: {}\n", e.t_s, w.peer(&e.peer), e.connected);
    }
    for e in events {
        s += &format!("control    t={:.3}s {}\n", e.t_s, e.what);
    }
    s
}

impl Provenance {
    fn to_text(&self) -> String {
        format!("provenance netfi {} on {}, started {} (seed {})\n  command  {}\n", self.version, self.host, self.started_utc, self.seed, self.command_line)
    }
}

impl RunStreams {
    /// The table of streams, for the text report.
    pub fn to_text(&self) -> String {
        let mut s = format!("streams    {} (the figures above are stream 0's)\n", self.streams.len());
        s += "  stream  scenario          sent  entered  delivered  received  dropped  held  loss     lateness p99  balanced\n";
        for st in &self.streams {
            let f = &st.frames;
            s += &format!(
                "  {:<6}  {:<16} {:>6} {:>8} {:>10} {:>9} {:>8} {:>5}  {:<7.4}  {:>12}  {}\n",
                st.stream,
                st.scenario,
                opt(f.sent),
                opt(f.entered),
                opt(f.delivered),
                opt(f.received),
                f.dropped.values().sum::<u64>(),
                opt(f.held_at_end),
                st.loss_rate.unwrap_or(f64::NAN),
                st.release_lateness_ns.map_or("?".into(), |p| fmt_ns(p.p99)),
                if f.balanced { "yes" } else { "NO" }
            );
        }
        let t = &self.total;
        s += &format!(
            "  total   {:<16} {:>6} {:>8} {:>10} {:>9} {:>8} {:>5}  {:<7.4}  {:>12}  {}\n",
            "",
            t.sent,
            t.entered,
            t.delivered,
            t.received,
            t.dropped.values().sum::<u64>(),
            t.held_at_end,
            t.loss_rate,
            t.release_lateness_p99_max_ns.map_or("?".into(), fmt_ns),
            if t.balanced { "yes" } else { "NO" }
        );
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stage(phase: usize, model: Option<f64>) -> StageReport {
        serde_json::from_value(serde_json::json!({
            "phase": phase, "stage": 1, "label": "ge_lomax#0", "model": "ge_lomax", "reached": 100, "dropped": 30,
            "loss_rate": 0.3, "loss_rate_model": model, "delay_ms_model": null
        }))
        .unwrap()
    }

    #[test]
    fn the_loss_line_is_the_scenarios_against_its_model_with_malformed_frames_apart() {
        let dropped: BTreeMap<String, u64> = [("ge_lomax".to_string(), 30), ("wrong_size".to_string(), 10), ("bad_checksum".to_string(), 2)].into();
        let stages = [stage(1, Some(0.3042))];
        let line = LossLine { rate: 0.3, ci95: [0.25, 0.36], unseen: Some(0.0227), entered: Some(112), dropped: &dropped, stages: &stages };
        let text = line.text();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines[0], "loss       0.3000 realized: the scenario's drops of the 100 frames it decided, 95% CI [0.2500, 0.3600]; model 0.3042");
        assert_eq!(lines[1], "           (the upper end adds the 0.0227 the models lose in bursts longer than a run this long likely meets)");
        assert_eq!(lines[2], "           12 malformed frames (2 bad_checksum, 10 wrong_size) were dropped before the scenario: not in this figure");
        // No malformed frame, nothing unseen, several phases (no one model):
        // one line; a loss-free run's upper bound never reads as 0.
        let (none, two) = (BTreeMap::new(), [stage(1, Some(0.1)), stage(2, Some(0.2))]);
        let quiet = LossLine { rate: 0.0, ci95: [0.0, 2.9957e-6], unseen: None, entered: Some(1_000_000), dropped: &none, stages: &two };
        assert_eq!(quiet.text(), "loss       0.0000 realized: the scenario's drops of the 1000000 frames it decided, 95% CI [0.0000, 0.0000030]\n");
    }

    #[test]
    fn what_netfi_adds_over_the_direct_hop_reads_in_the_report_s_units() {
        let added: BTreeMap<String, i64> = [("p50".to_string(), 106), ("p99".to_string(), 1_038_200), ("p999".to_string(), -4_702_720)].into();
        let o = Overhead { ingress_wait: None, decision: None, release_lateness: None, end_to_end_extra: None, direct_hop: None, added_over_direct: Some(added) };
        let text = overhead_text(&o, None, &Words::itp());
        assert!(text.contains("  added over direct p50 106 ns  p99 1.038 ms  p99.9 -4.703 ms\n"), "{text}");
        assert!(text.contains("negative\n     where the direct hop's own tail is longer"), "{text}");
    }
}
