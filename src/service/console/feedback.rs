//! The console's end of the feedback loop: the robot's feedback as it came
//! back through the emulator, the round trip, and the console's own pose
//! per recent command to compare it with.

use super::ConsoleFeedback;
use crate::service::schema::Ended;
use crate::clock::now_ns;
use crate::frame::{ItpFrame, ItpView};
use crate::kinematics::{Integrator, KinematicsConfig, KinematicsConfigError};
use crate::metrics::LatencyHistogram;
use crate::sample::{FeedbackSample, ITP_FRAME_LEN};
use crate::transport::FrameSubscriber;

/// Commands whose console-side pose is kept, to compare with the robot's
/// feedback for them: 65,536 (65 s at 1 kHz).
const POSE_RING: usize = 1 << 16;

/// The console's end of the feedback loop: the port, the round trip, and
/// the console's own pose per recent command.
pub(super) struct FeedbackIn {
    pub(super) port: FrameSubscriber<FeedbackSample>,
    sample: FeedbackSample,
    rtt: LatencyHistogram,
    share: LatencyHistogram,
    pub(super) received: u64,
    pub(super) sent_by_emulator: Option<u64>,
    unknown_command: u64,
    own: Integrator,
    poses: Vec<[[i64; 3]; 2]>,
    unit_mm: f64,
    div_final: [f64; 2],
    div_max: [f64; 2],
}

impl FeedbackIn {
    pub(super) fn new(port: FrameSubscriber<FeedbackSample>) -> Result<FeedbackIn, KinematicsConfigError> {
        let cfg = KinematicsConfig::default();
        Ok(FeedbackIn {
            port,
            sample: FeedbackSample::ZERO,
            rtt: LatencyHistogram::new(),
            share: LatencyHistogram::new(),
            received: 0,
            sent_by_emulator: None,
            unknown_command: 0,
            own: Integrator::new(cfg)?,
            poses: vec![[[0; 3]; 2]; POSE_RING],
            unit_mm: cfg.unit_mm,
            div_final: [0.0; 2],
            div_max: [0.0; 2],
        })
    }

    /// The console sent command `index` (`wire`) at `t`: its own pose after it.
    pub(super) fn sent(&mut self, index: u64, t: u64, wire: &[u8; ITP_FRAME_LEN]) {
        self.own.push(t, &ItpFrame::parse_unverified(&ItpView::new_unchecked(&wire[..])));
        self.poses[index as usize % POSE_RING] = [0, 1].map(|arm| self.own.pose(arm).position);
    }

    /// Takes every waiting feedback sample; `sent` commands have gone out.
    pub(super) fn poll(&mut self, sent: u64) {
        loop {
            let got = match self.port.try_recv() {
                Ok(Some(s)) => s,
                _ => return,
            };
            let t = now_ns();
            self.sample = got;
            let f = &self.sample;
            if f.is_end() {
                self.sent_by_emulator = Some(f.robot_index);
                continue;
            }
            self.received += 1;
            if f.console_index >= sent {
                self.unknown_command += 1;
                continue;
            }
            self.rtt.record(t.saturating_sub(f.command_send_ns));
            let fwd = f.command_release_ns as i64 - f.command_ingress_ns as i64 - f.command_injected_delay_ns as i64;
            let back = f.release_ns as i64 - f.ingress_ns as i64 - f.injected_delay_ns as i64;
            if f.command_release_ns != 0 && f.release_ns != 0 {
                self.share.record_signed(fwd + back);
            }
            if f.console_index + (POSE_RING as u64) >= sent {
                let own = &self.poses[f.console_index as usize % POSE_RING];
                for arm in 0..2 {
                    let d: f64 = (0..3).map(|k| ((f.position[arm][k] - own[arm][k]) as f64).powi(2)).sum::<f64>().sqrt() * self.unit_mm;
                    self.div_final[arm] = d;
                    self.div_max[arm] = self.div_max[arm].max(d);
                }
            }
        }
    }

    pub(super) fn live_line(&self) -> String {
        let r = self.rtt.summary();
        format!(
            "console: feedback {} received; round trip p50 {} p99 {}; divergence arm 0 {:.2} mm, arm 1 {:.2} mm",
            self.received,
            crate::metrics::fmt_ns(r.p50),
            crate::metrics::fmt_ns(r.p99),
            self.div_final[0],
            self.div_final[1]
        )
    }

    pub(super) fn report(&self, ended_by: Ended, out: &std::path::Path, duration_s: f64) -> ConsoleFeedback {
        let hlog = out.join("round_trip.hlog");
        let (round_trip_hlog, round_trip_hlog_error) = match self.rtt.write_log(&hlog, "round_trip", 0.0, duration_s) {
            Ok(()) => (Some(hlog), None),
            Err(e) => {
                // Not `eprintln!`: on a full disk the log cannot take it either.
                let _ = std::io::Write::write_fmt(&mut std::io::stderr(), format_args!("console: {} not written: {e}\n", hlog.display()));
                (None, Some(e.to_string()))
            }
        };
        ConsoleFeedback {
            received: self.received,
            sent_by_emulator: self.sent_by_emulator,
            unknown_command: self.unknown_command,
            ended_by,
            round_trip_ns: self.rtt.summary(),
            emulator_share_ns: self.share.summary(),
            divergence_final_mm: self.div_final,
            divergence_max_mm: self.div_max,
            round_trip_hlog,
            round_trip_hlog_error,
        }
    }
}
