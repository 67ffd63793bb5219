//! Opening this process's iceoryx2 node in a run, and clearing what
//! killed processes of earlier runs left. A lane's transports are opened
//! by the registry ([`super::open`]).

use crate::transport::{CleanupError, IpcConfig, IpcNode, NodeOpenError, Role, RunId, RunIdError};

/// Why this process's iceoryx2 node could not be opened.
#[derive(Debug, thiserror::Error)]
pub enum NodeError {
    /// The run id is not one netfi accepts.
    #[error("run id `{run_id}`: {source}")]
    RunId {
        /// What was given.
        run_id: String,
        /// What is wrong with it.
        #[source]
        source: RunIdError,
    },
    /// iceoryx2 refused the node.
    #[error("opening the {role} node of run `{run_id}`: {source}")]
    Open {
        /// The process's role.
        role: Role,
        /// The run.
        run_id: String,
        /// Why.
        #[source]
        source: NodeOpenError,
    },
}

/// Opens this process's node in run `run_id`.
pub fn open_node(run_id: &str, role: Role) -> Result<IpcNode, NodeError> {
    let run = RunId::new(run_id).map_err(|source| NodeError::RunId { run_id: run_id.to_string(), source })?;
    IpcNode::open(&IpcConfig::new(run), role).map_err(|source| NodeError::Open { role, run_id: run_id.to_string(), source })
}

/// Removes what killed processes of earlier runs left on this host; returns
/// how many dead nodes were removed.
pub fn cleanup_stale() -> Result<usize, CleanupError> {
    let reports = crate::transport::cleanup_dead_runs(|_| true)?;
    Ok(reports.iter().map(|(_, r)| r.removed.len()).sum())
}

/// The shared-memory files with run `run_id`'s names that another user
/// made first (the names carry this user's uid: only a stranger planting
/// them makes such a file someone else's). A run refuses to start over
/// them. This user's own (the lab's programs joining the run, which may
/// start first) are the run's.
pub fn names_taken(run_id: &str) -> Vec<String> {
    use std::os::unix::fs::MetadataExt;
    // SAFETY: geteuid has no preconditions and cannot fail.
    let me = unsafe { libc::geteuid() };
    let Ok(run) = RunId::new(run_id) else { return Vec::new() };
    let config = IpcConfig::new(run);
    let prefix = config.prefix();
    let Ok(entries) = std::fs::read_dir("/dev/shm") else { return Vec::new() };
    let mut taken: Vec<String> = entries.filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().starts_with(prefix))
        .filter_map(|e| std::fs::symlink_metadata(e.path()).ok().filter(|m| m.uid() != me).map(|m| format!("{} belongs to uid {}", e.file_name().to_string_lossy(), m.uid())))
        .collect();
    taken.sort();
    taken
}
