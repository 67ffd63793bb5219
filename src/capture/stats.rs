//! What a capture holds, counted record by record, and when it is refused.

use super::{CaptureRecord, RecordLayout, MAX_GAP_NS, MAX_STEP_BACKWARD_NS};
use crate::frame::SURGEON_ENGAGED;
use std::path::Path;

/// Summary of a capture, built record by record with [`CaptureStats::push`].
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize)]
pub struct CaptureStats {
    /// Records (frames).
    pub frames: u64,
    /// Time of the first record, ns.
    pub first_ns: u64,
    /// Time of the last record, ns.
    pub last_ns: u64,
    /// Longest interval between consecutive records, ns.
    pub gap_ns_max: u64,
    /// Records stamped earlier than the one before them (a wall clock may step
    /// back); such intervals count as zero in `gap_ns_max`.
    pub time_steps_backward: u64,
    /// Frames whose carried checksum disagrees with their fields.
    pub checksum_failures: u64,
    /// Frames whose `surgeon_mode` is not engaged (1): their increments do
    /// not apply.
    pub clutch_released_frames: u64,
    /// Records whose dropped flag is set.
    pub dropped_flagged: u64,
    /// Longest step backwards in time, ns.
    #[serde(default)]
    pub step_backward_ns_max: u64,
    /// Steps backwards longer than [`MAX_STEP_BACKWARD_NS`].
    #[serde(default)]
    pub steps_backward_over_limit: u64,
    /// Gaps forwards longer than [`MAX_GAP_NS`].
    #[serde(default)]
    pub gaps_over_limit: u64,
    /// Whether every LZ4 frame of the file carries a content checksum (set
    /// by [`load`] and [`parse`]; a loaded capture matched them).
    #[serde(default)]
    pub content_checksum: bool,
    /// The LZ4 frames the file holds (set by [`load`] and [`parse`]; a
    /// recorder that flushes every batch writes one per batch).
    #[serde(default)]
    pub lz4_frames: u64,
}

impl CaptureStats {
    /// Accounts for one more record.
    pub fn push(&mut self, record: &CaptureRecord) {
        if self.frames == 0 {
            self.first_ns = record.time_ns;
        } else if record.time_ns < self.last_ns {
            let back = self.last_ns - record.time_ns;
            self.time_steps_backward += 1;
            self.step_backward_ns_max = self.step_backward_ns_max.max(back);
            self.steps_backward_over_limit += u64::from(back > MAX_STEP_BACKWARD_NS);
        } else {
            let gap = record.time_ns - self.last_ns;
            self.gap_ns_max = self.gap_ns_max.max(gap);
            self.gaps_over_limit += u64::from(gap > MAX_GAP_NS);
        }
        self.last_ns = record.time_ns;
        self.frames += 1;
        let view = record.view();
        if !view.verify_checksum() {
            self.checksum_failures += 1;
        }
        if view.surgeon_mode() != SURGEON_ENGAGED {
            self.clutch_released_frames += 1;
        }
        if record.is_dropped() {
            self.dropped_flagged += 1;
        }
    }

    /// Statistics of a slice of records.
    pub fn from_records(records: &[CaptureRecord]) -> CaptureStats {
        let mut stats = CaptureStats::default();
        records.iter().for_each(|r| stats.push(r));
        stats
    }

    /// Why a capture with these counts is refused, by the rule in the
    /// module docs; `None` when it is accepted.
    pub fn refusal(&self) -> Option<String> {
        let mut why = Vec::new();
        if self.checksum_failures > 0 && !self.content_checksum {
            why.push(format!(
                "{} of {} frames have a wrong ITP checksum and the file has no LZ4 content checksum to show it is intact",
                self.checksum_failures, self.frames
            ));
        }
        why.extend(over_limit(self.steps_backward_over_limit, "time step(s) backwards", MAX_STEP_BACKWARD_NS, "", self.step_backward_ns_max));
        why.extend(over_limit(self.gaps_over_limit, "gap(s)", MAX_GAP_NS, " between records", self.gap_ns_max));
        (!why.is_empty()).then(|| why.join("; "))
    }

    /// What is accepted but worth saying, one line each.
    pub fn warnings(&self) -> Vec<String> {
        let mut w = Vec::new();
        if self.checksum_failures > 0 && self.content_checksum {
            w.push(format!("{} frames were recorded with a wrong ITP checksum", self.checksum_failures));
        }
        if self.time_steps_backward > 0 && self.steps_backward_over_limit == 0 {
            w.push(format!(
                "{} time step(s) backwards (longest {:.6} s); replayed as no wait",
                self.time_steps_backward,
                self.step_backward_ns_max as f64 * 1e-9
            ));
        }
        w
    }

    /// Time from the first record to the last, ns.
    pub fn duration_ns(&self) -> u64 {
        self.last_ns.saturating_sub(self.first_ns)
    }

    /// Time from the first record to the last, s.
    pub fn duration_s(&self) -> f64 {
        self.duration_ns() as f64 * 1e-9
    }

    /// Mean frame rate, Hz: intervals per second, `(frames − 1) / duration`;
    /// 0 with fewer than two frames or no elapsed time.
    pub fn rate_hz_mean(&self) -> f64 {
        if self.frames < 2 || self.duration_ns() == 0 {
            0.0
        } else {
            (self.frames - 1) as f64 / self.duration_s()
        }
    }
}

/// `count` intervals (`what`) longer than `limit_ns`, the longest
/// `longest_ns`, in words; `None` when there are none.
fn over_limit(count: u64, what: &str, limit_ns: u64, place: &str, longest_ns: u64) -> Option<String> {
    (count > 0).then(|| format!("{count} {what} of more than {} s{place} (longest {:.3} s)", limit_ns / 1_000_000_000, longest_ns as f64 * 1e-9))
}

/// The ITP frame's fields its checksum leaves out (docs/spec.md §2), with
/// their byte ranges: a change there passes the frame's check.
pub const FRAME_FIELDS_UNCHECKED: [(&str, std::ops::Range<usize>); 7] =
    [("pactyp", 4..8), ("version", 8..12), ("Qx", 36..52), ("Qy", 52..68), ("Qz", 68..84), ("Qw", 84..100), ("grasp", 108..116)];

/// What no checksum covers in a capture of `layout` without an LZ4 content
/// checksum: the record header's time stamp and its flag or delay (the
/// length is checked: it must be one frame), and the frame fields the ITP
/// checksum leaves out.
pub fn unverified_fields(layout: RecordLayout) -> Vec<String> {
    let flag = match layout {
        RecordLayout::Dropped => "dropped",
        RecordLayout::Delay => "delay_s",
    };
    ["time_ns", flag].into_iter().map(String::from).chain(FRAME_FIELDS_UNCHECKED.iter().map(|(f, _)| format!("frame.{f}"))).collect()
}

/// What a loaded capture is, for reports (`scenario check --json`, the
/// console's report) and stderr: its file, size, layout, and whether its
/// content is verified, with the fields that are not.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CaptureNote {
    /// The file, as named.
    pub path: String,
    /// Records read.
    pub records: u64,
    /// The record layout found.
    pub layout: RecordLayout,
    /// LZ4 frames in the file.
    pub lz4_frames: u64,
    /// Whether every LZ4 frame carries a content checksum (all matched:
    /// the file is as written).
    pub content_checksum: bool,
    /// The fields no checksum covers ([`unverified_fields`]); empty with a
    /// content checksum.
    pub unverified: Vec<String>,
}

impl CaptureNote {
    /// The note of a capture read from `path`.
    pub fn new(path: &Path, layout: RecordLayout, stats: &CaptureStats) -> CaptureNote {
        CaptureNote {
            path: path.display().to_string(),
            records: stats.frames,
            layout,
            lz4_frames: stats.lz4_frames,
            content_checksum: stats.content_checksum,
            unverified: if stats.content_checksum { Vec::new() } else { unverified_fields(layout) },
        }
    }

    /// The warning to print when the content is not verified.
    pub fn unverified_warning(&self) -> Option<String> {
        if self.content_checksum {
            return None;
        }
        let (header, frame): (Vec<&str>, Vec<&str>) = self.unverified.iter().map(String::as_str).partition(|f| !f.starts_with("frame."));
        let frame: Vec<&str> = frame.iter().map(|f| f.trim_start_matches("frame.")).collect();
        Some(format!(
            "capture `{}` has no LZ4 content checksum, so nothing shows it is as written: each frame's ITP checksum was checked, \
             but not the records' {}, nor the frame fields the ITP checksum leaves out ({}); damage there is read as recorded \
             (a time stamp is refused only beyond a 1 s step back or a 60 s gap)",
            self.path,
            header.join(" and "),
            frame.join(", ")
        ))
    }
}
