//! The feedback loop over iceoryx2: robot → emulator → console. The robot
//! publishes one [`FeedbackSample`] per command it received (its integrated
//! pose and which command that was) on `netfi/<run>/feedback`; the emulator
//! passes each through a [`Link`] of its own, shaped by the return scenario
//! (`--return-scenario`, default `Normal`), and releases survivors on
//! `netfi/<run>/feedback_out`, where the console measures the round trip.
//!
//! The path is polled by the emulator's one pinned loop, once per turn
//! ([`super::emulator::Forward::turn`]): every due release, then at most one
//! feedback sample in. Like the forward path it allocates nothing and takes
//! no lock per sample; every feedback sample that enters gets exactly one
//! fate, and `entered = delivered + dropped + held_at_end` is checked at the
//! end.
//!
//! The robot ends its feedback with an end marker once it has the
//! emulator's; the emulator then releases what it holds, forwards its own
//! marker (carrying the number released) to the console, and ends. A robot
//! that publishes no feedback (or is gone) does not hold the run: once the
//! forward stream has ended, the path ends when no robot publishes on
//! `feedback` and nothing is held, or after the feedback grace.

use crate::clock::now_ns;
use crate::metrics::Summary;
use crate::sample::FeedbackSample;
use crate::scenario::Scenario;
use crate::service::link::{Arrival, Carried, Link, Release};
use crate::transport::{FeedbackEgress, FeedbackIngress, PortError};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

impl Carried for FeedbackSample {
    /// A copy of feedback is a second release of the same sample; a flip
    /// needs an ITP frame's bytes, which feedback is not.
    const UNSUPPORTED: &'static [crate::model::ModelKind] = &[crate::model::ModelKind::Corrupt];

    #[inline]
    fn ingress_ns(&self) -> u64 {
        self.ingress_ns
    }
}

/// Feedback is released stamped with its scheduled and actual release times
/// and its injected delay.
impl Release<FeedbackSample> for FeedbackEgress {
    #[inline]
    fn release(&mut self, item: &FeedbackSample, scheduled_ns: u64) -> Result<u64, (u64, PortError)> {
        let mut release_ns = 0;
        let sent = self.send_with(item, |s| {
            s.release_sched_ns = scheduled_ns;
            s.injected_delay_ns = scheduled_ns - s.ingress_ns;
            release_ns = now_ns();
            s.release_ns = release_ns;
        });
        match sent {
            Ok(_) => Ok(release_ns),
            Err(e) => Err((now_ns(), e)),
        }
    }
}

/// How long the feedback path waits, once the forward stream has ended,
/// for the robot's end marker while a robot still publishes: 2 s.
pub const FEEDBACK_GRACE_NS: u64 = 2_000_000_000;

/// The feedback direction of the emulator: its link and its two ports.
pub struct FeedbackPath {
    /// The link every feedback sample goes through.
    pub link: Link<FeedbackSample>,
    source: FeedbackIngress,
    sink: FeedbackEgress,
    sample: FeedbackSample,
    seed: u64,
    sent_by_robot: Option<u64>,
    end_forwarded: bool,
    receive_errors: u64,
    last_error: Option<PortError>,
    last_rx_ns: u64,
}

impl FeedbackPath {
    /// A feedback path from `source` to `sink` through `link` (whose
    /// scenario was seeded with `seed`).
    pub fn new(link: Link<FeedbackSample>, seed: u64, source: FeedbackIngress, sink: FeedbackEgress) -> FeedbackPath {
        FeedbackPath {
            link,
            source,
            sink,
            sample: FeedbackSample::ZERO,
            seed,
            sent_by_robot: None,
            end_forwarded: false,
            receive_errors: 0,
            last_error: None,
            last_rx_ns: 0,
        }
    }

    /// One turn: every due release, then at most one feedback sample in.
    #[inline]
    pub fn poll(&mut self) {
        self.link.release_due(now_ns(), &mut self.sink);
        let s = &mut self.sample;
        match self.source.try_recv(s) {
            Ok(true) if s.is_end() => self.sent_by_robot = Some(s.robot_index),
            Ok(true) => {
                let t_take = now_ns();
                self.last_rx_ns = t_take;
                s.ingress_index = self.link.next_ingress_index();
                s.ingress_ns = t_take;
                let arrival = Arrival { sequence: Some(s.sequence), console_index: s.robot_index, send_ns: s.send_ns };
                self.link.ingress(t_take, *s, arrival);
            }
            Ok(false) => {}
            Err(e) => {
                self.receive_errors += 1;
                self.last_error = Some(e);
            }
        }
    }

    /// Whether the path has ended, asked off the hot path once the forward
    /// stream has ended (at `forward_end_ns`): the robot's end marker has
    /// come and every held sample is released; or no robot publishes and
    /// nothing is held; or the robot's marker has not come within the
    /// grace (what is still held then is `held_at_end`). Forwards the end marker to
    /// the console when it ends.
    pub fn finished(&mut self, now: u64, forward_end_ns: u64) -> bool {
        if self.end_forwarded {
            return true;
        }
        let held = self.link.held();
        let robot_gone = self.source.peers() == Some(0) && now.saturating_sub(self.last_rx_ns) > 50_000_000;
        let done = (self.sent_by_robot.is_some() && held == 0)
            || (robot_gone && held == 0)
            || (self.sent_by_robot.is_none() && now.saturating_sub(forward_end_ns) > FEEDBACK_GRACE_NS);
        if done {
            self.forward_end();
        }
        done
    }

    /// Sends the console the end marker (best effort), once.
    pub fn forward_end(&mut self) {
        if !self.end_forwarded {
            self.end_forwarded = true;
            let _ = self.sink.send_with(&FeedbackSample::end_marker(self.link.released()), |_| {});
        }
    }

    /// The two ports (tests drive in-memory ones).
    pub fn ports_mut(&mut self) -> (&mut FeedbackIngress, &mut FeedbackEgress) {
        (&mut self.source, &mut self.sink)
    }

    /// Keeps the trace's writer thread off `core`; `false` where it may
    /// use no other core.
    pub fn keep_trace_off_core(&self, core: usize) -> bool {
        self.link.keep_trace_off_core(core)
    }

    /// Stops the trace writer, writes `trace_feedback.csv` into `out_dir`,
    /// checks the account, and reports.
    pub fn finish(mut self, out_dir: &Path, duration_ns: u64) -> anyhow::Result<FeedbackReport> {
        self.forward_end();
        let unsubscribed = self.sink.unsubscribed();
        if let Some(e) = &self.last_error {
            eprintln!("emulator: last feedback receive error: {e}");
        }
        let l = self.link.finish(&out_dir.join("trace_feedback.csv"), duration_ns)?;
        if let Some(e) = &l.last_error {
            eprintln!("emulator: last feedback send error: {e}");
        }
        let dropped_total: u64 = l.dropped.values().sum();
        Ok(FeedbackReport {
            scenario: l.scenario,
            seed: self.seed,
            queue_order: l.queue_order,
            queue_capacity: l.queue_capacity,
            sent_by_robot: self.sent_by_robot,
            entered: l.entered,
            delivered: l.delivered,
            duplicated: l.duplicated,
            delivered_unsubscribed: unsubscribed,
            dropped: l.dropped,
            held_at_end: l.held_at_end,
            balanced: l.entered + l.duplicated == l.delivered + dropped_total + l.held_at_end
                && self.sent_by_robot.map_or(true, |n| n == l.entered),
            loss_rate: l.measures.loss_rate,
            loss_rate_ci95: l.measures.loss_rate_ci95,
            injected_delay_ns: l.measures.injected_delay_ns,
            decision_ns: l.measures.decision_ns,
            release_lateness_ns: l.measures.release_lateness_ns,
            send_errors: l.send_errors,
            receive_errors: self.receive_errors,
            trace_path: l.trace_path,
        })
    }
}

/// What the feedback path did: `entered + duplicated = delivered + dropped
/// + held_at_end`; `balanced` also asks that every feedback sample the robot
/// said it sent entered.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FeedbackReport {
    pub scenario: String,
    pub seed: u64,
    pub queue_order: String,
    pub queue_capacity: usize,
    /// Feedback samples the robot said it sent (from its end marker).
    pub sent_by_robot: Option<u64>,
    pub entered: u64,
    /// Released towards the console (including those whose send failed);
    /// copies included.
    pub delivered: u64,
    /// Copies made by `duplicate` stages of the return scenario.
    #[serde(default)]
    pub duplicated: u64,
    /// Of those, released while no console was subscribed.
    pub delivered_unsubscribed: u64,
    pub dropped: BTreeMap<String, u64>,
    pub held_at_end: u64,
    pub balanced: bool,
    pub loss_rate: f64,
    pub loss_rate_ci95: [f64; 2],
    pub injected_delay_ns: Summary,
    pub decision_ns: Summary,
    pub release_lateness_ns: Summary,
    pub send_errors: u64,
    pub receive_errors: u64,
    pub trace_path: PathBuf,
}

/// The feedback path of a run through `scenario` (seeded `seed`) between
/// the two ports; `expected` sizes its trace and batches.
pub fn path(
    scenario: Scenario,
    seed: u64,
    queue_capacity: usize,
    expected: u64,
    source: FeedbackIngress,
    sink: FeedbackEgress,
) -> anyhow::Result<FeedbackPath> {
    let link = Link::new(scenario, queue_capacity, expected)?;
    Ok(FeedbackPath::new(link, seed, source, sink))
}
