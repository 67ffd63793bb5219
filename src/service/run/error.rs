//! Why `netfi run` did not run to its report: each step's failure, and
//! what it concerned (a flag's scenario, a stream, a file, a process).

use crate::scenario::ScenarioError;
use crate::service::args::ArgsError;
use std::path::PathBuf;
use std::time::Duration;

/// Why a run did not start (or its runner gave up on a process).
#[derive(Debug, thiserror::Error)]
pub enum RunnerError {
    #[error(transparent)]
    Args(#[from] ArgsError),
    /// Shared-memory files already bear the run's names.
    #[error("run id `{run_id}`: /dev/shm holds {} file(s) with its names that another user made first ({}); choose another --run-id", files.len(), files.iter().take(3).cloned().collect::<Vec<_>>().join(", "))]
    NamesTaken { run_id: String, files: Vec<String> },
    /// The run's own scenario.
    #[error(transparent)]
    Scenario(#[from] ScenarioError),
    #[error(transparent)]
    PathScenario(#[from] crate::service::emulator::opening::PathScenarioError),
    #[error("--stream-scenario {stream}={what}")]
    StreamScenario {
        stream: usize,
        what: String,
        #[source]
        cause: ScenarioError,
    },
    /// A stream's scenario with its seed.
    #[error("the scenario of stream {0}")]
    StreamSeed(usize, #[source] ScenarioError),
    #[error("the run id of stream {0}")]
    StreamRunId(usize, #[source] crate::transport::RunIdError),
    /// The runner kept off the emulator's core.
    #[error(transparent)]
    Place(#[from] crate::host::placement::PlaceError),
    /// What earlier runs left in shared memory.
    #[error(transparent)]
    Cleanup(#[from] crate::transport::CleanupError),
    #[error("creating {}", .0.display())]
    Create(PathBuf, #[source] std::io::Error),
    #[error("writing {}", .0.display())]
    Write(PathBuf, #[source] std::io::Error),
    #[error("opening {}", .0.display())]
    OpenLock(PathBuf, #[source] std::io::Error),
    #[error("locking {}", .0.display())]
    Lock(PathBuf, #[source] std::io::Error),
    /// The output directory cannot be opened as one (a symbolic link at
    /// its name is refused).
    #[error("the output directory {}", .0.display())]
    OutDir(PathBuf, #[source] std::io::Error),
    /// The output directory is another user's, or inside one: that user
    /// could plant files or links in it.
    #[error("the output directory {}: {what} uid {uid}, not this user (uid {me}): its owner could plant files or links where the run writes; give a directory of your own, or --out-owned-by-other if this one is meant", .dir.display())]
    OwnedByOther { dir: PathBuf, what: &'static str, uid: u32, me: u32 },
    #[error("the output directory {} is in use by another netfi run (pid {owner}); wait for it to end or give another --out", .out.display())]
    InUse { out: PathBuf, owner: String },
    #[error("locating the netfi executable")]
    Exe(#[source] std::io::Error),
    #[error("starting the {role} ({})", .exe.display())]
    Spawn {
        role: &'static str,
        exe: PathBuf,
        #[source]
        cause: std::io::Error,
    },
    /// A process that ended before its ready file, with its log's tail.
    #[error("the {role} ended before it was ready ({status}):\n{log}")]
    EndedEarly { role: &'static str, status: String, log: String },
    #[error("the {role} was not ready after {after:?}:\n{log}")]
    NotReady { role: &'static str, after: Duration, log: String },
}
