//! Where the console's frames come from: synthetic motion at a fixed rate,
//! or a capture replayed with its timing or at a fixed rate.

use crate::capture::{self, CaptureLimits, CaptureNote, CaptureRecord};
use crate::service::error::ScriptError;
use crate::motion::{MotionGenerator, MotionParams};
use crate::sample::ITP_FRAME_LEN;
use crate::service::args::ConsoleArgs;


/// Where frames come from: each call gives the frame's planned offset from
/// the stream's start and its wire bytes.
pub(super) enum Script {
    Synthetic { motion: Box<MotionGenerator>, period_ns: f64 },
    /// The capture's records, their times made offsets from the first
    /// that never step back (one copy of the capture, not two).
    Replay { records: Vec<CaptureRecord>, period_ns: Option<f64> },
}

impl Script {
    pub(super) fn len(&self, frames: Option<u64>, duration_s: Option<f64>) -> u64 {
        match self {
            Script::Synthetic { period_ns, .. } => frames.unwrap_or_else(|| (duration_s.unwrap_or(10.0) * 1e9 / period_ns).round() as u64),
            Script::Replay { records, period_ns } => {
                let all = records.len() as u64;
                let by_time = duration_s.map(|d| match period_ns {
                    Some(p) => (d * 1e9 / p).round() as u64,
                    None => records.iter().take_while(|r| r.time_ns as f64 <= d * 1e9).count() as u64,
                });
                frames.or(by_time).unwrap_or(all).min(all)
            }
        }
    }

    #[inline]
    pub(super) fn frame(&mut self, i: u64) -> (u64, [u8; ITP_FRAME_LEN]) {
        match self {
            Script::Synthetic { motion, period_ns } => ((i as f64 * *period_ns).round() as u64, motion.next_frame().to_bytes()),
            Script::Replay { records, period_ns } => {
                let r = &records[i as usize];
                match period_ns {
                    Some(p) => ((i as f64 * *p).round() as u64, r.payload),
                    None => (r.time_ns, r.payload),
                }
            }
        }
    }
}

impl Script {
    /// The capture given (read up to `--capture-max-records`; what is
    /// worth saying about it said on stderr, and its note), or synthetic
    /// motion at the given rate.
    pub(super) fn from_args(args: &ConsoleArgs, seed: u64) -> Result<(Script, Option<CaptureNote>), ScriptError> {
        Ok(match &args.source.capture {
            Some(path) => {
                let limits = args.source.capture_max_records.map_or_else(CaptureLimits::default, CaptureLimits::records);
                let mut cap = capture::load_with(path, limits)?;
                let note = cap.note();
                for w in note.unverified_warning().into_iter().chain(cap.stats.warnings()) {
                    eprintln!("console: WARNING: {w}");
                }
                let t0 = cap.records.first().map_or(0, |r| r.time_ns);
                let mut last = 0;
                for r in &mut cap.records {
                    // Wall-clock captures can step backwards; a schedule cannot.
                    last = r.time_ns.saturating_sub(t0).max(last);
                    r.time_ns = last;
                }
                (Script::Replay { records: cap.records, period_ns: args.source.rate_hz.map(|r| 1e9 / r) }, Some(note))
            }
            None => {
                // `--rate-hz` is checked where it is parsed (`args::parse_rate_hz`).
                let rate = args.source.rate_hz.unwrap_or(crate::service::args::values::DEFAULT_RATE_HZ);
                let motion = MotionGenerator::new(MotionParams::peg_transfer(rate), seed)?;
                (Script::Synthetic { motion: Box::new(motion), period_ns: 1e9 / rate }, None)
            }
        })
    }
}
