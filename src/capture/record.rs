//! A record of a capture and the two layouts it may have on disk.

use crate::frame::{FrameError, ItpFrame, ItpView, FRAME_LEN};

/// Bytes in a record header: time (8), length (2), dropped flag (1).
pub const RECORD_HEADER_LEN: usize = 11;

/// Bytes in a record that carries one ITP frame.
pub const RECORD_LEN: usize = RECORD_HEADER_LEN + FRAME_LEN;

/// Bytes in a delay capture's record header: time (8), length (2), delay (4).
pub const DELAY_RECORD_HEADER_LEN: usize = 14;

/// The two record layouts a capture may use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RecordLayout {
    /// `u64 time_ns | u16 len | u8 dropped | payload`: netfi's and the
    /// study's console recordings.
    Dropped,
    /// `u64 time_ns | u16 len | f32 delay_s | payload`: the study's
    /// delay-trial captures.
    Delay,
}

impl RecordLayout {
    /// Bytes before the payload.
    pub const fn header_len(self) -> usize {
        match self {
            RecordLayout::Dropped => RECORD_HEADER_LEN,
            RecordLayout::Delay => DELAY_RECORD_HEADER_LEN,
        }
    }

    /// The layout in words, for reports.
    pub const fn describe(self) -> &'static str {
        match self {
            RecordLayout::Dropped => "time | length | dropped flag | frame",
            RecordLayout::Delay => "time | length | delay (s) | frame",
        }
    }
}

/// One record of a capture carrying an ITP frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CaptureRecord {
    /// Receive time at the recorder, ns.
    pub time_ns: u64,
    /// The "dropped" flag byte as written (0: the frame was delivered; 0 in
    /// a delay capture).
    pub dropped: u8,
    /// The delay the study's tool drew for the frame, s (delay captures
    /// only).
    pub delay_s: Option<f32>,
    /// The ITP frame's wire bytes.
    pub payload: [u8; FRAME_LEN],
}

impl CaptureRecord {
    /// A record of a delivered frame.
    pub fn new(time_ns: u64, frame: &ItpFrame) -> CaptureRecord {
        CaptureRecord { time_ns, dropped: 0, delay_s: None, payload: frame.to_bytes() }
    }

    /// Whether the recorder flagged the frame as dropped.
    pub fn is_dropped(&self) -> bool {
        self.dropped != 0
    }

    /// A view of the payload (always one frame long).
    pub fn view(&self) -> ItpView<&[u8; FRAME_LEN]> {
        ItpView::new_unchecked(&self.payload)
    }

    /// The payload parsed, checksum verified.
    pub fn frame(&self) -> Result<ItpFrame, FrameError> {
        ItpFrame::parse(&self.view())
    }

    /// The payload parsed without judging the checksum.
    pub fn frame_unverified(&self) -> ItpFrame {
        ItpFrame::parse_unverified(&self.view())
    }
}
