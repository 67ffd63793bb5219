//! The emulator's reports, assembled from what its paths and its loop
//! return: each lane's `emulator.json` ([`EmulatorReport`]) and the joint
//! one of several lanes ([`EmulatorStreams`]). A transport writes its own
//! beside them (`crate::transport::TransportReports`).

use crate::host::isolate::IsolationSummary;
use crate::service::control::ControlEvent;
use crate::service::schema::ForwardExtra;
use crate::service::emulator::spin::LoopEnd;
use crate::service::schema::{EmulatorFrames, EmulatorProcess, EmulatorReport, EmulatorStream, EmulatorStreams, Ended, LoopBusy, PathReport, PeerEvent, Shaping, WithPaths};
use std::collections::BTreeMap;
use std::path::PathBuf;

pub use crate::service::{write_json, WriteError};

/// What the loop and the process add to every lane's report.
pub struct Run<'a> {
    pub end: &'a LoopEnd,
    pub core: Option<usize>,
    pub realtime_priority: Option<i32>,
    /// The process's other threads and where they ran.
    pub threads: Vec<crate::host::placement::ThreadPlace>,
    pub steal: crate::host::Steal,
}

/// What is a lane's own besides its paths: what the loop saw of it.
pub struct LaneEnd {
    pub busy: LoopBusy,
    pub peer_events: Vec<PeerEvent>,
    pub dead_peers: Vec<String>,
    pub robot_died: bool,
    /// Lane 0's: what clearing the core did, and the live control's events.
    pub isolation: Option<IsolationSummary>,
    pub events: Vec<ControlEvent>,
}

/// A lane's `emulator.json` of its forward path's report `fwd`, its
/// reverse paths' reports `paths`, what the loop saw of it, and the run.
pub fn lane_report(fwd: PathReport<ForwardExtra>, paths: BTreeMap<String, serde_json::Value>, lane: LaneEnd, run: &Run) -> EmulatorReport {
    let (duration_ns, rounds) = (run.end.duration_ns(), run.end.rounds);
    let (decision_hlog, lateness_hlog) = fwd.hlogs.clone().unzip();
    let shaping = Shaping {
        link: fwd.measures,
        peer_events: lane.peer_events,
        events: lane.events,
        trace_path: Some(fwd.trace_path),
        decision_hlog,
        lateness_hlog,
    };
    let process = EmulatorProcess {
        scenario: fwd.scenario,
        seed: fwd.seed,
        core: run.core,
        realtime_priority: run.realtime_priority,
        threads: run.threads.clone(),
        isolation: lane.isolation,
        queue_order: fwd.queue_order,
        queue_capacity: fwd.queue_capacity,
        frames: EmulatorFrames {
            account: fwd.account,
            sent_by_console: fwd.extra.sent_by_console,
            bad_checksum_passed: fwd.extra.bad_checksum_passed,
            bad_input: fwd.extra.bad_input,
            delivered_unsubscribed: fwd.delivered_unsubscribed,
        },
        ended_by: run.end.lane_ended_by(lane.robot_died),
        dead_peers: lane.dead_peers,
        duration_s: duration_ns as f64 / 1e9,
        loop_iterations: rounds,
        loop_iteration_ns_mean: if rounds > 0 { duration_ns as f64 / rounds as f64 } else { 0.0 },
        receive_errors: fwd.receive_errors,
        send_errors: fwd.send_errors,
        trace_overflowed: fwd.trace_overflowed,
        steal_ms: run.steal.ms,
        steal_fraction: run.steal.fraction,
        busy: Some(lane.busy),
        kinematics: fwd.extra.kinematics.and_then(|k| serde_json::to_value(k).ok()),
    };
    EmulatorReport { shaping, process: WithPaths { inner: process, paths } }
}

/// The joint report of the lanes' reports; their run ids and directories.
pub fn joint(reports: &[EmulatorReport], run_ids: &[String], dirs: &[PathBuf], ended_by: Ended) -> EmulatorStreams {
    let mut total = EmulatorFrames { sent_by_console: Some(0), ..EmulatorFrames::default() };
    let mut streams = Vec::new();
    for (k, r) in reports.iter().enumerate() {
        total.add(&r.process.frames);
        let l = &r.shaping.link;
        streams.push(EmulatorStream {
            stream: k,
            run_id: run_ids[k].clone(),
            scenario: r.process.scenario.clone(),
            seed: r.process.seed,
            dir: dirs[k].clone(),
            frames: r.process.frames.clone(),
            loss_rate: l.loss_rate,
            ingress_wait_ns: l.ingress_wait_ns,
            decision_ns: l.decision_ns,
            release_lateness_ns: l.release_lateness_ns,
        });
    }
    let p = &reports[0].process;
    EmulatorStreams {
        streams,
        total,
        balanced: reports.iter().all(|r| r.process.frames.account.closes()),
        core: p.core,
        ended_by,
        duration_s: p.duration_s,
        loop_rounds: p.loop_iterations,
        loop_round_ns_mean: p.loop_iteration_ns_mean,
        steal_fraction: p.steal_fraction,
        busy: LoopBusy::total(reports.iter().filter_map(|r| r.process.busy.as_ref())),
    }
}

/// One line for the log: what came in, what went out, and how the lane
/// ended (a transport's report adds its own after it).
pub fn summary_line(r: &EmulatorReport) -> String {
    let (f, p) = (&r.process.frames, &r.process);
    let a = &f.account;
    format!(
        "emulator: {} entered, {} delivered, {} dropped {:?}, {} held at end; ended by {}",
        a.entered,
        a.delivered,
        a.dropped_total(),
        a.dropped,
        a.held_at_end,
        p.ended_by
    )
}
