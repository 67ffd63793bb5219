//! The video stream's flags, the same for `netfi run` and each service.

use crate::flags::{Argv, Render};
use crate::transport::ipc::video::DEFAULT_VIDEO_MAX_BYTES;
use crate::video::{Gop, GopError};
use clap::Args;

/// Why the video flags were refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum VideoArgsError {
    /// The bit rate, frame rate or group of pictures make no stream.
    #[error("--video-*: {0}")]
    Gop(#[from] GopError),
    /// A video option without the video stream.
    #[error("--video-hz, --video-gop, --video-key-ratio, --video-max-bytes, --video-scenario and --video-seed need --video-mbps (the video stream is off)")]
    OptionsWithoutVideo,
    /// Video over another transport than iceoryx2.
    #[error("--video-mbps needs iceoryx2 on both sides: the video channels are iceoryx2's")]
    NeedsIceoryx2,
    /// Video with several streams.
    #[error("--video-mbps goes with one stream: the video path is stream 0's, and --streams {streams} asks for more")]
    OneStream {
        /// The streams asked for.
        streams: u32,
    },
    /// A largest payload out of range.
    #[error("--video-max-bytes must be from 1 to {MAX_VIDEO_MAX_BYTES} bytes, got {got}")]
    MaxBytes {
        /// What was given.
        got: usize,
    },
}

/// The largest `--video-max-bytes`: the link stages' largest payload, 64 MiB.
pub const MAX_VIDEO_MAX_BYTES: usize = crate::model::backlog::MAX_PAYLOAD_BYTES as usize;

/// The video stream's flags, the same for `netfi run` and each service.
#[derive(Debug, Clone, PartialEq, Args)]
pub struct VideoArgs {
    /// Add a synthetic camera on the robot side streaming video back to the
    /// console at this mean bit rate, Mbit/s (default: no video).
    #[arg(long, value_name = "MBIT_S")]
    pub video_mbps: Option<f64>,
    /// The camera's frame rate, Hz.
    #[arg(long, default_value_t = 60.0)]
    pub video_hz: f64,
    /// Frames per group of pictures (one key frame, then delta frames).
    #[arg(long, default_value_t = 30)]
    pub video_gop: u32,
    /// A key frame's size over a delta frame's.
    #[arg(long, default_value_t = 8.0)]
    pub video_key_ratio: f64,
    /// The largest video payload of the run, bytes; a larger frame is the
    /// emulator's drop `too_large`.
    #[arg(long, default_value_t = DEFAULT_VIDEO_MAX_BYTES)]
    pub video_max_bytes: usize,
    /// The scenario (file or preset) the video goes through, robot →
    /// console (default Normal: nothing injected).
    #[arg(long, value_name = "SCENARIO")]
    pub video_scenario: Option<String>,
    /// Seed of the video scenario (default: derived from the run's seed).
    #[arg(long)]
    pub video_seed: Option<u64>,
}

impl Default for VideoArgs {
    /// No video.
    fn default() -> Self {
        VideoArgs {
            video_mbps: None,
            video_hz: 60.0,
            video_gop: 30,
            video_key_ratio: 8.0,
            video_max_bytes: DEFAULT_VIDEO_MAX_BYTES,
            video_scenario: None,
            video_seed: None,
        }
    }
}

impl VideoArgs {
    /// Whether the run has video.
    pub fn on(&self) -> bool {
        self.video_mbps.is_some()
    }

    /// The group of pictures asked for, checked.
    pub fn gop(&self) -> Result<Gop, VideoArgsError> {
        let mbps = self.video_mbps.unwrap_or(1.0);
        Ok(Gop::new(mbps * 1e6, self.video_hz, self.video_gop, self.video_key_ratio)?)
    }

    /// Checks the flags: a bit rate, frame rate and group that make sense,
    /// a maximum payload in range, and no video options without video.
    pub fn validate(&self) -> Result<(), VideoArgsError> {
        if !self.on() {
            if *self != VideoArgs::default() {
                return Err(VideoArgsError::OptionsWithoutVideo);
            }
            return Ok(());
        }
        self.gop()?;
        if !(1..=MAX_VIDEO_MAX_BYTES).contains(&self.video_max_bytes) {
            return Err(VideoArgsError::MaxBytes { got: self.video_max_bytes });
        }
        Ok(())
    }
}

impl Render for VideoArgs {
    /// Only what differs from the defaults: nothing for a run without
    /// video whose other video flags are left alone.
    fn render(&self, a: &mut Argv) {
        let d = VideoArgs::default();
        a.opt("--video-mbps", self.video_mbps)
            .unless_default("--video-hz", self.video_hz, d.video_hz)
            .unless_default("--video-gop", self.video_gop, d.video_gop)
            .unless_default("--video-key-ratio", self.video_key_ratio, d.video_key_ratio)
            .unless_default("--video-max-bytes", self.video_max_bytes, d.video_max_bytes)
            .opt("--video-scenario", self.video_scenario.as_ref())
            .opt("--video-seed", self.video_seed);
    }
}
