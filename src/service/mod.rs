//! The real-time services: console, emulator and simulator loops, and the
//! runner that starts all three. Unlike the sans-IO core these read the
//! clock, pin cores and talk to transports — through the
//! [`FrameSource`](crate::transport::FrameSource) and
//! [`FrameSink`](crate::transport::FrameSink) traits, so the loops do not
//! depend on which transport carries the frames.
//!
//! | file | what |
//! |---|---|
//! | `args` | the services' command-line arguments, and the argv each renders |
//! | `link` | the link: injector, histograms, trace, written once |
//! | `emulator` | the emulator: one loop over lanes of paths around links, and its wiring |
//! | `schema` | the JSON contracts between the processes |
//! | `seeds` | every seed rule |
//! | `control`, `telemetry` | live control of a running emulator, and its telemetry, off the loop |
//! | `video` | the video stream's flags, the robot's camera, the console's receiver |
//! | `console`, `simulator` | the two ends of a local run |
//! | `ros2` | `netfi ros2 record` and `replay`: ROS 2 topics as MCAP (`bag`) |
//! | `plan`, `supervise`, `run`, `report` | `netfi run`: what runs where; when to stop what; the processes; the joined report |

pub mod args;
pub mod channel;
pub mod console;
pub mod control;
pub mod emulator;
pub mod error;
pub mod link;
pub mod plan;
pub mod report;
pub mod ros2;
pub mod run;
pub mod schema;
pub mod seeds;
pub mod signals;
pub mod simulator;
pub mod supervise;
pub mod telemetry;

/// Why `<out>/<role>.pid` could not be written.
#[derive(Debug, thiserror::Error)]
#[error("{what} {}: {source}", .path.display())]
pub struct PidError {
    /// `creating` (the directory) or `writing` (the file).
    pub what: &'static str,
    /// The directory or the file.
    pub path: std::path::PathBuf,
    /// The kernel's error.
    #[source]
    pub source: std::io::Error,
}

/// The flags of a service's own binary (`netfi-console`, …), named
/// `name`: parsed from the command line (clap prints help or the error and
/// exits), once the process is set to end with the `netfi run` that
/// started it, if one did.
pub fn standalone_args<A: clap::Args + clap::FromArgMatches>(name: &'static str, about: &'static str) -> Result<A, crate::host::process::DieWithParentError> {
    // After the flags: a group's own doc would otherwise name the command.
    let command = A::augment_args(clap::Command::new(name)).version(env!("CARGO_PKG_VERSION")).about(about).long_about(None);
    let args = A::from_arg_matches(&command.get_matches()).unwrap_or_else(|e| e.exit());
    crate::host::process::die_with_runner()?;
    Ok(args)
}

/// Writes `<out>/<role>.pid`, so supervisors and tests can find the process.
pub fn write_pid(out: &std::path::Path, role: &str) -> Result<(), PidError> {
    std::fs::create_dir_all(out).map_err(|source| PidError { what: "creating", path: out.to_path_buf(), source })?;
    let path = out.join(format!("{role}.pid"));
    crate::durable::write_whole(&path, std::process::id().to_string().as_bytes()).map_err(|e| PidError { what: "writing", path, source: std::io::Error::other(e) })
}

/// Why a report file was not written.
#[derive(Debug, thiserror::Error)]
pub enum WriteError {
    #[error(transparent)]
    Json(#[from] serde_json::Error),
    #[error("writing {}", .path.display())]
    File {
        path: std::path::PathBuf,
        #[source]
        cause: crate::durable::DurableError,
    },
}

/// Writes `value` as pretty JSON to `path`, whole or not at all (every
/// service's report).
pub fn write_json(path: &std::path::Path, value: &impl serde::Serialize) -> Result<(), WriteError> {
    crate::durable::write_whole(path, &serde_json::to_vec_pretty(value)?).map_err(|cause| WriteError::File { path: path.to_path_buf(), cause })
}

/// Every iceoryx2 port of a run: the frames' own, then each reverse
/// channel's, towards the emulator and away from it.
pub fn ports() -> Vec<crate::transport::Port> {
    use crate::transport::Port;
    let mut ports = vec![Port::CONSOLE, Port::EMULATOR, Port::DIRECT];
    ports.extend(channel::channel_ports());
    ports
}
