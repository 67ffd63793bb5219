//! Why the console or the simulator did not run to its report: the steps
//! both share (their pid file, node, ports, placement, video, ready file
//! and report), and each one's own (the console's frames and its wait for
//! the emulator, the robot's set-up and end).

use crate::capture::CaptureError;
use crate::durable::DurableError;
use crate::kinematics::KinematicsConfigError;
use crate::metrics::IntervalLogError;
use crate::motion::MotionParamError;

/// Why a console or a simulator did not run to its report.
#[derive(Debug, thiserror::Error)]
pub enum ServiceError {
    #[error(transparent)]
    Pid(#[from] super::PidError),
    #[error(transparent)]
    Node(#[from] crate::transport::open::NodeError),
    /// A port this process publishes on, by its direction.
    #[error("opening the {0} port")]
    Publisher(&'static str, #[source] crate::transport::PublisherOpenError),
    /// A port this process subscribes to, by its direction.
    #[error("opening the {0} port")]
    Subscriber(&'static str, #[source] crate::transport::SubscriberOpenError),
    #[error(transparent)]
    Place(#[from] crate::host::placement::PlaceError),
    #[error(transparent)]
    Video(#[from] super::channel::video::VideoError),
    /// `<role>.ready`.
    #[error("writing {0}")]
    Ready(&'static str, #[source] std::io::Error),
    /// The report.
    #[error(transparent)]
    Report(#[from] super::WriteError),
    #[error(transparent)]
    Args(#[from] super::args::ArgsError),
    /// The console's frames.
    #[error(transparent)]
    Script(#[from] ScriptError),
    /// The console's end of the feedback loop, or the robot's kinematics.
    #[error(transparent)]
    Kinematics(#[from] crate::kinematics::KinematicsConfigError),
    /// The console's wait for the emulator.
    #[error(transparent)]
    Wait(#[from] WaitError),
    #[error(transparent)]
    Robot(#[from] RobotError),
}

/// Why the console's frames could not be had.
#[derive(Debug, thiserror::Error)]
pub enum ScriptError {
    /// The capture could not be read, or was refused.
    #[error(transparent)]
    Capture(#[from] CaptureError),
    /// The synthetic motion's parameters were refused.
    #[error(transparent)]
    Motion(#[from] MotionParamError),
}

/// Why the console did not start streaming.
#[derive(Debug, thiserror::Error)]
pub enum WaitError {
    /// No emulator subscribed in time.
    #[error("no emulator subscribed to netfi/{run_id}/console within {wait_s} s")]
    NoEmulator {
        /// The run.
        run_id: String,
        /// How long the console waited (`--wait-for-peer-s`).
        wait_s: f64,
    },
    /// Told to stop while waiting.
    #[error("stopped before streaming")]
    Stopped,
}

/// Why the simulator's robot could not be set up or end whole.
#[derive(Debug, thiserror::Error)]
pub enum RobotError {
    /// `--stall-ms` out of the kinematics' range.
    #[error("--stall-ms: {0}")]
    StallMs(#[source] KinematicsConfigError),
    /// `received.csv` could not be written whole.
    #[error(transparent)]
    Received(#[from] DurableError),
    /// A histogram log could not be written.
    #[error(transparent)]
    Histogram(#[from] IntervalLogError),
}
