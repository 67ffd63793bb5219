//! What the return path adds to its path's report (`FeedbackExtra` over
//! iceoryx2, `ReturnExtra` over UDP), and the run report's feedback
//! section: the emulator's feedback path joined with the console's view of
//! it and the robot's own count.

use super::super::declare::Sources;
use crate::metrics::{fmt_rate, Summary};
use crate::metrics::text::{dropped_list, line, opt};
use crate::service::schema::PathReport;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// What the feedback channel adds to its path's report: the feedback
/// samples the robot said it sent (from its end marker).
pub type FeedbackExtra = crate::service::channel::relay::RelayExtra;

/// What the UDP return channel adds to its path's report: `received =
/// entered + unroutable`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ReturnExtra {
    /// `untouched` (no return scenario) or `scenario`.
    pub mode: String,
    /// Where return datagrams go.
    pub destination: String,
    /// Datagrams taken off the egress socket.
    pub received: u64,
    /// Received before any console was known: not relayed.
    pub unroutable: u64,
    /// Return datagrams the kernel dropped before the emulator took them.
    pub kernel_drops: Option<u64>,
    /// Datagrams at the egress socket from others than the robot: refused.
    #[serde(default)]
    pub refused: crate::transport::udp::Refused,
}

/// What the console saw of the robot's feedback.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ConsoleFeedback {
    /// Feedback samples received on `feedback_out`.
    pub received: u64,
    /// Feedback the emulator said it released (from its end marker).
    pub sent_by_emulator: Option<u64>,
    /// Feedback naming a command this console never sent.
    pub unknown_command: u64,
    /// `end_marker`, `no_emulator` (nobody published feedback), `timeout`
    /// or `signal`.
    pub ended_by: crate::service::schema::Ended,
    /// Command sent → the robot's feedback naming it received.
    pub round_trip_ns: Summary,
    /// The emulator's own share of each round trip: both directions'
    /// release − take − injected delay.
    pub emulator_share_ns: Summary,
    /// Robot position (from its feedback) against the console's own pose
    /// after the same command, per arm, mm.
    pub divergence_final_mm: [f64; 2],
    pub divergence_max_mm: [f64; 2],
    pub round_trip_hlog: Option<std::path::PathBuf>,
    /// Why `round_trip.hlog` could not be written whole (it is then absent,
    /// or left cut as `round_trip.hlog.partial`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub round_trip_hlog_error: Option<String>,
}

/// The feedback loop robot → emulator → console: what the return scenario
/// did, every feedback sample accounted for, and the round trip.
///
/// `sent_by_robot = entered + not_taken_at_stop`, `entered + duplicated =
/// delivered + dropped + held_at_end`, `delivered = received_by_console +
/// unread_at_stop`: `balanced` (on the counts the run's reports give: a
/// robot's or console's without a report of its own is unknown, `None`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FeedbackSection {
    pub return_scenario: String,
    pub seed: u64,
    pub sent_by_robot: Option<u64>,
    pub entered: u64,
    pub delivered: u64,
    /// Copies made by `duplicate` stages of the return scenario.
    #[serde(default)]
    pub duplicated: u64,
    pub dropped: BTreeMap<String, u64>,
    pub held_at_end: u64,
    pub received_by_console: Option<u64>,
    /// In a stopped run: samples the robot sent after the emulator had
    /// stopped taking them, and samples the emulator delivered after the
    /// console had stopped reading (the processes stop console first,
    /// robot last). Both 0 in a run that ended on its own.
    #[serde(default)]
    pub not_taken_at_stop: u64,
    #[serde(default)]
    pub unread_at_stop: u64,
    pub balanced: bool,
    pub loss_rate: f64,
    pub loss_rate_ci95: [f64; 2],
    pub injected_delay_ns: Summary,
    /// Command sent → the robot's feedback naming it received, at the console.
    pub round_trip_ns: Option<Summary>,
    /// The emulator's own share of each round trip (both directions).
    pub emulator_share_ns: Option<Summary>,
    /// The robot's position (from its feedback) against the console's,
    /// per arm, mm: at the last feedback, and the most seen.
    pub divergence_final_mm: Option<[f64; 2]>,
    pub divergence_max_mm: Option<[f64; 2]>,
    /// Why the console's `round_trip.hlog` was not written whole.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub round_trip_hlog_error: Option<String>,
}

/// The run's feedback section, where the emulator had a feedback path: the
/// console's report's `feedback`, the robot's `feedback_sent`.
pub fn join(s: Sources) -> Option<FeedbackSection> {
    let e = s.emulator?.path::<FeedbackExtra>(super::iceoryx2::NAME)?;
    let console: Option<ConsoleFeedback> = s.console_part("feedback");
    let robot_sent = s.simulator.and_then(|r| r.get("feedback_sent")).and_then(serde_json::Value::as_u64);
    Some(FeedbackSection::join(&e, console.as_ref(), robot_sent, s.stopped))
}

impl FeedbackSection {
    /// Joins the emulator's feedback path, the console's view of it and
    /// the robot's own count of what it sent (`robot_sent`, from its
    /// report): that count stands where the robot's end marker did not
    /// reach the emulator before it stopped waiting for it. In a run that
    /// was `stopped`, the processes stop console first and robot last:
    /// what the robot sent after the emulator stopped, and what the
    /// emulator delivered after the console stopped reading, were in
    /// flight at the stop and are counted as such.
    pub fn join(e: &PathReport<FeedbackExtra>, c: Option<&ConsoleFeedback>, robot_sent: Option<u64>, stopped: bool) -> FeedbackSection {
        let received_by_console = c.map(|c| c.received);
        let sent_by_robot = e.extra.sent_by_robot.or(robot_sent);
        let a = &e.account;
        let (mut not_taken_at_stop, mut unread_at_stop) = (0, 0);
        if stopped {
            not_taken_at_stop = sent_by_robot.map_or(0, |s| s.saturating_sub(a.entered));
            unread_at_stop = received_by_console.map_or(0, |r| a.delivered.saturating_sub(r));
        }
        // A count no report gives (the lab's own robot or console, a
        // stand-alone emulator) is unknown, not wrong: the section balances
        // on the counts there are.
        let balanced = a.closes()
            && sent_by_robot.is_none_or(|s| s == a.entered + not_taken_at_stop)
            && received_by_console.is_none_or(|r| r + unread_at_stop == a.delivered);
        FeedbackSection {
            return_scenario: e.scenario.clone(),
            seed: e.seed,
            sent_by_robot,
            entered: a.entered,
            delivered: a.delivered,
            duplicated: a.duplicated,
            dropped: a.dropped.clone(),
            held_at_end: a.held_at_end,
            received_by_console,
            not_taken_at_stop,
            unread_at_stop,
            balanced,
            loss_rate: e.measures.loss_rate,
            loss_rate_ci95: e.measures.loss_rate_ci95,
            injected_delay_ns: e.measures.injected_delay_ns,
            round_trip_ns: c.map(|c| c.round_trip_ns).filter(|s| s.count > 0),
            emulator_share_ns: c.map(|c| c.emulator_share_ns).filter(|s| s.count > 0),
            divergence_final_mm: c.map(|c| c.divergence_final_mm),
            divergence_max_mm: c.map(|c| c.divergence_max_mm),
            round_trip_hlog_error: c.and_then(|c| c.round_trip_hlog_error.clone()),
        }
    }

    /// What is wrong when the section does not balance.
    pub fn fault(&self) -> Option<String> {
        self.unbalanced()
    }

    /// What is wrong with the section: it does not balance; the round
    /// trip's histogram log was not written whole.
    pub fn faults(&self) -> Vec<String> {
        let hlog = self.round_trip_hlog_error.as_ref().map(|e| format!("the console's round_trip.hlog not written whole: {e}"));
        self.unbalanced().into_iter().chain(hlog).collect()
    }

    fn unbalanced(&self) -> Option<String> {
        (!self.balanced).then(|| {
            format!(
                "feedback not balanced: the robot sent {}, {} entered the emulator, {} were delivered, the console received {}",
                opt(self.sent_by_robot),
                self.entered,
                self.delivered,
                opt(self.received_by_console)
            )
        })
    }

    /// The feedback loop's lines of the text report.
    pub fn to_text(&self) -> String {
        let mut s = format!(
            "feedback   return scenario {} (seed {}): sent by robot {}  entered {}  delivered {}  received {}  held at end {}; dropped {}\n",
            self.return_scenario,
            self.seed,
            opt(self.sent_by_robot),
            self.entered,
            self.delivered,
            opt(self.received_by_console),
            self.held_at_end,
            dropped_list(&self.dropped)
        );
        if self.duplicated > 0 {
            s += &format!("  duplicated {} copies made (delivered may exceed entered by these)\n", self.duplicated);
        }
        if self.not_taken_at_stop + self.unread_at_stop > 0 {
            s += &format!(
                "  in flight at the stop: {} sent by the robot after the emulator stopped, {} delivered after the console stopped reading\n",
                self.not_taken_at_stop, self.unread_at_stop
            );
        }
        s += &format!(
            "  accounting {}; loss {:.4}, 95% CI [{}, {}]\n",
            if self.balanced { "balanced" } else { "NOT balanced" },
            self.loss_rate,
            fmt_rate(self.loss_rate_ci95[0], 4),
            fmt_rate(self.loss_rate_ci95[1], 4)
        );
        s += &format!("  round trip        {}\n", line(&self.round_trip_ns));
        s += &format!("  emulator's share  {}\n", line(&self.emulator_share_ns));
        if let (Some(f), Some(m)) = (self.divergence_final_mm, self.divergence_max_mm) {
            s += &format!("  live divergence   arm 0 final {:.2} mm (max {:.2}), arm 1 final {:.2} mm (max {:.2})\n", f[0], m[0], f[1], m[1]);
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn feedback_path(entered: u64, delivered: u64, sent_by_robot: Option<u64>) -> PathReport<FeedbackExtra> {
        serde_json::from_value(json!({
            "scenario": "Normal", "seed": 3, "queue_order": "fifo", "queue_capacity": 16,
            "entered": entered, "delivered": delivered, "dropped": {"bernoulli": entered - delivered}, "held_at_end": 0,
            "delivered_unsubscribed": 0, "balanced": true, "loss_rate": 0.0, "loss_rate_ci95": [0.0, 0.1], "stages": [],
            "injected_delay_ns": Summary::default(), "ingress_wait_ns": Summary::default(), "decision_ns": Summary::default(),
            "release_lateness_ns": Summary::default(), "send_errors": 0, "receive_errors": 0, "trace_path": "trace_feedback.csv",
            "sent_by_robot": sent_by_robot
        }))
        .unwrap()
    }

    fn console_feedback(received: u64) -> ConsoleFeedback {
        let rtt = Summary { count: received, p50: 1_000, ..Summary::default() };
        serde_json::from_value(json!({
            "received": received, "sent_by_emulator": received, "unknown_command": 0, "ended_by": "end_marker",
            "round_trip_ns": rtt, "emulator_share_ns": Summary::default(), "divergence_final_mm": [0.5, 0.25],
            "divergence_max_mm": [1.0, 0.5], "round_trip_hlog": null
        }))
        .unwrap()
    }

    #[test]
    fn feedback_balances_from_the_robot_through_the_emulator_to_the_console() {
        let f = FeedbackSection::join(&feedback_path(10, 8, Some(10)), Some(&console_feedback(8)), Some(10), false);
        assert!(f.balanced, "{f:?}");
        assert_eq!((f.return_scenario.as_str(), f.seed, f.dropped["bernoulli"]), ("Normal", 3, 2));
        assert_eq!(f.round_trip_ns.map(|s| s.p50), Some(1_000));
        assert_eq!(f.emulator_share_ns, None, "an empty distribution is none");
        assert_eq!(f.divergence_max_mm, Some([1.0, 0.5]));
        assert_eq!(f.fault(), None);
        // The robot's end marker did not reach the emulator: its own count stands.
        let late = FeedbackSection::join(&feedback_path(10, 8, None), Some(&console_feedback(8)), Some(10), false);
        assert_eq!(late.sent_by_robot, Some(10));
        assert!(late.balanced);
        // The console received less than was delivered.
        let short = FeedbackSection::join(&feedback_path(10, 8, Some(10)), Some(&console_feedback(7)), Some(10), false);
        assert!(!short.balanced);
        let fault = short.fault().unwrap();
        assert_eq!(fault, "feedback not balanced: the robot sent 10, 10 entered the emulator, 8 were delivered, the console received 7");
        // The robot sent more than entered.
        assert!(!FeedbackSection::join(&feedback_path(10, 8, Some(11)), Some(&console_feedback(8)), None, false).balanced);
        // No console report (the lab's own console): what it received is
        // unknown, not a fault; the emulator's own account still must close.
        let foreign = FeedbackSection::join(&feedback_path(10, 8, Some(10)), None, None, false);
        assert_eq!((foreign.received_by_console, foreign.round_trip_ns, foreign.balanced), (None, None, true));
        assert!(foreign.to_text().contains("console received ?") || foreign.to_text().contains('?'), "{}", foreign.to_text());
        let mut open = feedback_path(10, 8, Some(10));
        open.account.held_at_end = 1;
        let fault = FeedbackSection::join(&open, None, None, false).fault().unwrap();
        assert!(fault.ends_with("the console received ?"), "{fault}");
    }

    #[test]
    fn a_stopped_run_accounts_the_feedback_in_flight_at_the_stop() {
        // The console stopped reading with one sample delivered to it, and
        // the robot sent two after the emulator stopped taking them.
        let stopped = FeedbackSection::join(&feedback_path(10, 8, Some(12)), Some(&console_feedback(7)), Some(12), true);
        assert!(stopped.balanced, "{stopped:?}");
        assert_eq!((stopped.not_taken_at_stop, stopped.unread_at_stop), (2, 1));
        // The same counts in a run that ended on its own are lost samples.
        let ended = FeedbackSection::join(&feedback_path(10, 8, Some(12)), Some(&console_feedback(7)), Some(12), false);
        assert!(!ended.balanced);
        assert_eq!((ended.not_taken_at_stop, ended.unread_at_stop), (0, 0));
        // A stop explains nothing the other way: a console that received
        // more than was delivered, or an emulator account that does not close.
        assert!(!FeedbackSection::join(&feedback_path(10, 8, Some(10)), Some(&console_feedback(9)), Some(10), true).balanced);
        let mut open = feedback_path(10, 8, Some(10));
        open.account.held_at_end = 1;
        assert!(!FeedbackSection::join(&open, Some(&console_feedback(8)), Some(10), true).balanced);
    }
}
