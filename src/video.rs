//! The pure parts of the synthetic video stream (`netfi run --video-mbps`):
//! the sizes of a group of pictures, the per-frame accounting, and the
//! freeze detector. No clock, no I/O: times come in as ns.
//!
//! **Sizes.** A group of pictures of `gop_frames` frames is one key frame of
//! `key_ratio` times a delta frame's size, then `gop_frames − 1` delta
//! frames; the sizes are scaled so that the stream's mean bit rate is the
//! one asked: `delta = R / (8 · hz) · gop / (gop − 1 + key_ratio)` bytes.
//!
//! **Fates.** A frame is *whole* when it reached the console with every
//! byte; *damaged* when part of it was lost: a frame of several packets
//! (larger than one MTU) that a loss stage dropped (on a packet network
//! the other packets would have arrived, but the frame cannot be decoded),
//! or one that arrived with wrong bytes; *lost* when none of it arrived (a
//! one-packet frame dropped, or a frame dropped whole: the link's queue,
//! the emulator's queue, a payload over the run's maximum). The core
//! decides one fate per payload (its packets share it, see
//! [`crate::model::backlog`]), so which dropped frames were damaged is told
//! from the drop's reason and the frame's size ([`drop_kind`]).
//!
//! **Freezes.** The console displays each whole frame newer than the last
//! one displayed. A gap between two displayed frames longer than two frame
//! periods is a freeze of the gap's length ([`Freezes`]).

use serde::{Deserialize, Serialize};

/// Why a group of pictures makes no stream; each says what is accepted.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum GopError {
    /// A bit rate not above 0, or over 100 Gbit/s.
    #[error("the video's bit rate must be above 0 and at most 100 Gbit/s, got {bit_s} bit/s")]
    BitRate {
        /// What was given, bit/s.
        bit_s: f64,
    },
    /// A frame rate outside 0.1–10 000 Hz.
    #[error("the video's frame rate must be from 0.1 to 10000 Hz, got {hz}")]
    FrameRate {
        /// What was given, Hz.
        hz: f64,
    },
    /// A group of no frames.
    #[error("a group of pictures has at least one frame")]
    NoFrames,
    /// A key frame ratio outside 1–1000.
    #[error("the key frame ratio must be from 1 to 1000, got {ratio}")]
    KeyRatio {
        /// What was given.
        ratio: f64,
    },
}

/// The sizes of a group of pictures at a bit rate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gop {
    /// Frames per group (the key frame included).
    pub frames: u32,
    pub key_bytes: u64,
    pub delta_bytes: u64,
}

impl Gop {
    /// The group for `bit_rate_bit_s` at `frame_hz` frames a second, with
    /// `frames` frames a group and key frames `key_ratio` times a delta
    /// frame. Every frame has at least one byte.
    pub fn new(bit_rate_bit_s: f64, frame_hz: f64, frames: u32, key_ratio: f64) -> Result<Gop, GopError> {
        if !(bit_rate_bit_s.is_finite() && bit_rate_bit_s > 0.0 && bit_rate_bit_s <= 1e11) {
            return Err(GopError::BitRate { bit_s: bit_rate_bit_s });
        }
        if !(frame_hz.is_finite() && (0.1..=10_000.0).contains(&frame_hz)) {
            return Err(GopError::FrameRate { hz: frame_hz });
        }
        if frames == 0 {
            return Err(GopError::NoFrames);
        }
        if !(key_ratio.is_finite() && (1.0..=1000.0).contains(&key_ratio)) {
            return Err(GopError::KeyRatio { ratio: key_ratio });
        }
        let mean = bit_rate_bit_s / 8.0 / frame_hz;
        let delta = mean * f64::from(frames) / (f64::from(frames) - 1.0 + key_ratio);
        let delta_bytes = (delta.round() as u64).max(1);
        let key_bytes = ((delta * key_ratio).round() as u64).max(1);
        Ok(Gop { frames, key_bytes, delta_bytes })
    }

    /// Frame `index`'s size and whether it is a key frame.
    #[inline]
    pub fn size(&self, index: u64) -> (u64, bool) {
        if index % u64::from(self.frames) == 0 {
            (self.key_bytes, true)
        } else {
            (self.delta_bytes, false)
        }
    }

    /// The mean bit rate the sizes give, bit/s.
    pub fn bit_rate(&self, frame_hz: f64) -> f64 {
        let group = self.key_bytes + self.delta_bytes * u64::from(self.frames - 1);
        group as f64 * 8.0 * frame_hz / f64::from(self.frames)
    }
}

/// What became of a dropped frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DropKind {
    /// Part of it lost: undecodable.
    Damaged,
    /// Lost whole.
    Lost,
}

/// A frame of `len` bytes dropped for `reason` (a drop reason of the
/// report) on packets of `mtu_bytes`: damaged when a loss stage took a
/// frame of several packets, else lost (module docs).
pub fn drop_kind(len: u64, reason: &str, mtu_bytes: u64) -> DropKind {
    let whole_drop = matches!(reason, "link_queue" | "queue_full" | "too_large" | "wrong_size" | "bad_flags" | "outage");
    if len > mtu_bytes && !whole_drop {
        DropKind::Damaged
    } else {
        DropKind::Lost
    }
}

/// The freezes of a displayed stream: gaps between consecutive displayed
/// frames longer than a threshold (two frame periods).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Freezes {
    threshold_ns: u64,
    last_ns: Option<u64>,
    pub count: u64,
    pub total_ns: u64,
    pub longest_ns: u64,
}

impl Freezes {
    /// A detector for a stream of `frame_hz` frames a second.
    pub fn new(frame_hz: f64) -> Freezes {
        Freezes { threshold_ns: (2e9 / frame_hz) as u64, last_ns: None, count: 0, total_ns: 0, longest_ns: 0 }
    }

    /// A frame displayed at `t_ns` (times do not decrease); the gap since
    /// the frame displayed before it (none for the first), a freeze when
    /// [`Freezes::is_freeze`].
    #[inline]
    pub fn displayed(&mut self, t_ns: u64) -> Option<u64> {
        let gap = self.last_ns.map(|last| t_ns.saturating_sub(last));
        if let Some(gap) = gap.filter(|g| self.is_freeze(*g)) {
            self.count += 1;
            self.total_ns += gap;
            self.longest_ns = self.longest_ns.max(gap);
        }
        self.last_ns = Some(t_ns);
        gap
    }

    /// Whether a gap between two displayed frames is a freeze.
    #[inline]
    pub fn is_freeze(&self, gap_ns: u64) -> bool {
        gap_ns > self.threshold_ns
    }

    /// The threshold, ns.
    pub fn threshold_ns(&self) -> u64 {
        self.threshold_ns
    }
}

/// The header line of `video_received.csv`, the console's record of each
/// video frame it received (docs/spec.md §6).
pub const RECEIVED_CSV_HEADER: &str =
    "frame_index,gop_index,key,len,bytes,send_ns,ingress_index,ingress_ns,release_sched_ns,release_ns,recv_ns,delay_ns,fate,displayed,gap_ns,freeze";

/// One video frame the console received: a row of `video_received.csv`.
/// The header's fields as they arrived, the receive time, and what the
/// console made of the frame.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ReceivedRow {
    pub frame_index: u64,
    pub gop_index: u32,
    pub key: bool,
    /// The header's `len`.
    pub len: u32,
    /// The bytes that came (the slice's length).
    pub bytes: u64,
    pub send_ns: u64,
    pub ingress_index: u64,
    pub ingress_ns: u64,
    pub release_sched_ns: u64,
    pub release_ns: u64,
    pub recv_ns: u64,
    /// Every byte as sent (else damaged).
    pub whole: bool,
    /// Whole and newer than the last frame displayed.
    pub displayed: bool,
    /// For a displayed frame but the first: the time since the frame
    /// displayed before it.
    pub gap_ns: Option<u64>,
    /// That gap is a freeze (over two frame periods).
    pub freeze: bool,
}

impl ReceivedRow {
    /// Camera send → console receive.
    #[inline]
    pub fn delay_ns(&self) -> u64 {
        self.recv_ns.saturating_sub(self.send_ns)
    }

    /// Writes the row as a CSV line (nothing allocated).
    pub fn write(&self, w: &mut impl std::io::Write) -> std::io::Result<()> {
        writeln!(
            w,
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}",
            self.frame_index,
            self.gop_index,
            u8::from(self.key),
            self.len,
            self.bytes,
            self.send_ns,
            self.ingress_index,
            self.ingress_ns,
            self.release_sched_ns,
            self.release_ns,
            self.recv_ns,
            self.delay_ns(),
            if self.whole { "whole" } else { "damaged" },
            u8::from(self.displayed),
            Cell(self.gap_ns),
            u8::from(self.freeze),
        )
    }
}

/// A CSV cell: the number, or nothing.
struct Cell(Option<u64>);

impl std::fmt::Display for Cell {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.0 {
            Some(v) => write!(f, "{v}"),
            None => Ok(()),
        }
    }
}

/// The frames of a video stream by fate: `sent = whole + damaged + lost`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct FrameTally {
    pub sent: u64,
    pub whole: u64,
    pub damaged: u64,
    pub lost: u64,
}

impl FrameTally {
    /// The tally of `sent` frames of which `whole` arrived whole, `damaged_received`
    /// arrived with wrong bytes and `damaged_dropped` were dropped part-way
    /// ([`drop_kind`]); the rest were lost. Frames the console did not see
    /// but the emulator did not drop either (still held at the end) count as
    /// lost.
    pub fn new(sent: u64, whole: u64, damaged_received: u64, damaged_dropped: u64) -> FrameTally {
        let damaged = (damaged_received + damaged_dropped).min(sent.saturating_sub(whole));
        FrameTally { sent, whole, damaged, lost: sent.saturating_sub(whole + damaged) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_gop_gives_the_bit_rate_asked() {
        let g = Gop::new(8e6, 60.0, 30, 8.0).unwrap();
        assert_eq!(g.size(0), (g.key_bytes, true));
        assert_eq!(g.size(1), (g.delta_bytes, false));
        assert_eq!(g.size(30), (g.key_bytes, true));
        // delta = 16666.7 · 30 / 37 = 13513.5 → 13514 (rounded), key 8× the exact delta.
        assert_eq!((g.delta_bytes, g.key_bytes), (13514, 108108));
        // Rounding to whole bytes moves the rate by less than one byte a frame.
        assert!((g.bit_rate(60.0) - 8e6).abs() < 8.0 * 60.0, "{}", g.bit_rate(60.0));
        let one = Gop::new(8e6, 60.0, 1, 8.0).unwrap();
        assert_eq!(one.size(5), (one.key_bytes, true));
        assert!((one.bit_rate(60.0) - 8e6).abs() < 8.0 * 60.0);
    }

    #[test]
    fn bad_gop_parameters_are_refused() {
        assert!(Gop::new(0.0, 60.0, 30, 8.0).unwrap_err().to_string().contains("bit rate"));
        assert!(Gop::new(8e6, 0.0, 30, 8.0).unwrap_err().to_string().contains("frame rate"));
        assert!(Gop::new(8e6, 60.0, 0, 8.0).is_err());
        assert!(Gop::new(8e6, 60.0, 30, 0.5).unwrap_err().to_string().contains("key frame"));
        assert!(Gop::new(f64::NAN, 60.0, 30, 8.0).is_err());
    }

    #[test]
    fn a_loss_damages_a_frame_of_several_packets_and_a_queue_loses_it() {
        assert_eq!(drop_kind(4000, "bernoulli", 1500), DropKind::Damaged);
        assert_eq!(drop_kind(4000, "ge_lomax", 1500), DropKind::Damaged);
        assert_eq!(drop_kind(1500, "bernoulli", 1500), DropKind::Lost);
        assert_eq!(drop_kind(4000, "link_queue", 1500), DropKind::Lost);
        assert_eq!(drop_kind(4000, "queue_full", 1500), DropKind::Lost);
        assert_eq!(drop_kind(1 << 30, "too_large", 1500), DropKind::Lost);
    }

    #[test]
    fn freezes_are_gaps_over_two_periods() {
        let mut f = Freezes::new(50.0); // 20 ms a frame, threshold 40 ms
        assert_eq!(f.threshold_ns(), 40_000_000);
        let gaps: Vec<Option<u64>> = [0, 20, 40, 80, 100, 200, 201].iter().map(|t| f.displayed(t * 1_000_000)).collect();
        assert_eq!(gaps[0], None);
        assert_eq!(gaps[3], Some(40_000_000));
        assert!(!f.is_freeze(40_000_000) && f.is_freeze(40_000_001));
        // 40 → 80 is exactly two periods: no freeze; 100 → 200 is one.
        assert_eq!((f.count, f.total_ns, f.longest_ns), (1, 100_000_000, 100_000_000));
        f.displayed(500_000_000);
        assert_eq!((f.count, f.total_ns, f.longest_ns), (2, 399_000_000, 299_000_000));
    }

    #[test]
    fn a_received_row_is_one_csv_line_under_the_header() {
        let mut r = ReceivedRow {
            frame_index: 7,
            gop_index: 0,
            key: true,
            len: 1000,
            bytes: 1000,
            send_ns: 100,
            ingress_index: 6,
            ingress_ns: 110,
            release_sched_ns: 150,
            release_ns: 151,
            recv_ns: 160,
            whole: true,
            displayed: true,
            gap_ns: Some(50_000_000),
            freeze: true,
        };
        let mut out = Vec::new();
        r.write(&mut out).unwrap();
        (r.whole, r.displayed, r.gap_ns, r.freeze) = (false, false, None, false);
        r.write(&mut out).unwrap();
        let text = String::from_utf8(out).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines, ["7,0,1,1000,1000,100,6,110,150,151,160,60,whole,1,50000000,1", "7,0,1,1000,1000,100,6,110,150,151,160,60,damaged,0,,0"]);
        assert!(lines.iter().all(|l| l.split(',').count() == RECEIVED_CSV_HEADER.split(',').count()));
    }

    #[test]
    fn the_tally_adds_up() {
        let t = FrameTally::new(100, 90, 1, 4);
        assert_eq!(t, FrameTally { sent: 100, whole: 90, damaged: 5, lost: 5 });
        assert_eq!(t.whole + t.damaged + t.lost, t.sent);
        // More damage claimed than frames missing cannot happen; it is capped.
        assert_eq!(FrameTally::new(10, 10, 0, 3), FrameTally { sent: 10, whole: 10, damaged: 0, lost: 0 });
    }
}
