//! Where the console's frames come from: synthetic motion at a fixed rate,
//! or a capture replayed with its timing or at a fixed rate.

use crate::capture;
use crate::service::error::ScriptError;
use crate::motion::{MotionGenerator, MotionParams};
use crate::sample::ITP_FRAME_LEN;
use crate::service::args::ConsoleArgs;


/// Where frames come from: each call gives the frame's planned offset from
/// the stream's start and its wire bytes.
pub(super) enum Script {
    Synthetic { motion: Box<MotionGenerator>, period_ns: f64 },
    Replay { records: Vec<(u64, [u8; ITP_FRAME_LEN])>, period_ns: Option<f64> },
}

impl Script {
    pub(super) fn len(&self, frames: Option<u64>, duration_s: Option<f64>) -> u64 {
        match self {
            Script::Synthetic { period_ns, .. } => frames.unwrap_or_else(|| (duration_s.unwrap_or(10.0) * 1e9 / period_ns).round() as u64),
            Script::Replay { records, period_ns } => {
                let all = records.len() as u64;
                let by_time = duration_s.map(|d| match period_ns {
                    Some(p) => (d * 1e9 / p).round() as u64,
                    None => records.iter().take_while(|r| r.0 as f64 <= d * 1e9).count() as u64,
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
                    Some(p) => ((i as f64 * *p).round() as u64, r.1),
                    None => (r.0, r.1),
                }
            }
        }
    }
}

impl Script {
    /// The capture given, or synthetic motion at the given rate.
    pub(super) fn from_args(args: &ConsoleArgs, seed: u64) -> Result<Script, ScriptError> {
        Ok(match &args.source.capture {
            Some(path) => {
                let cap = capture::load(path)?;
                let t0 = cap.records.first().map_or(0, |r| r.time_ns);
                let mut last = 0;
                let records = cap
                    .records
                    .iter()
                    .map(|r| {
                        // Wall-clock captures can step backwards; a schedule cannot.
                        last = r.time_ns.saturating_sub(t0).max(last);
                        (last, r.payload)
                    })
                    .collect();
                Script::Replay { records, period_ns: args.source.rate_hz.map(|r| 1e9 / r) }
            }
            None => {
                // `--rate-hz` is checked where it is parsed (`args::parse_rate_hz`).
                let rate = args.source.rate_hz.unwrap_or(crate::service::args::values::DEFAULT_RATE_HZ);
                let motion = MotionGenerator::new(MotionParams::peg_transfer(rate), seed)?;
                Script::Synthetic { motion: Box::new(motion), period_ns: 1e9 / rate }
            }
        })
    }
}
