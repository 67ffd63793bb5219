//! The video's section of the run report: the emulator's path, the
//! console's receiver and the camera joined.

use super::{CameraReport, ReceivedVideo};
use crate::metrics::Summary;
use super::VideoExtra;
use crate::service::schema::PathReport;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// The video stream of a run robot → emulator → console: what the camera
/// sent, what the video scenario did, and what the console saw.
///
/// `frames` counts the frames the emulator took in less those it released
/// while no console listened: whole (arrived with every byte), damaged
/// (part lost: dropped part-way by a loss stage, or arrived with wrong
/// bytes) and lost. `balanced`: the emulator's account holds and the
/// console received what the emulator released to it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct VideoSection {
    pub scenario: String,
    pub seed: u64,
    pub camera: Option<CameraReport>,
    pub frames: crate::video::FrameTally,
    pub dropped: BTreeMap<String, u64>,
    pub held_at_end: u64,
    /// Whole frames older than one already displayed.
    pub late: Option<u64>,
    /// Camera send → console receive of the whole frames.
    pub delay_ns: Option<Summary>,
    /// The delay the video scenario injected (a link stage's queueing and
    /// serialization included).
    pub injected_delay_ns: Summary,
    pub freezes: Option<u64>,
    pub freeze_total_ms: Option<f64>,
    pub freeze_longest_ms: Option<f64>,
    pub freeze_threshold_ms: Option<f64>,
    pub bytes_entered: u64,
    pub bytes_delivered: u64,
    /// The video scenario's stages (a link stage's utilisation, queue and delay).
    pub stages: serde_json::Value,
    pub balanced: bool,
}

impl VideoSection {
    /// Joins the emulator's video path, the console's receiver and the
    /// camera's report; `None` without video.
    pub fn join(e: Option<&PathReport<VideoExtra>>, c: Option<&ReceivedVideo>, camera: Option<&CameraReport>) -> Option<VideoSection> {
        let e = e?;
        let a = &e.account;
        let sent = a.entered.saturating_sub(e.delivered_unsubscribed);
        let (whole, damaged_rx) = c.map_or((0, 0), |c| (c.whole, c.damaged));
        let balanced = e.balanced && c.is_some_and(|c| c.received + e.delivered_unsubscribed == a.delivered);
        Some(VideoSection {
            scenario: e.scenario.clone(),
            seed: e.seed,
            camera: camera.cloned(),
            frames: crate::video::FrameTally::new(sent, whole, damaged_rx, e.extra.dropped_damaged),
            dropped: a.dropped.clone(),
            held_at_end: a.held_at_end,
            late: c.map(|c| c.late),
            delay_ns: c.map(|c| c.delay_ns).filter(|d| d.count > 0),
            injected_delay_ns: e.measures.injected_delay_ns,
            freezes: c.map(|c| c.freezes),
            freeze_total_ms: c.map(|c| c.freeze_total_ms),
            freeze_longest_ms: c.map(|c| c.freeze_longest_ms),
            freeze_threshold_ms: c.map(|c| c.freeze_threshold_ms),
            bytes_entered: e.extra.bytes_entered,
            bytes_delivered: e.extra.bytes_delivered,
            stages: serde_json::to_value(&e.measures.stages).unwrap_or_default(),
            balanced,
        })
    }

    /// What is wrong when the section does not balance.
    pub fn fault(&self) -> Option<String> {
        (!self.balanced).then(|| {
            let f = &self.frames;
            format!(
                "video not balanced: {} frames through the emulator ({} whole, {} damaged, {} lost), dropped {}, held at end {}",
                f.sent,
                f.whole,
                f.damaged,
                f.lost,
                crate::service::report::dropped_list(&self.dropped),
                self.held_at_end
            )
        })
    }

    /// The section as lines of the run's text report.
    pub fn to_text(&self) -> String {
        let dropped: Vec<String> = self.dropped.iter().map(|(k, v)| format!("{v} by {k}")).collect();
        let mut s = format!("video      scenario {} (seed {})", self.scenario, self.seed);
        if let Some(c) = &self.camera {
            s += &format!(
                ": camera {:.0} Hz, {:.2} Mbit/s, GOP {} (key {} B, delta {} B), {} frames sent",
                c.frame_hz,
                c.bit_rate_bit_s / 1e6,
                c.gop_frames,
                c.key_bytes,
                c.delta_bytes,
                c.frames_sent
            );
        }
        s += "\n";
        let f = &self.frames;
        s += &format!(
            "  frames     {} through the emulator: {} whole, {} damaged, {} lost; dropped {}; held at end {}; accounting {}\n",
            f.sent,
            f.whole,
            f.damaged,
            f.lost,
            if dropped.is_empty() { "none".into() } else { dropped.join(", ") },
            self.held_at_end,
            if self.balanced { "balanced" } else { "NOT balanced" }
        );
        s += &format!("  delay      {}\n", line_ms(self.delay_ns.as_ref()));
        if let (Some(n), Some(t), Some(l), Some(th)) = (self.freezes, self.freeze_total_ms, self.freeze_longest_ms, self.freeze_threshold_ms) {
            s += &format!("  freezes    {n} (gaps over {th:.1} ms): total {t:.1} ms, longest {l:.1} ms\n");
        }
        s
    }
}

fn line_ms(d: Option<&Summary>) -> String {
    match d {
        Some(d) => format!(
            "p50 {:.2} ms  p90 {:.2} ms  p99 {:.2} ms  max {:.2} ms  ({} whole frames)",
            d.p50 as f64 / 1e6,
            d.p90 as f64 / 1e6,
            d.p99 as f64 / 1e6,
            d.max as f64 / 1e6,
            d.count
        ),
        None => "-".into(),
    }
}

