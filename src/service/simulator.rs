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
use crate::metrics::{LatencyHistogram, Summary};
use crate::sample::{FeedbackSample, FrameSample, ITP_FRAME_LEN};
use crate::service::args::SimulatorArgs;
use crate::transport::open_node;
use crate::transport::FrameSource;
use crate::service::signals;
use crate::transport::{Channel, Role};
use anyhow::{Context, Result};
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
    pub ended_by: String,
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

/// `received.csv`, written as frames arrive: the ingress index and receive
/// time of each frame that came through the emulator. Memory stays flat
/// however long the run; the first failed write is kept and reported, with
/// the file's name, when the run ends (a full disk is an error, not a cut
/// file).
struct ReceivedLog {
    path: std::path::PathBuf,
    w: std::io::BufWriter<std::fs::File>,
    error: Option<std::io::Error>,
}

impl ReceivedLog {
    fn create(path: std::path::PathBuf) -> Result<ReceivedLog> {
        let open = || -> std::io::Result<std::io::BufWriter<std::fs::File>> {
            let mut w = std::io::BufWriter::with_capacity(1 << 16, std::fs::File::create(&path)?);
            writeln!(w, "ingress_index,recv_ns")?;
            Ok(w)
        };
        let w = open().with_context(|| format!("writing {}", path.display()))?;
        Ok(ReceivedLog { path, w, error: None })
    }

    fn push(&mut self, ingress_index: u64, recv_ns: u64) {
        if self.error.is_none() {
            if let Err(e) = writeln!(self.w, "{ingress_index},{recv_ns}") {
                self.error = Some(e);
            }
        }
    }

    fn finish(mut self) -> Result<()> {
        let result = match self.error.take() {
            Some(e) => Err(e),
            None => self.w.flush(),
        };
        result.with_context(|| format!("writing {}", self.path.display()))
    }
}

/// Runs the simulator; returns its report (also `simulator.json`).
pub fn main(args: &SimulatorArgs) -> Result<SimulatorReport> {
    crate::service::write_pid(&args.out, "simulator")?;
    let node = open_node(&args.run_id, Role::Simulator)?;
    let mut port = node.subscriber(Channel::Emulator).context("opening the emulator → simulator port")?;
    let mut direct = node.subscriber(Channel::Direct).context("opening the console → simulator port")?;
    let mut feedback_port = node.publisher_of::<FeedbackSample>(Channel::Feedback).context("opening the robot → emulator feedback port")?;
    let (mut feedback_sent, mut feedback_errors) = (0u64, 0u64);
    signals::install();
    crate::service::place("simulator", args.core, args.avoid_core)?;
    let wait = if args.spin { Wait::Spin } else { Wait::SpinYield };
    let stall_ns = (args.stall_ms * 1e6) as u64;
    let checksum_policy = if args.drop_bad_checksum { ChecksumPolicy::Discard } else { ChecksumPolicy::Apply };
    let mut kin = Kinematics::new(KinematicsConfig { stall_threshold_ns: stall_ns, checksum_policy, ..Default::default() })
        .context("--stall-ms")?;
    let mut e2e = LatencyHistogram::new();
    let mut hop = LatencyHistogram::new();
    let mut seen = LatencyHistogram::new();
    let received_csv = args.out.join("received.csv");
    let mut received_log = ReceivedLog::create(received_csv.clone())?;
    let (mut received, mut received_direct, mut wrong_size, mut bad_checksum, mut receive_errors) = (0u64, 0u64, 0u64, 0u64, 0u64);
    let mut released_by_emulator = None;
    let mut direct_ended = false;
    let steal_timer = StealTimer::start();
    std::fs::write(args.out.join("simulator.ready"), b"").context("writing simulator.ready")?;
    let t_start = now_ns();
    let mut s = FrameSample::ZERO;
    let mut d = FrameSample::ZERO;
    let mut iter = 0u64;
    let mut stop_at: Option<u64> = None;
    let mut stop = signals::StopCheck::new(64, || node.termination_requested());
    let mut last_frame_ns = now_ns();
    let ended_by = loop {
        let mut idle = true;
        match FrameSource::try_recv(&mut port, &mut s) {
            Ok(true) => {
                let t = now_ns();
                idle = false;
                last_frame_ns = t;
                if s.is_end() {
                    released_by_emulator = Some(s.console_index);
                } else {
                    received += 1;
                    received_log.push(s.ingress_index, t);
                    e2e.record_signed(t as i64 - s.send_ns as i64 - s.injected_delay_ns as i64);
                    seen.record(t.saturating_sub(s.send_ns));
                    let sequence = match robot_frame(&s) {
                        Err(()) => {
                            wrong_size += 1;
                            0
                        }
                        Ok((frame, checksum_ok)) => {
                            bad_checksum += u64::from(!checksum_ok);
                            kin.robot(t, &frame);
                            frame.sequence
                        }
                    };
                    // Feedback for every command received, applied or not.
                    let fb = feedback(&kin, &s, sequence, feedback_sent, received);
                    match feedback_port.send_from(&fb, |f| f.send_ns = now_ns()) {
                        Ok(n) if n > 0 => {}
                        _ => feedback_errors += 1,
                    }
                    feedback_sent += 1;
                }
            }
            Ok(false) => {}
            Err(_) => receive_errors += 1,
        }
        match FrameSource::try_recv(&mut direct, &mut d) {
            Ok(true) => {
                let t = now_ns();
                idle = false;
                if d.is_end() {
                    direct_ended = true;
                } else {
                    received_direct += 1;
                    hop.record(t.saturating_sub(d.send_ns));
                    if d.len as usize == ITP_FRAME_LEN {
                        kin.console(t, &ItpFrame::parse_unverified(&ItpView::new_unchecked(&d.wire[..])));
                    }
                }
            }
            Ok(false) => {}
            Err(_) => receive_errors += 1,
        }
        if idle {
            wait.relax();
        }
        iter = iter.wrapping_add(1);
        if iter % 1024 == 0 {
            if released_by_emulator.is_some() && (direct_ended || direct.peers_connected() == 0) {
                break "end_marker";
            }
            if stop_at.is_none() && stop.requested() {
                stop_at = Some(now_ns());
            }
            if let Some(_t) = stop_at {
                if released_by_emulator.is_some() || now_ns().saturating_sub(last_frame_ns) > 200_000_000 {
                    break "signal";
                }
            }
        }
    };
    let t_end = now_ns();
    // The feedback ends after the commands (best effort: the emulator may be gone).
    let _ = feedback_port.send(&FeedbackSample::end_marker(feedback_sent));
    received_log.finish()?;
    let duration_s = (t_end - t_start) as f64 / 1e9;
    let e2e_hlog = args.out.join("end_to_end.hlog");
    e2e.write_log(&e2e_hlog, "end_to_end_extra", 0.0, duration_s).with_context(|| format!("writing {}", e2e_hlog.display()))?;
    let hop_hlog = args.out.join("direct_hop.hlog");
    hop.write_log(&hop_hlog, "direct_hop", 0.0, duration_s).with_context(|| format!("writing {}", hop_hlog.display()))?;
    let steal = steal_timer.stop();
    kin.close(t_end);
    let kinematics = serde_json::to_value(kin.report()).ok();
    let report = SimulatorReport {
        received,
        received_direct,
        wrong_size,
        bad_checksum,
        released_by_emulator,
        end_to_end_extra_ns: e2e.summary(),
        direct_hop_ns: hop.summary(),
        delay_seen_ns: seen.summary(),
        kinematics,
        ended_by: ended_by.into(),
        duration_s,
        receive_errors,
        steal_ms: steal.ms,
        steal_fraction: steal.fraction,
        received_csv: Some(received_csv),
        end_to_end_hlog: Some(e2e_hlog),
        feedback_sent,
        feedback_errors,
    };
    let path = args.out.join("simulator.json");
    std::fs::write(&path, serde_json::to_vec_pretty(&report)?).with_context(|| format!("writing {}", path.display()))?;
    Ok(report)
}
