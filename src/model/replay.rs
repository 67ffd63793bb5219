//! `replay` (docs/spec.md §3.14): the fates recorded in an earlier run,
//! applied frame by frame, so a new trial runs under exactly the network an
//! earlier one had.
//!
//! Law. The `k`-th frame that reaches the stage (from 0) gets recorded fate
//! `k mod N` of the `N` in the recording: dropped (reason `replay`), or
//! passed with the recorded delay. When the recording ends it starts again
//! from its first fate. No randomness is drawn; the frame's time is not
//! looked at.
//!
//! Recordings ([`Recording`]):
//! - netfi's own `trace.csv` (docs/spec.md §6), parsed here from its text
//!   ([`Recording::parse_trace_csv`]): a `delivered` or `held` row is a pass
//!   with its `delay_ns`; a `dropped` row is a drop, but for the reasons
//!   that reject a malformed frame before any stage (`wrong_size`,
//!   `bad_checksum`, `bad_flags`), whose rows are skipped: such frames
//!   never reach a stage, in the recorded run or in this one. A frame the
//!   recorded run's queue refused (`queue_full`) replays as a drop.
//! - the study's delay-trial captures (`u64 time_ns | u16 len | f32 delay_s
//!   | payload` records): every record is a pass with its delay, rounded to
//!   the ns. Reading them is the shell's ([`crate::capture`]); the shell
//!   hands over the delays ([`Recording::from_delays_s`]).

use super::{Model, ParamError, StageRng, Verdict};
use serde::{Deserialize, Serialize};
use std::sync::Arc;

/// The recorded fate meaning "dropped".
const DROPPED: u64 = u64::MAX;
/// The longest recorded delay: one hour (the delay models' own bound).
pub const MAX_DELAY_NS: u64 = 3_600 * 1_000_000_000;
/// The most fates a recording may hold.
pub const MAX_FATES: usize = 1 << 28;

/// Where a recording came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RecordingKind {
    /// netfi's `trace.csv`.
    TraceCsv,
    /// A capture whose records carry the delay drawn for them.
    DelayCapture,
}

impl RecordingKind {
    pub fn name(self) -> &'static str {
        match self {
            RecordingKind::TraceCsv => "trace.csv",
            RecordingKind::DelayCapture => "delay capture",
        }
    }

    /// The layout the fates were read from, in words: a trace's columns, or
    /// a capture's records (the words of
    /// `crate::capture::RecordLayout::describe`, which the reader checks).
    pub fn layout(self) -> &'static str {
        match self {
            RecordingKind::TraceCsv => "columns fate, reason, delay_ns",
            RecordingKind::DelayCapture => "time | length | delay (s) | frame",
        }
    }
}

/// Recorded fates, in order: a delay in ns, or dropped.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Recording {
    kind: RecordingKind,
    fates: Vec<u64>,
}

/// What is wrong with a recording, and where (a 1-based line of a CSV, or
/// a 0-based record of a capture).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{}{problem}", at.as_ref().map(|a| format!("{a}: ")).unwrap_or_default())]
pub struct RecordingError {
    pub at: Option<String>,
    pub problem: String,
}

impl Recording {
    /// Parses netfi's `trace.csv`: a header naming at least the columns
    /// `fate`, `reason` and `delay_ns`, then one row per frame.
    pub fn parse_trace_csv(text: &str) -> Result<Recording, RecordingError> {
        let err = |line: usize, problem: String| RecordingError { at: Some(format!("line {line}")), problem };
        let mut lines = text.lines();
        let header = lines.next().ok_or_else(|| RecordingError { at: None, problem: "the file is empty".into() })?;
        let cols: Vec<&str> = header.split(',').map(str::trim).collect();
        let col = |name: &str| {
            cols.iter().position(|c| *c == name).ok_or_else(|| err(1, format!("no `{name}` column: expected the header of netfi's trace.csv")))
        };
        let (fate_col, reason_col, delay_col) = (col("fate")?, col("reason")?, col("delay_ns")?);
        let mut fates = Vec::new();
        for (i, row) in lines.enumerate() {
            let line = i + 2;
            if row.trim().is_empty() {
                continue;
            }
            let cells: Vec<&str> = row.split(',').collect();
            if cells.len() != cols.len() {
                return Err(err(line, format!("{} cells, the header has {}", cells.len(), cols.len())));
            }
            let fate = match (cells[fate_col].trim(), cells[reason_col].trim()) {
                ("dropped", "wrong_size" | "bad_checksum" | "bad_flags") => continue,
                ("dropped", _) => DROPPED,
                ("delivered" | "held", _) => {
                    let d = cells[delay_col].trim();
                    let delay: u64 = d.parse().map_err(|_| err(line, "`delay_ns` is not a whole number of ns".into()))?;
                    if delay > MAX_DELAY_NS {
                        return Err(err(line, format!("`delay_ns` is beyond one hour: expected at most {MAX_DELAY_NS} ns")));
                    }
                    delay
                }
                // The cell is not repeated: the file may not be a trace.
                _ => return Err(err(line, "`fate` is none of delivered, dropped or held".into())),
            };
            if fates.len() == MAX_FATES {
                return Err(err(line, format!("more than {MAX_FATES} frames")));
            }
            fates.push(fate);
        }
        if fates.is_empty() {
            return Err(RecordingError { at: None, problem: "no frame reached the scenario in this trace: nothing to replay".into() });
        }
        Ok(Recording { kind: RecordingKind::TraceCsv, fates })
    }

    /// The delays of a delay-trial capture, in seconds, record by record.
    pub fn from_delays_s(delays_s: &[f32]) -> Result<Recording, RecordingError> {
        let mut fates = Vec::with_capacity(delays_s.len());
        for (i, &d) in delays_s.iter().enumerate() {
            let ns = f64::from(d) * 1e9;
            if !ns.is_finite() || ns < 0.0 || ns > MAX_DELAY_NS as f64 {
                return Err(RecordingError { at: Some(format!("record {i}")), problem: format!("delay {d} s: expected 0 to 3600 s") });
            }
            fates.push(ns.round() as u64);
        }
        if fates.is_empty() {
            return Err(RecordingError { at: None, problem: "the capture has no record: nothing to replay".into() });
        }
        Ok(Recording { kind: RecordingKind::DelayCapture, fates })
    }

    pub fn kind(&self) -> RecordingKind {
        self.kind
    }

    pub fn len(&self) -> usize {
        self.fates.len()
    }

    pub fn is_empty(&self) -> bool {
        self.fates.is_empty()
    }

    /// Fate `k`: `None` if dropped, else the delay in ns.
    pub fn fate(&self, k: usize) -> Option<u64> {
        Some(self.fates[k]).filter(|&f| f != DROPPED)
    }

    /// The fraction of recorded frames dropped.
    pub fn loss_rate(&self) -> f64 {
        self.fates.iter().filter(|&&f| f == DROPPED).count() as f64 / self.fates.len() as f64
    }

    /// The mean recorded delay of the frames that passed, ms.
    pub fn mean_delay_ms(&self) -> f64 {
        let passed: Vec<u64> = self.fates.iter().copied().filter(|&f| f != DROPPED).collect();
        if passed.is_empty() {
            return 0.0;
        }
        passed.iter().map(|&d| d as f64).sum::<f64>() / passed.len() as f64 / 1e6
    }
}

#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ReplayParams {
    /// The recording (a `trace.csv`, or a delay-trial capture), relative to
    /// the scenario file.
    pub file: String,
    /// The most records read of a delay capture (`file`): 1 to
    /// [`MAX_FATES`]; default the capture reader's (4,194,304, as
    /// `--capture-max-records`). A capture with more is refused.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_records: Option<u64>,
    /// The parsed recording, filled in by whoever read `file`.
    #[serde(skip)]
    pub recording: Option<Arc<Recording>>,
}

impl ReplayParams {
    pub fn new(file: impl Into<String>, recording: Recording) -> ReplayParams {
        ReplayParams { file: file.into(), max_records: None, recording: Some(Arc::new(recording)) }
    }
}

/// A validated `replay` stage.
#[derive(Debug, Clone)]
pub struct Replay {
    /// The file, as the scenario names it.
    file: String,
    recording: Arc<Recording>,
    next: usize,
    /// Times the recording ran out and started again.
    wraps: u64,
}

impl Replay {
    pub fn new(p: &ReplayParams) -> Result<Replay, ParamError> {
        let Some(recording) = p.recording.clone() else {
            return Err(ParamError::new("file", format!("the recording `{}` was not read: load the scenario from its file", p.file)));
        };
        Ok(Replay { file: p.file.clone(), recording, next: 0, wraps: 0 })
    }

    pub fn recording(&self) -> &Recording {
        &self.recording
    }

    /// The recording's file, as the scenario names it.
    pub fn file(&self) -> &str {
        &self.file
    }

    /// Times the recording ran out and started again.
    pub fn wraps(&self) -> u64 {
        self.wraps
    }

    /// Whether any recorded delay differs from another's order: a later
    /// frame's release before an earlier one's is possible.
    pub fn may_reorder(&self) -> bool {
        // Frames may arrive at any spacing, so any delay that is not the
        // smallest can be overtaken; only a constant delay keeps the order.
        let mut passed = self.recording.fates.iter().filter(|&&f| f != DROPPED);
        let first = passed.next();
        passed.any(|f| Some(f) != first)
    }
}

impl Model for Replay {
    #[inline]
    fn decide(&mut self, _t_ns: u64, _rng: &mut StageRng) -> Verdict {
        // The recording starts again when a frame comes after its last fate
        // was used, not when that fate is used: a run of exactly `N` frames
        // used each fate once and started nothing again.
        if self.next == self.recording.fates.len() {
            self.next = 0;
            self.wraps += 1;
        }
        let fate = self.recording.fates[self.next];
        self.next += 1;
        if fate == DROPPED {
            Verdict::Drop
        } else {
            Verdict::Pass { delay_ns: fate }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const HEAD: &str = "ingress_index,sequence,console_index,send_ns,ingress_ns,fate,reason,phase,stage,delay_ns,release_sched_ns,release_ns,recv_ns\n";

    #[test]
    fn a_trace_csv_replays_its_fates_in_order_and_repeats() {
        let text = format!(
            "{HEAD}0,1,0,0,10,delivered,,,,5000,5010,5011,\n1,2,1,0,20,dropped,bernoulli,1,1,,,,\n2,,2,0,30,dropped,wrong_size,,,,,,\n3,4,3,0,40,held,,,,7,47,,\n"
        );
        let rec = Recording::parse_trace_csv(&text).unwrap();
        assert_eq!(rec.len(), 3);
        let mut m = Replay::new(&ReplayParams::new("t.csv", rec)).unwrap();
        let mut rng = <StageRng as rand::SeedableRng>::seed_from_u64(1);
        let got: Vec<Verdict> = (0..4).map(|i| m.decide(i, &mut rng)).collect();
        assert_eq!(got, [Verdict::Pass { delay_ns: 5000 }, Verdict::Drop, Verdict::Pass { delay_ns: 7 }, Verdict::Pass { delay_ns: 5000 }]);
        assert_eq!(m.wraps(), 1);
    }

    #[test]
    fn started_again_counts_the_frames_that_came_after_the_last_fate() {
        let rec = Recording::from_delays_s(&[0.001, 0.002, 0.003]).unwrap();
        let mut m = Replay::new(&ReplayParams::new("d.bin", rec)).unwrap();
        let mut rng = <StageRng as rand::SeedableRng>::seed_from_u64(1);
        let mut decided = 0;
        // (frames decided so far, times started again)
        for (frames, wraps) in [(1, 0), (2, 0), (3, 0), (4, 1), (6, 1), (7, 2), (9, 2), (10, 3)] {
            while decided < frames {
                m.decide(0, &mut rng);
                decided += 1;
            }
            assert_eq!(m.wraps(), wraps, "after {frames} frames of a 3-fate recording");
        }
    }

    #[test]
    fn bad_recordings_say_where() {
        let e = Recording::parse_trace_csv("").unwrap_err();
        assert!(e.problem.contains("empty"), "{e}");
        let e = Recording::parse_trace_csv("a,b\n1,2\n").unwrap_err();
        assert!(e.to_string().starts_with("line 1: no `fate` column"), "{e}");
        let e = Recording::parse_trace_csv(&format!("{HEAD}0,1,0,0,10,delivered,,,,x,5010,5011,\n")).unwrap_err();
        assert_eq!(e.at.as_deref(), Some("line 2"), "{e}");
        let e = Recording::parse_trace_csv(&format!("{HEAD}0,1,0,0,10,lost,,,,1,5010,5011,\n")).unwrap_err();
        assert!(e.problem.contains("`fate` is none of delivered, dropped or held") && !e.problem.contains("lost"), "{e}");
        let e = Recording::from_delays_s(&[0.1, -0.5]).unwrap_err();
        assert_eq!(e.at.as_deref(), Some("record 1"));
        assert_eq!(Recording::from_delays_s(&[0.25]).unwrap().fate(0), Some(250_000_000));
    }
}
