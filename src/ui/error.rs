//! Why the UI did not serve, or refused to start a run: each says what it
//! concerned and, in its text, why (the text a page shows as it is).

use std::net::SocketAddr;
use std::path::PathBuf;

/// Why `netfi ui` did not serve, or a run it was asked for did not start.
#[derive(Debug, thiserror::Error)]
pub enum UiError {
    /// The start token, or serving without one.
    #[error(transparent)]
    Guard(#[from] super::guard::GuardError),
    #[error("reading this process's CPU mask: {0}")]
    Mask(std::io::Error),
    /// `--emulator-core` names a core the runs could not be pinned to.
    #[error(transparent)]
    Core(crate::service::args::ArgsError),
    /// Keeping off the emulator's core.
    #[error(transparent)]
    Place(#[from] crate::host::placement::PlaceError),
    #[error("starting the server's runtime: {0}")]
    Runtime(std::io::Error),
    #[error("listening on {addr}: {cause}")]
    Listen { addr: SocketAddr, cause: std::io::Error },
    #[error("serving: {0}")]
    Serve(std::io::Error),
    #[error("creating {}: {cause}", .path.display())]
    Create { path: PathBuf, cause: std::io::Error },
    #[error("writing {}: {cause}", .path.display())]
    Write { path: PathBuf, cause: std::io::Error },
    #[error("reading {}: {cause}", .path.display())]
    Read { path: PathBuf, cause: std::io::Error },
    #[error("starting {}: {cause}", .path.display())]
    Spawn { path: PathBuf, cause: std::io::Error },
    #[error("starting the telemetry thread: {0}")]
    Thread(std::io::Error),
    /// A run's scenario, as the parser says.
    #[error(transparent)]
    Scenario(#[from] crate::scenario::ScenarioError),
    #[error("the duration must be between 0 and 86400 s, got {0}")]
    Duration(f64),
    #[error("{what} `{name}` is not a preset (presets: {})", crate::scenario::PRESET_NAMES.join(", "))]
    NotPreset { what: &'static str, name: String },
    #[error("capture `{0}`: no such file on this host (give the path of an LZ4 ITP capture, or leave it empty for synthetic motion)")]
    NoCapture(String),
    /// The capture given is refused, as the run's console would refuse it
    /// (not a regular file, damaged, more records than the default limit).
    #[error(transparent)]
    Capture(crate::capture::CaptureError),
    /// `netfi run`'s options as its command line reads them (clap's first
    /// paragraph).
    #[error("{0}")]
    RunOptions(String),
    #[error(transparent)]
    Args(#[from] crate::service::args::ArgsError),
    /// A run's report page.
    #[error(transparent)]
    Html(#[from] crate::html::HtmlError),
}
