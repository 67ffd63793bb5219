//! Arguments that parse one by one but do not go together: each error
//! says which flags, and what would be accepted.

/// Why a service's or a run's arguments were refused.
#[derive(Debug, thiserror::Error)]
pub enum ArgsError {
    /// Several streams over UDP.
    #[error("--streams and --stream-scenario need iceoryx2 on both sides")]
    StreamsNeedIceoryx2,
    /// A `--stream-scenario` that names no stream of the run.
    #[error("--stream-scenario {text}: {why}")]
    StreamScenario {
        /// What was given.
        text: String,
        /// What is wrong with it.
        why: String,
    },
    /// The video flags, as [`VideoArgs::validate`](crate::service::video::VideoArgs::validate) says.
    #[error(transparent)]
    Video(#[from] crate::service::video::VideoArgsError),
    /// Video over UDP.
    #[error("--video-mbps needs iceoryx2 on both sides: the video channels are iceoryx2's")]
    VideoNeedsIceoryx2,
    /// Video with several streams.
    #[error("--video-mbps goes with one stream: the video path is stream 0's, and --streams {streams} asks for more")]
    VideoOneStream {
        /// The streams asked for.
        streams: u32,
    },
    /// A transport's flags that do not fit the lane.
    #[error(transparent)]
    Transport(#[from] crate::transport::TransportArgsError),
    /// `--no-feedback` with a scenario or seed for the feedback.
    #[error("--no-feedback cannot be combined with --return-scenario or --return-seed")]
    NoFeedbackWithReturn,
    /// `--no-feedback` over UDP.
    #[error("--no-feedback applies to the iceoryx2 feedback loop (iceoryx2 on both sides)")]
    NoFeedbackNeedsIceoryx2,
    /// Return options with one UDP side.
    #[error("--return-scenario, --return-to and --return-seed apply to the return path, which needs UDP on both sides (or iceoryx2 on both, for the feedback loop)")]
    ReturnNeedsBothSides,
    /// `--no-return` with return options.
    #[error("--no-return cannot be combined with --return-scenario, --return-to or --return-seed")]
    NoReturnWithReturn,
    /// A run that would last longer than a run may.
    #[error("--frames {frames} at {rate_hz} Hz would stream for {seconds} s; a run lasts at most a week ({max_s} s)")]
    TooLong {
        /// Frames asked for.
        frames: u64,
        /// At this rate.
        rate_hz: f64,
        /// For this long.
        seconds: String,
        /// The longest run.
        max_s: f64,
    },
    /// A core this process may not run on.
    #[error("{flag} {core}: this process may only run on CPU(s) {cores:?} (an inherited CPU mask: `taskset`?)")]
    CoreNotAllowed {
        /// The flag that named it.
        flag: &'static str,
        /// The core.
        core: usize,
        /// The cores it may run on.
        cores: Vec<usize>,
    },
}
