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
    /// A reverse channel's flags that do not fit the lane.
    #[error(transparent)]
    Channel(#[from] crate::service::channel::ChannelArgsError),
    /// A transport's flags that do not fit the lane.
    #[error(transparent)]
    Transport(#[from] crate::transport::TransportArgsError),
    /// netfi's own console or robot at an endpoint other than iceoryx2.
    #[error("netfi's own {end} speaks iceoryx2 only, and {flag} is {at}: give --{end} lab to join the lab's {end} there")]
    OwnEndElsewhere {
        /// `console` or `robot`.
        end: &'static str,
        /// The flag of its side.
        flag: &'static str,
        /// What that side is.
        at: String,
    },
    /// The lab's programs with several streams.
    #[error("--streams {streams}: the lab's console and robot join one stream (several arms: --ros2-topic once per arm)")]
    LabStreams {
        /// The streams asked for.
        streams: u32,
    },
    /// A capture's limit without a capture.
    #[error("--capture-max-records bounds --capture, and none was given")]
    CaptureLimitAlone,
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
