//! What each direction of the emulator adds to its path's report (the
//! `extra` of [`super::PathReport`]): the forward stream's, the feedback's,
//! the video's and the UDP return's.

use super::BadInput;
use serde::{Deserialize, Serialize};

/// What the forward channel adds to its path's report.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct ForwardExtra {
    pub sent_by_console: Option<u64>,
    pub bad_checksum_passed: u64,
    pub bad_input: BadInput,
}

/// What the feedback channel adds to its path's report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FeedbackExtra {
    /// Feedback samples the robot said it sent (from its end marker).
    pub sent_by_robot: Option<u64>,
}

/// What the video channel adds to its path's report: `entered = delivered
/// + dropped + held_at_end`, and every drop is damaged or lost.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct VideoExtra {
    pub max_bytes: usize,
    /// Frames the camera said it sent (from its end marker).
    pub sent_by_camera: Option<u64>,
    /// Dropped frames of several packets taken by a loss stage.
    pub dropped_damaged: u64,
    /// Dropped frames lost whole.
    pub dropped_lost: u64,
    pub bytes_entered: u64,
    pub bytes_delivered: u64,
}

/// What the return channel adds to its path's report: `received = entered
/// + unroutable`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ReturnExtra {
    /// `untouched` (no return scenario) or `scenario`.
    pub mode: String,
    /// Where return datagrams go.
    pub destination: String,
    /// Datagrams taken off the egress socket.
    pub received: u64,
    /// Received before any console was known: not relayed.
    pub unroutable: u64,
    /// Return datagrams the kernel dropped before the emulator took them.
    pub kernel_drops: Option<u64>,
    /// Datagrams at the egress socket from others than the robot: refused.
    #[serde(default)]
    pub refused: crate::transport::udp::Refused,
}

