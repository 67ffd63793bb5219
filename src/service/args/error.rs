//! Arguments that parse one by one but do not go together: each error
//! says which flags, and what would be accepted.

use crate::transport::Endpoint;

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
    #[error("{0:#}")]
    Video(anyhow::Error),
    /// Video over UDP.
    #[error("--video-mbps needs iceoryx2 on both sides: the video channels are iceoryx2's")]
    VideoNeedsIceoryx2,
    /// Video with several streams.
    #[error("--video-mbps goes with one stream: the video path is stream 0's, and --streams {streams} asks for more")]
    VideoOneStream {
        /// The streams asked for.
        streams: u32,
    },
    /// `--wait-for-peer-s` towards a UDP robot.
    #[error("--wait-for-peer-s waits for a robot on the iceoryx2 egress; a UDP robot does not subscribe")]
    WaitForUdpPeer,
    /// No run id for an iceoryx2 side.
    #[error("--run-id is required with the iceoryx2 ingress and egress")]
    RunIdRequired,
    /// No run id for the iceoryx2 side of a UDP bridge.
    #[error("--run-id is needed for the iceoryx2 side (ingress {ingress}, egress {egress})")]
    RunIdNeeded {
        /// Where frames come from.
        ingress: Endpoint,
        /// Where they go.
        egress: Endpoint,
    },
    /// UDP return options with iceoryx2 on both sides.
    #[error("--return-to and --no-return apply to the UDP return path; with iceoryx2 on both sides the feedback goes to the console's `feedback_out` (--no-feedback turns it off)")]
    UdpReturnWithIceoryx2,
    /// `--no-feedback` with a scenario or seed for the feedback.
    #[error("--no-feedback cannot be combined with --return-scenario or --return-seed")]
    NoFeedbackWithReturn,
    /// `--no-feedback` over UDP.
    #[error("--no-feedback applies to the iceoryx2 feedback loop (iceoryx2 on both sides)")]
    NoFeedbackNeedsIceoryx2,
    /// Raw payloads with an iceoryx2 side.
    #[error("--payload raw needs UDP on both sides (--ingress udp://… --egress udp://…): an iceoryx2 port carries ITP frames only")]
    RawNeedsUdp,
    /// Return options with one UDP side.
    #[error("--return-scenario, --return-to and --return-seed apply to the return path, which needs UDP on both sides (or iceoryx2 on both, for the feedback loop)")]
    ReturnNeedsBothSides,
    /// `--robot-from` without UDP on both sides.
    #[error("--robot-from applies to the return path, which needs UDP on both sides")]
    RobotFromNeedsBothSides,
    /// `--no-return` with return options.
    #[error("--no-return cannot be combined with --return-scenario, --return-to or --return-seed")]
    NoReturnWithReturn,
    /// A flag of one UDP side given without that side.
    #[error("{flag} applies to a UDP {side}{more}")]
    NeedsUdpSide {
        /// The flag.
        flag: &'static str,
        /// `ingress` or `egress`.
        side: &'static str,
        /// What else to say.
        more: &'static str,
    },
    /// A robot's address that cannot be sent to.
    #[error("--egress {egress}: the robot's address needs a specific address and a port other than 0")]
    EgressAddress {
        /// What was given.
        egress: Endpoint,
    },
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
