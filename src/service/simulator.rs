//! The simulator service: receives the frames the emulator releases, applies
//! ITP semantics (clutch, incremental motion, absolute grasp) to a robot-side
//! pose, and measures what arrives: end-to-end latency beyond the injected
//! delay (HDR), the bare hop of the console's direct copies, and the
//! kinematics of docs/spec.md §6 — console vs robot motion, divergence, clutch
//! activations, stalls.
//!
//! It shares a core with the console on small machines, so it polls and
//! yields the core on each idle turn (`--spin` polls without yielding, for a
//! core of its own). On SIGINT/SIGTERM it keeps draining until the
//! emulator's end marker or 200 ms of silence.

use crate::clock::{now_ns, Wait};
use crate::frame::ItpView;
use crate::host::StealTimer;
use crate::frame::ItpFrame;
use crate::kinematics::{ChecksumPolicy, Kinematics, KinematicsConfig};
use crate::metrics::{IntervalLog, LatencyHistogram, Summary};
use crate::sample::{FeedbackSample, FrameSample, ITP_FRAME_LEN};
use crate::service::args::SimulatorArgs;
use crate::transport::open_node;
use crate::transport::FrameSource;
use crate::service::signals;
use crate::transport::{Port, Role};
use crate::service::error::{RobotError, ServiceError};
use crate::service::schema::Ended;
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::PathBuf;


/// The simulator's report, written as `simulator.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SimulatorReport {
    /// Frames received from the emulator.
    pub received: u64,
    /// Frames received on the direct (baseline) port.
    pub received_direct: u64,
    pub wrong_size: u64,
    /// Frames whose ITP checksum did not hold: what the check catches (of
    /// the emulator's corruption, docs/spec.md §3.9, a flip in a byte the
    /// checksum covers; a flip in `grasp` or the rotations passes).
    pub bad_checksum: u64,
    /// Frames the emulator said it released (from its end marker).
    pub released_by_emulator: Option<u64>,
    /// Receive − console send − injected delay.
    pub end_to_end_extra_ns: Summary,
    /// Receive − send of the direct copies.
    pub direct_hop_ns: Summary,
    /// Receive − console send (what the robot experiences).
    pub delay_seen_ns: Summary,
    /// Robot (emulated stream) vs console (direct stream) kinematics.
    pub kinematics: Option<serde_json::Value>,
    /// `end_marker` or `signal`.
    pub ended_by: Ended,
    pub duration_s: f64,
    pub receive_errors: u64,
    pub steal_ms: u64,
    pub steal_fraction: f64,
    pub received_csv: Option<PathBuf>,
    pub end_to_end_hlog: Option<PathBuf>,
    /// Feedback samples published to the emulator (one per frame received).
    #[serde(default)]
    pub feedback_sent: u64,
    /// Feedback samples the transport refused or that reached no emulator.
    #[serde(default)]
    pub feedback_errors: u64,
    /// The camera, when the run has video.
    #[serde(default)]
    pub camera: Option<crate::service::channel::video::CameraReport>,
}

/// The robot's feedback after the command `s` (frame `f`): the command it
/// answers and the pose the robot side holds now.
#[inline]
fn feedback(kin: &Kinematics, s: &FrameSample, sequence: u32, index: u64, commands: u64) -> FeedbackSample {
    let robot = kin.robot_side();
    let mut fb = FeedbackSample {
        robot_index: index,
        console_index: s.console_index,
        command_send_ns: s.send_ns,
        command_ingress_ns: s.ingress_ns,
        command_release_ns: s.release_ns,
        command_injected_delay_ns: s.injected_delay_ns,
        sequence,
        commands,
        ..FeedbackSample::ZERO
    };
    for arm in 0..2 {
        let p = robot.pose(arm);
        fb.position[arm] = p.position;
        fb.rotation[arm] = p.rotation;
        fb.grasp[arm] = p.grasp;
    }
    fb
}

/// The ITP frame a sample from the emulator carries, and whether its
/// checksum holds; `Err` if its length is not an ITP frame's.
#[inline]
fn robot_frame(s: &FrameSample) -> Result<(ItpFrame, bool), ()> {
    if s.len as usize != ITP_FRAME_LEN {
        return Err(());
    }
    let view = ItpView::new_unchecked(&s.wire[..]);
    Ok((ItpFrame::parse_unverified(&view), view.verify_checksum()))
}

/// What the robot side has seen and done so far: its kinematics, its
/// latency histograms, `received.csv` and its counts.
struct Robot {
    kin: Kinematics,
    /// `end_to_end.hlog` and `direct_hop.hlog`, streamed one interval
    /// per second.
    e2e: IntervalLog,
    hop: IntervalLog,
    seen: LatencyHistogram,
    received_csv: PathBuf,
    /// `received.csv`, written as frames arrive: the ingress index, receive
    /// time and scheduled release time of each frame that came through the
    /// emulator (a copy, docs/spec.md §3.8, has its original's ingress
    /// index; its scheduled release tells the two apart), flushed at least
    /// once a second ([`crate::trace::CsvLog`]).
    received_log: crate::trace::CsvLog,
    received: u64,
    received_direct: u64,
    wrong_size: u64,
    bad_checksum: u64,
    receive_errors: u64,
    released_by_emulator: Option<u64>,
    direct_ended: bool,
    feedback_sent: u64,
    feedback_errors: u64,
    last_frame_ns: u64,
}

impl Robot {
    fn new(args: &SimulatorArgs) -> Result<Robot, RobotError> {
        let stall_ns = (args.stall_ms * 1e6) as u64;
        let checksum_policy = if args.drop_bad_checksum { ChecksumPolicy::Discard } else { ChecksumPolicy::Apply };
        let kin = Kinematics::new(KinematicsConfig { stall_threshold_ns: stall_ns, checksum_policy, ..Default::default() })
            .map_err(RobotError::StallMs)?;
        let received_csv = args.out.join("received.csv");
        let received_log = crate::trace::CsvLog::create(received_csv.clone(), "ingress_index,recv_ns,release_sched_ns")?;
        let origin_ns = now_ns();
        let hlog = |file: &str, tag: &str| IntervalLog::create(&args.out.join(file), tag, origin_ns);
        Ok(Robot {
            kin,
            e2e: hlog("end_to_end.hlog", "end_to_end_extra")?,
            hop: hlog("direct_hop.hlog", "direct_hop")?,
            seen: LatencyHistogram::new(),
            received_csv,
            received_log,
            received: 0,
            received_direct: 0,
            wrong_size: 0,
            bad_checksum: 0,
            receive_errors: 0,
            released_by_emulator: None,
            direct_ended: false,
            feedback_sent: 0,
            feedback_errors: 0,
            last_frame_ns: now_ns(),
        })
    }

    /// A command from the emulator, received at `t`: applied, measured, and
    /// answered with feedback through `send` (which says whether a
    /// subscriber took it).
    fn command(&mut self, s: &FrameSample, t: u64, send: impl FnOnce(&FeedbackSample) -> bool) {
        self.last_frame_ns = t;
        if s.is_end() {
            self.released_by_emulator = Some(s.console_index);
            return;
        }
        self.received += 1;
        let (i, r) = (s.ingress_index, s.release_sched_ns);
        self.received_log.push(|w| writeln!(w, "{i},{t},{r}"));
        self.e2e.record_signed(t as i64 - s.send_ns as i64 - s.injected_delay_ns as i64);
        self.seen.record(t.saturating_sub(s.send_ns));
        let sequence = match robot_frame(s) {
            Err(()) => {
                self.wrong_size += 1;
                0
            }
            Ok((frame, checksum_ok)) => {
                self.bad_checksum += u64::from(!checksum_ok);
                self.kin.robot(t, &frame);
                frame.sequence
            }
        };
        // Feedback for every command received, applied or not.
        let fb = feedback(&self.kin, s, sequence, self.feedback_sent, self.received);
        if !send(&fb) {
            self.feedback_errors += 1;
        }
        self.feedback_sent += 1;
    }

    /// The console's own copy of a command, received straight at `t`.
    fn direct(&mut self, d: &FrameSample, t: u64) {
        if d.is_end() {
            self.direct_ended = true;
            return;
        }
        self.received_direct += 1;
        self.hop.record(t.saturating_sub(d.send_ns));
        if d.len as usize == ITP_FRAME_LEN {
            self.kin.console(t, &ItpFrame::parse_unverified(&ItpView::new_unchecked(&d.wire[..])));
        }
    }

    /// Ends the histogram logs' current intervals once they have lasted a
    /// second (called every few hundred turns of the loop, not per frame).
    fn tick(&mut self, now: u64) {
        self.e2e.tick(now);
        self.hop.tick(now);
        self.received_log.tick(now);
    }

    /// Writes `received.csv`'s end and the histogram logs' last
    /// intervals, and reports.
    fn finish(mut self, args: &SimulatorArgs, ended_by: Ended, t_start: u64, t_end: u64, steal: crate::host::Steal) -> Result<SimulatorReport, RobotError> {
        self.received_log.finish()?;
        let duration_s = (t_end - t_start) as f64 / 1e9;
        let e2e_hlog = args.out.join("end_to_end.hlog");
        // The whole run's figures: the sum of the intervals written.
        let e2e = self.e2e.finish(t_end)?;
        let hop = self.hop.finish(t_end)?;
        self.kin.close(t_end);
        Ok(SimulatorReport {
            received: self.received,
            received_direct: self.received_direct,
            wrong_size: self.wrong_size,
            bad_checksum: self.bad_checksum,
            released_by_emulator: self.released_by_emulator,
            end_to_end_extra_ns: e2e.summary(),
            direct_hop_ns: hop.summary(),
            delay_seen_ns: self.seen.summary(),
            kinematics: serde_json::to_value(self.kin.report()).ok(),
            ended_by,
            duration_s,
            receive_errors: self.receive_errors,
            steal_ms: steal.ms,
            steal_fraction: steal.fraction,
            received_csv: Some(self.received_csv),
            end_to_end_hlog: Some(e2e_hlog),
            feedback_sent: self.feedback_sent,
            feedback_errors: self.feedback_errors,
            camera: None,
        })
    }
}

/// Runs the simulator; returns its report (also `simulator.json`).
pub fn main(args: &SimulatorArgs) -> Result<SimulatorReport, ServiceError> {
    crate::service::write_pid(&args.out, "simulator")?;
    let node = open_node(&args.run_id, Role::Simulator)?;
    let mut port = node.subscriber(Port::EMULATOR).map_err(|e| ServiceError::Subscriber("emulator → simulator", e))?;
    let mut direct = node.subscriber(Port::DIRECT).map_err(|e| ServiceError::Subscriber("console → simulator", e))?;
    let mut feedback_port = node.publisher_of::<FeedbackSample>(crate::service::channel::feedback::FEEDBACK).map_err(|e| ServiceError::Publisher("robot → emulator feedback", e))?;
    signals::install();
    crate::host::placement::place("simulator", args.pin.core, args.pin.avoid_core)?;
    // Started after the placement, whose CPU mask its thread inherits: off the emulator's core.
    let camera = crate::service::channel::video::camera(&args.run_id, &args.channels.video)?;
    let wait = match (args.spin, args.nap_us) {
        (true, _) => Wait::Spin,
        (false, Some(us)) => Wait::Nap(us * 1000),
        (false, None) => Wait::SpinYield,
    };
    let mut robot = Robot::new(args)?;
    let steal_timer = StealTimer::start();
    crate::durable::write_whole(&args.out.join("simulator.ready"), b"").map_err(|e| ServiceError::Ready("simulator.ready", std::io::Error::other(e)))?;
    let t_start = now_ns();
    let mut s = FrameSample::ZERO;
    let mut d = FrameSample::ZERO;
    let mut iter = 0u64;
    let mut stop_at: Option<u64> = None;
    let mut stop = signals::StopCheck::new(64, || node.termination_requested());
    let ended_by = loop {
        let mut idle = true;
        match FrameSource::try_recv(&mut port, &mut s) {
            Ok(true) => {
                idle = false;
                let now = now_ns();
                robot.command(&s, now, |fb| matches!(feedback_port.send_from(fb, |f| f.send_ns = now_ns()), Ok(n) if n > 0));
                // The logs' seconds are cut as frames come (a comparison),
                // not only every 1024 turns: a loaded host makes turns slow.
                robot.tick(now);
            }
            Ok(false) => {}
            Err(_) => robot.receive_errors += 1,
        }
        match FrameSource::try_recv(&mut direct, &mut d) {
            Ok(true) => {
                idle = false;
                robot.direct(&d, now_ns());
            }
            Ok(false) => {}
            Err(_) => robot.receive_errors += 1,
        }
        if idle {
            wait.relax();
        }
        iter = iter.wrapping_add(1);
        if iter % 1024 == 0 {
            robot.tick(now_ns());
            if robot.released_by_emulator.is_some() && (robot.direct_ended || direct.peers_connected() == 0) {
                break Ended::EndMarker;
            }
            if stop_at.is_none() && stop.requested() {
                stop_at = Some(now_ns());
            }
            if stop_at.is_some() && (robot.released_by_emulator.is_some() || now_ns().saturating_sub(robot.last_frame_ns) > 200_000_000) {
                break Ended::Signal;
            }
        }
    };
    let t_end = now_ns();
    // The feedback ends after the commands (best effort: the emulator may be gone).
    let _ = feedback_port.send(&FeedbackSample::end_marker(robot.feedback_sent));
    let mut report = robot.finish(args, ended_by, t_start, t_end, steal_timer.stop())?;
    report.camera = camera.map(|c| c.finish()).transpose()?;
    crate::service::write_json(&args.out.join("simulator.json"), &report)?;
    Ok(report)
}
