//! Why the console or the simulator did not run to its report: the steps
//! both share (their pid file, node, ports, placement, video, ready file
//! and report), and each one's own.

use std::path::PathBuf;

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
    Video(#[from] super::video::VideoError),
    /// `<role>.ready`.
    #[error("writing {0}")]
    Ready(&'static str, #[source] std::io::Error),
    /// The report as JSON.
    #[error(transparent)]
    Json(#[from] serde_json::Error),
    #[error("writing {}", .0.display())]
    Report(PathBuf, #[source] crate::durable::DurableError),
    #[error(transparent)]
    Args(#[from] super::args::ArgsError),
    /// The console's frames.
    #[error(transparent)]
    Script(#[from] super::console::ScriptError),
    /// The console's end of the feedback loop, or the robot's kinematics.
    #[error(transparent)]
    Kinematics(#[from] crate::kinematics::KinematicsConfigError),
    /// The console's wait for the emulator.
    #[error(transparent)]
    Wait(#[from] super::console::WaitError),
    #[error(transparent)]
    Robot(#[from] super::simulator::RobotError),
}

/// Writes a service's report as pretty JSON, whole or not at all.
pub(crate) fn write_report(path: PathBuf, report: &impl serde::Serialize) -> Result<(), ServiceError> {
    crate::durable::write_whole(&path, &serde_json::to_vec_pretty(report)?).map_err(|e| ServiceError::Report(path, e))
}
