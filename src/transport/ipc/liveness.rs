//! Peer liveness: finding the nodes of a run whose process died and removing
//! what they left behind.
//!
//! iceoryx2 marks each node with a file lock held by its process; the lock
//! disappears with the process however it ends, so a node whose lock is gone
//! is dead. Removing a dead node deregisters its ports from the channels,
//! which is what lets a restarted console or simulator open its port again
//! and what makes the survivors' `peers_connected` drop.

use core::time::Duration;

use iceoryx2::node::{NodeCleanupFailure, NodeListFailure, NodeView};
use iceoryx2::prelude::{CallbackProgression, Node, NodeState};

use super::{init_log_level, user_prefix, Ipc, IpcConfig, Role, RunId, FILE_PREFIX};

/// Longest wait for another process, or thread, that is removing a dead node
/// at the same time; only spent when that happens.
const CONCURRENT_CLEANUP_WAIT: Duration = Duration::from_millis(100);

/// A node of the run whose process is gone.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DeadPeer {
    /// Its role, when its node name is one of this run's.
    pub role: Option<Role>,
    /// Its node name, empty when its details were unreadable.
    pub node_name: String,
    /// The process id it had, when its details were readable.
    pub pid: Option<i32>,
    /// The executable it ran, when its details were readable.
    pub executable: Option<String>,
}

impl core::fmt::Display for DeadPeer {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self.role {
            Some(role) => write!(f, "{role}")?,
            None if self.node_name.is_empty() => f.write_str("unnamed node")?,
            None => write!(f, "node `{}`", self.node_name)?,
        }
        match (&self.executable, self.pid) {
            (Some(exe), Some(pid)) => write!(f, " ({exe}, pid {pid})"),
            (None, Some(pid)) => write!(f, " (pid {pid})"),
            _ => Ok(()),
        }
    }
}

/// A dead node whose resources could not be removed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FailedCleanup {
    /// The dead node.
    pub peer: DeadPeer,
    /// Why its resources stay (iceoryx2's reason, in words).
    pub reason: String,
}

/// What one scan of a run found.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct CleanupReport {
    /// Dead nodes whose resources are gone after this call, removed by it or
    /// by another process scanning at the same time: processes that reap
    /// concurrently may each report the same dead peer.
    pub removed: Vec<DeadPeer>,
    /// Dead nodes whose resources could not be removed; the next scan
    /// tries again.
    pub failed: Vec<FailedCleanup>,
    /// Live nodes of the run, the caller's own included.
    pub alive: usize,
    /// Nodes whose state could not be determined: not accessible to this
    /// user, or half created or half removed.
    pub undetermined: usize,
}

impl CleanupReport {
    /// All dead nodes found, removed or not.
    pub fn dead(&self) -> impl Iterator<Item = &DeadPeer> {
        self.removed
            .iter()
            .chain(self.failed.iter().map(|f| &f.peer))
    }

    /// Whether no dead node was found.
    pub fn is_clean(&self) -> bool {
        self.dead().next().is_none()
    }
}

/// Why the nodes of a run could not be scanned.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CleanupError {
    /// This user may not list or inspect the run's node files (the run was
    /// started by another user).
    #[error("cannot scan the nodes of run `{run}` for dead peers: insufficient permissions on iceoryx2's node directory")]
    InsufficientPermissions {
        /// The run.
        run: String,
    },
    /// A signal interrupted the scan; calling again is safe.
    #[error("scanning the nodes of run `{run}` for dead peers was interrupted by a signal")]
    Interrupted {
        /// The run.
        run: String,
    },
    /// iceoryx2 failed internally while listing the nodes.
    #[error("cannot scan the nodes of run `{run}` for dead peers: iceoryx2 failed internally ({detail})")]
    Internal {
        /// The run.
        run: String,
        /// iceoryx2's failure.
        detail: String,
    },
}

/// Removes the resources of every dead node of the run of `config`, for
/// instance those left by a console killed in an earlier session with the
/// same run id. Needs no node of its own; [`IpcNode::open`] calls it first.
///
/// [`IpcNode::open`]: super::IpcNode::open
pub fn cleanup_dead_nodes(config: &IpcConfig) -> Result<CleanupReport, CleanupError> {
    init_log_level();
    let run = || config.run_id().to_string();
    let mut report = CleanupReport::default();
    let mut dead = Vec::new();
    Node::<Ipc>::list(config.iceoryx2(), |state| {
        match state {
            NodeState::Alive(_) => report.alive += 1,
            NodeState::Dead(view) => dead.push(view),
            NodeState::Inaccessible(_) | NodeState::Undefined(_) => report.undetermined += 1,
        }
        CallbackProgression::Continue
    })
    .map_err(|e| match e {
        NodeListFailure::InsufficientPermissions => {
            CleanupError::InsufficientPermissions { run: run() }
        }
        NodeListFailure::Interrupt => CleanupError::Interrupted { run: run() },
        NodeListFailure::InternalError => CleanupError::Internal {
            run: run(),
            detail: format!("{e:?}"),
        },
    })?;

    for view in dead {
        let peer = describe(config, view.details());
        if view.details().is_none() {
            // Removal without details would make iceoryx2 fall back to its
            // file-based global configuration; leave such a node alone.
            report.failed.push(FailedCleanup {
                peer,
                reason: "its node details are unreadable, so its resources cannot be located"
                    .to_owned(),
            });
            continue;
        }
        // Waits while another process, or another thread of this one (iceoryx2
        // removes one node at a time per process), is removing a dead node;
        // returns at once when it is already gone.
        match view.blocking_remove_stale_resources(CONCURRENT_CLEANUP_WAIT) {
            Ok(()) => report.removed.push(peer),
            Err(e) => report.failed.push(FailedCleanup {
                peer,
                reason: cleanup_failure_reason(e).to_owned(),
            }),
        }
    }
    Ok(report)
}

/// Runs [`cleanup_dead_nodes`] for every netfi run with node files on this
/// host for which `select` returns true (`|_| true`: all of them), whatever
/// its run id. What processes of earlier runs left when they were killed is
/// removed (each killed publisher leaves its shared-memory pool behind,
/// several MiB); live nodes are only listed. Returns one report per run
/// scanned, in run id order.
///
/// Meant for start-up or a `clean` command, not for the service loop: it
/// reads iceoryx2's whole node directory.
pub fn cleanup_dead_runs(
    mut select: impl FnMut(&RunId) -> bool,
) -> Result<Vec<(RunId, CleanupReport)>, CleanupError> {
    init_log_level();
    let any = IpcConfig::new(RunId::new("any").expect("a valid run id"));
    let node_dir = any.iceoryx2().global.node_dir();
    let monitor_suffix = any.iceoryx2().global.node.monitor_suffix;
    // Management segments of runs with no node left (killed runs, or
    // earlier versions of netfi), older than a minute so that a run just
    // starting is not touched.
    remove_stale_mgmt_segments();
    let entries = match std::fs::read_dir(node_dir.as_str()) {
        Ok(entries) => entries,
        // No node was ever created on this host.
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(list_error("every run", &e)),
    };
    let mut runs = std::collections::BTreeMap::new();
    for entry in entries {
        let entry = entry.map_err(|e| list_error("every run", &e))?;
        let name = entry.file_name();
        if let Some(run) = name
            .to_str()
            .and_then(|n| run_of_monitor_file(n, monitor_suffix.as_str()))
        {
            runs.entry(run.as_str().to_owned()).or_insert(run);
        }
    }
    runs.into_values()
        .filter(|run| select(run))
        .map(|run| {
            let config = IpcConfig::new(run.clone());
            let report = cleanup_dead_nodes(&config)?;
            // A run whose processes were all killed: its management segment
            // goes with its last node.
            if report.alive == 0 && report.undetermined == 0 {
                remove_mgmt_segment_if_unused(&config);
            }
            Ok((run, report))
        })
        .collect()
}

/// The run id in a node monitor file name
/// `netfi_<run>_<node id><suffix>`, if it is one.
fn run_of_monitor_file(file_name: &str, suffix: &str) -> Option<RunId> {
    let middle = file_name.strip_prefix(&user_prefix())?.strip_suffix(suffix)?;
    let (run, node_id) = middle.rsplit_once('_')?;
    if node_id.is_empty() || !node_id.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    RunId::new(run).ok()
}

/// The suffix iceoryx2 gives its per-prefix management segment.
const MGMT_SUFFIX: &str = ".global_mgmt";

/// Removes the management segment of run `run` when no node of it is left.
/// For a process that watched a run's other processes end: each node's drop
/// already tries, but nodes of two processes dropped at the same moment
/// each see the other still there, and the segment stays.
pub fn remove_run_segment_if_unused(run: &RunId) {
    remove_mgmt_segment_if_unused(&IpcConfig::new(run.clone()));
}

/// Removes the management segment of the run of `config` when no node of
/// the run is left (alive or undetermined).
pub(super) fn remove_mgmt_segment_if_unused(config: &IpcConfig) {
    let mut in_use = 0usize;
    let listed = Node::<Ipc>::list(config.iceoryx2(), |state| {
        if !matches!(state, NodeState::Dead(_)) {
            in_use += 1;
        }
        CallbackProgression::Continue
    });
    if listed.is_err() || in_use > 0 {
        return;
    }
    remove_shm(|name| name.starts_with(config.prefix()) && name.ends_with(MGMT_SUFFIX), None);
}

/// Removes this user's management segments of netfi runs that have no node
/// files, modified more than a minute ago.
fn remove_stale_mgmt_segments() {
    let any = IpcConfig::new(RunId::new("any").expect("a valid run id"));
    let node_dir = any.iceoryx2().global.node_dir();
    let live: Vec<String> = std::fs::read_dir(node_dir.as_str())
        .map(|rd| rd.filter_map(|e| e.ok()?.file_name().into_string().ok()).collect())
        .unwrap_or_default();
    let mine = user_prefix();
    remove_shm(
        |name| {
            name.starts_with(FILE_PREFIX)
                && name.ends_with(MGMT_SUFFIX)
                // This user's runs whose nodes are all gone, or the
                // unnamed-per-user files of earlier versions.
                && match name.strip_prefix(&mine) {
                    Some(rest) => {
                        let run_prefix = &name[..mine.len() + rest.find('_').map_or(rest.len(), |i| i + 1)];
                        !live.iter().any(|f| f.starts_with(run_prefix))
                    }
                    None => !name.starts_with("netfi_u") && !legacy_run_alive(name),
                }
        },
        Some(std::time::Duration::from_secs(60)),
    );
}

/// Whether an earlier version's run (files `netfi_<run>_…` under iceoryx2's
/// shared `/tmp/iceoryx2/`) named by the segment `name` still has node
/// files.
fn legacy_run_alive(name: &str) -> bool {
    let Some(rest) = name.strip_prefix(FILE_PREFIX) else { return false };
    let run_prefix = &name[..FILE_PREFIX.len() + rest.find('_').map_or(rest.len(), |i| i + 1)];
    let legacy = iceoryx2::config::Config::default().global.node_dir();
    std::fs::read_dir(legacy.as_str())
        .map(|rd| rd.filter_map(|e| e.ok()?.file_name().into_string().ok()).any(|f| f.starts_with(run_prefix)))
        .unwrap_or(false)
}

/// Removes this user's files in `/dev/shm` whose names `select` picks,
/// modified at least `older_than` ago when given.
fn remove_shm(select: impl Fn(&str) -> bool, older_than: Option<std::time::Duration>) {
    use std::os::unix::fs::MetadataExt;
    // SAFETY: geteuid has no preconditions.
    let uid = unsafe { libc::geteuid() };
    let Ok(rd) = std::fs::read_dir(SHM_DIR) else { return };
    for e in rd.filter_map(|e| e.ok()) {
        let Some(name) = e.file_name().to_str().map(str::to_owned) else { continue };
        if !select(&name) {
            continue;
        }
        let Ok(meta) = std::fs::symlink_metadata(e.path()) else { continue };
        let old_enough = older_than.is_none_or(|d| meta.modified().ok().and_then(|m| m.elapsed().ok()).is_some_and(|age| age >= d));
        if meta.is_file() && meta.uid() == uid && old_enough {
            let _ = std::fs::remove_file(e.path());
        }
    }
}

/// How long the files of a run must have been left untouched before they
/// are taken for a dead run's, unless its dead nodes were just seen: a
/// process that is starting creates files before its node can be seen.
const UNSEEN_RUN_AGE: std::time::Duration = std::time::Duration::from_secs(10);

/// Removes what this user's runs picked by `select` left in `/dev/shm` and
/// under the root directory once their processes are all dead: their
/// dead nodes first ([`cleanup_dead_nodes`]), then every file of theirs
/// that iceoryx2 does not remove (segments of no node, half-created nodes,
/// services whose nodes are gone). A run counts as dead when no node of it
/// is alive or undetermined, and either dead nodes of it were found now or
/// none of its files changed in the last 10 s (a process of the run may be
/// creating its node). Call it before any other clean-up of dead nodes,
/// which would hide that the run's processes died. Returns each run swept
/// with the files removed.
pub fn remove_dead_run_files(mut select: impl FnMut(&RunId) -> bool) -> Result<Vec<(RunId, usize)>, CleanupError> {
    init_log_level();
    let any = IpcConfig::new(RunId::new("any").expect("a valid run id"));
    let (nodes, services) = (std::path::PathBuf::from(any.iceoryx2().global.node_dir().as_str()), std::path::PathBuf::from(any.iceoryx2().global.service_dir().as_str()));
    let files: Vec<std::path::PathBuf> = [std::path::Path::new(SHM_DIR), &services, &nodes]
        .iter()
        .flat_map(|d| std::fs::read_dir(d).into_iter().flatten().filter_map(|e| e.ok().map(|e| e.path())))
        .chain(node_files(&nodes))
        .collect();
    let mut runs = std::collections::BTreeMap::new();
    for f in &files {
        if let Some(run) = f.file_name().and_then(|n| n.to_str()).and_then(run_of_file) {
            runs.entry(run.as_str().to_owned()).or_insert(run);
        }
    }
    let mut swept = Vec::new();
    for run in runs.into_values().filter(|r| select(r)) {
        let config = IpcConfig::new(run.clone());
        let report = cleanup_dead_nodes(&config)?;
        let mine: Vec<&std::path::PathBuf> = files.iter().filter(|f| f.exists() && owned_member(f, config.prefix())).collect();
        let young = |f: &std::path::Path| std::fs::symlink_metadata(f).ok().and_then(|m| m.modified().ok()?.elapsed().ok()).is_none_or(|age| age < UNSEEN_RUN_AGE);
        if report.alive > 0 || report.undetermined > 0 || (report.is_clean() && mine.iter().any(|f| young(f))) {
            continue;
        }
        let removed = mine.iter().filter(|f| remove_member(f, &nodes)).count();
        if removed > 0 {
            swept.push((run, removed));
        }
    }
    Ok(swept)
}

/// The files in each node directory under `nodes`.
fn node_files(nodes: &std::path::Path) -> Vec<std::path::PathBuf> {
    let Ok(rd) = std::fs::read_dir(nodes) else { return Vec::new() };
    rd.filter_map(|e| e.ok())
        .filter(|e| e.file_type().is_ok_and(|t| t.is_dir()))
        .flat_map(|e| std::fs::read_dir(e.path()).into_iter().flatten().filter_map(|f| f.ok().map(|f| f.path())))
        .collect()
}

/// The run of one of this user's iceoryx2 file names: `<prefix><hash>_…`,
/// `<prefix><hash>.…` (segments, services), `<prefix><id>.node_monitor…`,
/// `<prefix>node.details`, where the prefix is `netfi_u<uid>_<run>_`.
fn run_of_file(name: &str) -> Option<RunId> {
    let rest = name.strip_prefix(&user_prefix())?;
    (1..rest.len()).filter(|&i| rest.as_bytes()[i] == b'_').find_map(|i| {
        let run = RunId::new(&rest[..i]).ok()?;
        member_rest(&rest[i + 1..]).then_some(run)
    })
}

/// Whether `rest`, what follows a run's prefix, is one of iceoryx2's names.
fn member_rest(rest: &str) -> bool {
    let hash = rest.len() > 40 && rest.as_bytes()[..40].iter().all(u8::is_ascii_hexdigit) && matches!(rest.as_bytes()[40], b'_' | b'.');
    let digits = rest.find('.').is_some_and(|i| i > 0 && rest.as_bytes()[..i].iter().all(u8::is_ascii_digit));
    hash || digits || rest == "node.details"
}

/// Whether `path` is a file of the run with `prefix` that this user owns.
fn owned_member(path: &std::path::Path, prefix: &str) -> bool {
    use std::os::unix::fs::MetadataExt;
    let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
    // SAFETY: geteuid has no preconditions.
    let uid = unsafe { libc::geteuid() };
    name.strip_prefix(prefix).is_some_and(member_rest) && std::fs::symlink_metadata(path).is_ok_and(|m| m.uid() == uid)
}

/// Removes one file of a dead run, and the node directory it leaves
/// empty; a node's details go with the node's whole directory (one node's,
/// so one run's). Whether it went.
fn remove_member(path: &std::path::Path, nodes: &std::path::Path) -> bool {
    let Some(dir) = path.parent().filter(|d| d.parent() == Some(nodes)) else { return std::fs::remove_file(path).is_ok() };
    if path.to_str().is_some_and(|p| p.ends_with("node.details")) {
        return std::fs::remove_dir_all(dir).is_ok();
    }
    let removed = std::fs::remove_file(path).is_ok();
    // Fails, as it should, while anything is left in it.
    let _ = std::fs::remove_dir(dir);
    removed
}

fn list_error(run: &str, e: &std::io::Error) -> CleanupError {
    match e.kind() {
        std::io::ErrorKind::PermissionDenied => CleanupError::InsufficientPermissions {
            run: run.to_owned(),
        },
        std::io::ErrorKind::Interrupted => CleanupError::Interrupted {
            run: run.to_owned(),
        },
        _ => CleanupError::Internal {
            run: run.to_owned(),
            detail: e.to_string(),
        },
    }
}

pub(super) fn describe(config: &IpcConfig, details: &Option<iceoryx2::node::NodeDetails>) -> DeadPeer {
    match details {
        Some(d) => {
            let node_name = d.name().as_str().to_owned();
            DeadPeer {
                role: config.role_of_node_name(&node_name),
                node_name,
                pid: Some(d.process_id().value()),
                executable: Some(d.executable().as_str().to_owned()),
            }
        }
        None => DeadPeer {
            role: None,
            node_name: String::new(),
            pid: None,
            executable: None,
        },
    }
}

fn cleanup_failure_reason(e: NodeCleanupFailure) -> &'static str {
    match e {
        NodeCleanupFailure::Interrupt => "interrupted by a signal; the next scan retries",
        NodeCleanupFailure::InternalError => "iceoryx2 failed internally while removing it",
        NodeCleanupFailure::InsufficientPermissions => {
            "insufficient permissions to remove its files (started by another user?)"
        }
        NodeCleanupFailure::VersionMismatch => {
            "it was created by another iceoryx2 version; remove its files by hand"
        }
        NodeCleanupFailure::ResourcesAlreadyCleanedUp => "another process removed it",
        NodeCleanupFailure::AnotherInstanceIsCleaningUpTheNode => {
            "another process is still removing it"
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn monitor_file_names_yield_their_run() {
        let suffix = ".node_monitor";
        let p = user_prefix();
        let run = |n: &str| run_of_monitor_file(&n.replacen("netfi_", &p, 1), suffix).map(|r| r.as_str().to_owned());
        assert_eq!(run("netfi_r1_123.node_monitor").as_deref(), Some("r1"));
        assert_eq!(run("netfi_a_b-c_9.node_monitor").as_deref(), Some("a_b-c"));
        assert_eq!(run("netfi__9.node_monitor"), None);
        assert_eq!(run("netfi_r1_12x.node_monitor"), None);
        assert_eq!(run("netfi_r1_.node_monitor"), None);
        assert_eq!(run("iox2_123.node_monitor"), None);
        // Another user's files are not this user's runs.
        assert_eq!(run_of_monitor_file("netfi_u4294967294_r1_1.node_monitor", suffix), None);
        assert_eq!(run("netfi_r1_123.details"), None);
    }

    /// A run's files are told from those of a run whose id extends it.
    #[test]
    fn file_names_yield_their_run_exactly() {
        let p = user_prefix();
        let hash = "0123456789abcdef0123456789abcdef01234567";
        let run = |n: String| run_of_file(&n).map(|r| r.as_str().to_owned());
        assert_eq!(run(format!("{p}a_{hash}_15.data")).as_deref(), Some("a"));
        assert_eq!(run(format!("{p}a_b_{hash}_15.data")).as_deref(), Some("a_b"));
        assert_eq!(run(format!("{p}a_b_{hash}.service")).as_deref(), Some("a_b"));
        assert_eq!(run(format!("{p}a_12_34.node_monitor_context")).as_deref(), Some("a_12"));
        assert_eq!(run(format!("{p}r-1_node.details")).as_deref(), Some("r-1"));
        assert_eq!(run(format!("{p}r1_whatever")), None);
        assert_eq!(run(format!("netfi_u4294967294_r1_{hash}_1.data")), None);
        // Run `a` does not claim the files of run `a_b`.
        assert!(!owned_member(std::path::Path::new(&format!("/nonexistent/{p}a_b_{hash}_1.data")), &format!("{p}a_")));
    }
}

/// Where POSIX shared memory lives on Linux.
pub(super) const SHM_DIR: &str = "/dev/shm";
