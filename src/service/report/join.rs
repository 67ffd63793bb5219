//! The pure joins: the run report's figures as functions of the services'
//! reports alone (no file, no clock). Where a report is missing, what needs
//! it is unknown (`None`) and the account is not balanced.

use super::{Corruption, FrameAccount, Overhead, RunReport, RunStream, RunStreams, StreamsTotal};
use crate::metrics::Summary;
use crate::service::console::ConsoleReport;
use crate::service::schema::{EmulatorFrames, EmulatorProcess, LinkMeasures};
use crate::service::simulator::SimulatorReport;
use std::collections::BTreeMap;

/// Every frame from the console's send to the robot's receive: the three
/// services' counts, what was lost between them, and whether it balances.
pub fn account(console: Option<&ConsoleReport>, emulator: Option<&EmulatorProcess>, simulator: Option<&SimulatorReport>) -> FrameAccount {
    let sent = console.map(|c| c.frames_sent).or_else(|| emulator.and_then(|e| e.frames.sent_by_console));
    let a = emulator.map(|e| &e.frames.account);
    let entered = a.map(|a| a.entered);
    let delivered = a.map(|a| a.delivered);
    let received = simulator.map(|s| s.received);
    let lost_before_emulator = sent.zip(entered).map(|(s, e)| s.saturating_sub(e));
    let lost_after_emulator = delivered.zip(received).map(|(d, r)| d.saturating_sub(r));
    let balanced = a.is_some_and(|a| a.closes()) && sent == entered && delivered == received;
    FrameAccount {
        sent,
        entered,
        delivered,
        received,
        duplicated: a.map(|a| a.duplicated),
        dropped: a.map(|a| a.dropped.clone()).unwrap_or_default(),
        held_at_end: a.map(|a| a.held_at_end),
        lost_before_emulator,
        lost_after_emulator,
        balanced,
        corruption: emulator.and_then(|e| corruption(&e.frames, simulator)),
    }
}

/// [`account`] of a run whose robot was the lab's own program: what it
/// received is not netfi's to know, so the account closes at the
/// emulator's release (every frame the console sent entered, and each was
/// delivered, dropped or held).
pub fn account_to_lab_robot(console: Option<&ConsoleReport>, emulator: Option<&EmulatorProcess>) -> FrameAccount {
    let mut f = account(console, emulator, None);
    f.balanced = emulator.is_some_and(|e| e.frames.account.closes()) && f.sent == f.entered;
    f
}

/// [`account`] of a run no runner started (an emulator started by hand,
/// its clients of any make): a count no report gives (a client of another
/// make writes none, and may send no end marker) is not known, not wrong,
/// so the account balances on the counts there are: the emulator's own
/// closes, and what the console sent and the robot received, where known,
/// is what entered and what was delivered.
pub fn account_by_hand(console: Option<&ConsoleReport>, emulator: Option<&EmulatorProcess>, simulator: Option<&SimulatorReport>) -> FrameAccount {
    let mut f = account(console, emulator, simulator);
    f.balanced = emulator.is_some_and(|e| e.frames.account.closes()) && f.sent.is_none_or(|s| Some(s) == f.entered) && f.received.is_none_or(|r| Some(r) == f.delivered);
    f
}

/// [`account`] of a run of ROS 2 topics (`topics`, and whether
/// `ros2.json` says its messages balance): the publishers' own count
/// (their sequence numbers) stands for the console's, and what they sent
/// before the emulator listened or lost on the way to it is accounted
/// there, not lost; what the subscribers received no report gives.
pub fn account_of_topics(emulator: Option<&EmulatorProcess>, topics: Option<(&super::Ros2Topics, bool)>) -> FrameAccount {
    let mut f = account(None, emulator, None);
    let before = topics.map_or(0, |(t, _)| t.sent_before_emulator + t.lost_before_ingress);
    f.lost_before_emulator = f.sent.zip(f.entered).map(|(s, e)| s.saturating_sub(e + before));
    f.balanced = emulator.is_some_and(|e| e.frames.account.closes()) && topics.is_some_and(|(_, b)| b);
    f
}

/// What `corrupt` stages did against what the robot's checksum caught;
/// `None` when nothing was corrupted. Frames that already had a bad
/// checksum when they entered are not counted as caught, and no more can
/// be caught than were delivered corrupted.
pub fn corruption(frames: &EmulatorFrames, simulator: Option<&SimulatorReport>) -> Option<Corruption> {
    let a = &frames.account;
    if a.corrupted == 0 {
        return None;
    }
    let caught = simulator.map(|s| s.bad_checksum.saturating_sub(frames.bad_checksum_passed).min(a.corrupted_delivered));
    Some(Corruption { corrupted: a.corrupted, delivered: a.corrupted_delivered, caught, passed: caught.map(|c| a.corrupted_delivered - c) })
}

/// What netfi itself added: the emulator's own figures (`link`, its
/// forward path's) and the robot's end-to-end ones; the difference to the
/// direct hop where both were measured.
pub fn overhead(link: Option<&LinkMeasures>, simulator: Option<&SimulatorReport>) -> Overhead {
    let end_to_end_extra = simulator.map(|s| s.end_to_end_extra_ns).filter(|p| p.count > 0);
    let direct_hop = simulator.map(|s| s.direct_hop_ns).filter(|p| p.count > 0);
    Overhead {
        ingress_wait: link.map(|l| l.ingress_wait_ns),
        decision: link.map(|l| l.decision_ns),
        release_lateness: link.map(|l| l.release_lateness_ns),
        added_over_direct: end_to_end_extra.as_ref().zip(direct_hop.as_ref()).map(|(a, b)| difference(a, b)),
        end_to_end_extra,
        direct_hop,
    }
}

/// `a − b` for the main percentiles.
pub fn difference(a: &Summary, b: &Summary) -> BTreeMap<String, i64> {
    crate::metrics::difference(a, b, &["p50", "p90", "p99", "p999"])
}

/// What the frame account shows went wrong: frames lost between the
/// processes.
pub fn faults(frames: &FrameAccount) -> Vec<String> {
    let mut faults = Vec::new();
    if let Some(n) = frames.lost_before_emulator.filter(|n| *n > 0) {
        faults.push(format!("{n} frames sent by the console never entered the emulator"));
    }
    if let Some(n) = frames.lost_after_emulator.filter(|n| *n > 0) {
        faults.push(format!("{n} frames released by the emulator never reached the simulator"));
    }
    faults
}

/// [`faults`] of a run of ROS 2 topics: messages the publishers' count
/// says they sent, neither entered, sent before the emulator listened, nor
/// lost on the way to it.
pub fn faults_of_topics(frames: &FrameAccount) -> Vec<String> {
    frames.lost_before_emulator.filter(|n| *n > 0).map(|n| format!("{n} messages the publishers sent are unaccounted for: they did not enter the emulator, and were neither sent before it listened nor missing from their sequence numbers")).into_iter().collect()
}

impl RunStream {
    /// Stream `k`'s line of its own report.
    pub fn of(k: usize, r: &RunReport) -> RunStream {
        RunStream {
            stream: k,
            run_id: r.run_id.clone(),
            scenario: r.scenario.clone(),
            seed: r.seed,
            frames: r.frames.clone(),
            loss_rate: r.loss_rate,
            loss_rate_ci95: r.loss_rate_ci95,
            release_lateness_ns: r.overhead_ns.release_lateness,
            end_to_end_extra_ns: r.overhead_ns.end_to_end_extra,
            added_over_direct_ns: r.overhead_ns.added_over_direct.clone(),
            faults: r.faults.clone(),
            report_json: r.files.report_json.clone(),
        }
    }
}

impl StreamsTotal {
    /// The streams' frames summed (an unknown count adds nothing); balanced
    /// when every stream is.
    pub fn of(streams: &[RunStream]) -> StreamsTotal {
        let mut t = StreamsTotal { balanced: true, ..StreamsTotal::default() };
        for s in streams {
            let f = &s.frames;
            t.sent += f.sent.unwrap_or(0);
            t.entered += f.entered.unwrap_or(0);
            t.delivered += f.delivered.unwrap_or(0);
            t.received += f.received.unwrap_or(0);
            t.duplicated += f.duplicated.unwrap_or(0);
            t.held_at_end += f.held_at_end.unwrap_or(0);
            for (k, v) in &f.dropped {
                *t.dropped.entry(k.clone()).or_default() += v;
            }
            t.balanced &= f.balanced;
        }
        let dropped: u64 = t.dropped.values().sum();
        t.loss_rate = if t.entered > 0 { dropped as f64 / t.entered as f64 } else { 0.0 };
        t.release_lateness_p99_max_ns = streams.iter().filter_map(|s| s.release_lateness_ns.map(|p| p.p99)).max();
        t
    }
}

impl RunStreams {
    /// The streams' lines and their total.
    pub fn of(streams: Vec<RunStream>) -> RunStreams {
        RunStreams { total: StreamsTotal::of(&streams), streams }
    }
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;
    use crate::service::schema::Account;
    use serde_json::json;

    pub fn console(sent: u64) -> ConsoleReport {
        serde_json::from_value(json!({
            "frames_sent": sent, "source": "synthetic", "rate_hz": 1000.0, "seed": 1, "duration_s": 1.0,
            "send_lateness_ns": Summary::default(), "send_errors": 0, "sent_unsubscribed": 0, "direct_sent": sent,
            "ended_by": "done", "steal_ms": 0, "steal_fraction": 0.0
        }))
        .unwrap()
    }

    pub fn simulator(received: u64, bad_checksum: u64) -> SimulatorReport {
        serde_json::from_value(json!({
            "received": received, "received_direct": received, "wrong_size": 0, "bad_checksum": bad_checksum,
            "released_by_emulator": null, "end_to_end_extra_ns": Summary::default(), "direct_hop_ns": Summary::default(),
            "delay_seen_ns": Summary::default(), "kinematics": null, "ended_by": "end_marker", "duration_s": 1.0,
            "receive_errors": 0, "steal_ms": 0, "steal_fraction": 0.0, "received_csv": null, "end_to_end_hlog": null,
            "feedback_sent": received
        }))
        .unwrap()
    }

    /// An emulator whose console said it sent `sent_by_console`.
    pub fn emulator(entered: u64, delivered: u64, dropped: u64, held: u64, sent_by_console: Option<u64>) -> EmulatorProcess {
        let account = Account { entered, delivered, dropped: [("ge_lomax".to_string(), dropped)].into(), held_at_end: held, ..Account::default() };
        let frames = EmulatorFrames { account, sent_by_console, ..EmulatorFrames::default() };
        serde_json::from_value(json!({
            "scenario": "PLM-2", "seed": 7, "core": null, "realtime_priority": null, "queue_order": "fifo",
            "queue_capacity": 16, "frames": frames, "ended_by": "end_marker", "duration_s": 1.0,
            "receive_errors": 0, "send_errors": 0, "trace_overflowed": 0, "steal_ms": 0, "steal_fraction": 0.0
        }))
        .unwrap()
    }

    #[test]
    fn a_ros2_run_accounts_what_was_published_before_the_emulator_and_balances_at_it() {
        let topics = |before, lost| super::super::Ros2Topics { from: "/x".into(), to: "/y".into(), type_name: "std_msgs/msg/String".into(), lost_before_ingress: lost, sent_before_emulator: before };
        // 12 published: 2 before the emulator listened, 10 entered.
        let e = emulator(10, 6, 3, 1, Some(12));
        let f = account_of_topics(Some(&e), Some((&topics(2, 0), true)));
        assert!(f.balanced && f.lost_before_emulator == Some(0) && f.received.is_none(), "{f:?}");
        assert!(faults_of_topics(&f).is_empty());
        // 1 missing that nothing explains: a fault, and not balanced.
        let f = account_of_topics(Some(&e), Some((&topics(1, 0), false)));
        assert!(!f.balanced && f.lost_before_emulator == Some(1), "{f:?}");
        assert_eq!(faults_of_topics(&f).len(), 1);
    }

    #[test]
    fn a_run_balances_when_every_frame_is_accounted_for_between_the_processes() {
        let (c, e, s) = (console(10), emulator(10, 6, 3, 1, Some(10)), simulator(6, 0));
        let f = account(Some(&c), Some(&e), Some(&s));
        assert_eq!((f.sent, f.entered, f.delivered, f.received, f.held_at_end), (Some(10), Some(10), Some(6), Some(6), Some(1)));
        assert_eq!((f.lost_before_emulator, f.lost_after_emulator), (Some(0), Some(0)));
        assert!(f.balanced);
        assert_eq!(f.dropped["ge_lomax"], 3);
        assert_eq!(f.corruption, None);
        assert!(faults(&f).is_empty());
    }

    #[test]
    fn frames_lost_between_the_processes_unbalance_the_run_and_are_faults() {
        let e = emulator(10, 6, 3, 1, Some(12));
        let before = account(Some(&console(12)), Some(&e), Some(&simulator(6, 0)));
        assert_eq!(before.lost_before_emulator, Some(2));
        assert!(!before.balanced);
        assert_eq!(faults(&before), ["2 frames sent by the console never entered the emulator"]);
        let after = account(Some(&console(10)), Some(&emulator(10, 6, 3, 1, Some(10))), Some(&simulator(5, 0)));
        assert_eq!(after.lost_after_emulator, Some(1));
        assert!(!after.balanced);
        assert_eq!(faults(&after), ["1 frames released by the emulator never reached the simulator"]);
        // Counts that agree between processes but an emulator account that does not close.
        let open = account(Some(&console(10)), Some(&emulator(10, 6, 3, 0, Some(10))), Some(&simulator(6, 0)));
        assert_eq!((open.lost_before_emulator, open.lost_after_emulator), (Some(0), Some(0)));
        assert!(!open.balanced);
    }

    #[test]
    fn a_missing_report_leaves_its_counts_unknown_and_the_run_unbalanced() {
        // A foreign console: the emulator's word for what was sent.
        let e = emulator(10, 6, 3, 1, Some(10));
        let no_console = account(None, Some(&e), Some(&simulator(6, 0)));
        assert_eq!(no_console.sent, Some(10));
        assert!(no_console.balanced, "the console's end marker is its word");
        // A foreign robot: what it received is unknown.
        let no_robot = account(Some(&console(10)), Some(&e), None);
        assert_eq!((no_robot.received, no_robot.lost_after_emulator), (None, None));
        assert!(!no_robot.balanced);
        assert!(faults(&no_robot).is_empty(), "unknown is not lost");
        let no_emulator = account(Some(&console(10)), None, Some(&simulator(6, 0)));
        assert_eq!((no_emulator.entered, no_emulator.held_at_end, no_emulator.lost_before_emulator), (None, None, None));
        assert!(!no_emulator.balanced);
        assert!(!account(None, None, None).balanced);
    }

    #[test]
    fn copies_may_make_more_delivered_than_entered() {
        let mut e = emulator(10, 9, 2, 1, Some(10));
        assert!(!account(Some(&console(10)), Some(&e), Some(&simulator(9, 0))).balanced, "two frames too many without copies");
        e.frames.account.duplicated = 2;
        let f = account(Some(&console(10)), Some(&e), Some(&simulator(9, 0)));
        assert_eq!(f.duplicated, Some(2));
        assert!(f.balanced);
    }

    #[test]
    fn corruption_caught_is_what_the_robot_found_less_what_came_in_bad() {
        let mut e = emulator(10, 10, 0, 0, Some(10));
        let a = &mut e.frames.account;
        (a.corrupted, a.corrupted_delivered) = (4, 3);
        e.frames.bad_checksum_passed = 3;
        let c = corruption(&e.frames, Some(&simulator(10, 5))).unwrap();
        assert_eq!((c.corrupted, c.delivered, c.caught, c.passed), (4, 3, Some(2), Some(1)));
        // More bad checksums than corrupted frames delivered: no more caught than delivered.
        let c = corruption(&e.frames, Some(&simulator(10, 50))).unwrap();
        assert_eq!((c.caught, c.passed), (Some(3), Some(0)));
        // No robot report: caught and passed unknown.
        let c = corruption(&e.frames, None).unwrap();
        assert_eq!((c.caught, c.passed), (None, None));
        e.frames.account.corrupted = 0;
        assert_eq!(corruption(&e.frames, Some(&simulator(10, 5))), None);
    }

    #[test]
    fn the_overhead_over_the_direct_hop_needs_both_measured() {
        let mut s = simulator(6, 0);
        s.end_to_end_extra_ns = Summary { count: 6, p50: 5_000, p90: 6_000, p99: 9_000, p999: 9_500, ..Summary::default() };
        s.direct_hop_ns = Summary { count: 6, p50: 2_000, p90: 2_500, p99: 12_000, p999: 12_000, ..Summary::default() };
        let o = overhead(None, Some(&s));
        assert_eq!((o.ingress_wait, o.decision, o.release_lateness), (None, None, None));
        let added = o.added_over_direct.unwrap();
        assert_eq!((added["p50"], added["p90"], added["p99"], added["p999"]), (3_000, 3_500, -3_000, -2_500));
        s.direct_hop_ns.count = 0;
        let o = overhead(None, Some(&s));
        assert_eq!((o.direct_hop, o.added_over_direct), (None, None), "a console without its direct copies");
        assert_eq!(overhead(None, None).end_to_end_extra, None);
    }

    fn stream(k: usize, f: FrameAccount, p99: Option<u64>) -> RunStream {
        RunStream {
            stream: k,
            run_id: format!("r-s{k}"),
            scenario: "PLM-2".into(),
            seed: k as u64,
            frames: f,
            loss_rate: None,
            loss_rate_ci95: None,
            release_lateness_ns: p99.map(|p99| Summary { p99, ..Summary::default() }),
            end_to_end_extra_ns: None,
            added_over_direct_ns: None,
            faults: vec![],
            report_json: format!("stream-{k}/report.json").into(),
        }
    }

    #[test]
    fn the_streams_total_sums_what_is_known_and_balances_only_when_every_stream_does() {
        let whole = account(Some(&console(10)), Some(&emulator(10, 6, 3, 1, Some(10))), Some(&simulator(6, 0)));
        let no_robot = account(Some(&console(20)), Some(&emulator(20, 10, 10, 0, Some(20))), None);
        let s = RunStreams::of(vec![stream(0, whole.clone(), Some(900)), stream(1, no_robot, Some(1_200)), stream(2, whole, None)]);
        let t = &s.total;
        assert_eq!((t.sent, t.entered, t.delivered, t.received, t.held_at_end), (40, 40, 22, 12, 2));
        assert_eq!(t.dropped["ge_lomax"], 16);
        assert!((t.loss_rate - 16.0 / 40.0).abs() < 1e-12);
        assert!(!t.balanced, "stream 1's robot is unknown");
        assert_eq!(t.release_lateness_p99_max_ns, Some(1_200));
        assert_eq!(s.streams.len(), 3);
        let none = RunStreams::of(vec![]);
        assert!(none.total.balanced && none.total.loss_rate == 0.0 && none.total.release_lateness_p99_max_ns.is_none());
    }
}
