//! A run's output directory: locked for the run, cleared of an earlier
//! run's marks, the scenarios written for the emulator, and at the end the
//! run's half-created iceoryx2 nodes removed.

use crate::scenario::ScenarioSpec;
use crate::service::plan::{Plan, StreamPlan};
use super::RunnerError;
use std::path::Path;

type Result<T> = std::result::Result<T, RunnerError>;

/// A run's exclusive claim on its output directory: an `flock` on
/// `<out>/run.lock`, held for the runner's life (the kernel lets it go
/// when the runner ends, however it ends). The file holds the owner's pid,
/// so that a refused run can say whose the directory is.
pub struct OutDirLock {
    _file: std::fs::File,
}

/// The lock file in a run's output directory.
pub const LOCK_FILE: &str = "run.lock";

impl OutDirLock {
    /// Takes the lock on `out` (which must exist) without waiting; a
    /// directory another run holds is an error naming it and that run's pid.
    pub fn take(out: &Path) -> Result<OutDirLock> {
        use std::io::{Read, Seek, Write};
        use std::os::fd::AsRawFd;
        let path = out.join(LOCK_FILE);
        // Not truncated on open: until the lock is ours the pid in it is
        // the owner's.
        let mut file = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(&path)
            .map_err(|e| RunnerError::OpenLock(path.clone(), e))?;
        // SAFETY: flock on a descriptor this function owns.
        if unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) } != 0 {
            let err = std::io::Error::last_os_error();
            if err.raw_os_error() == Some(libc::EWOULDBLOCK) {
                let mut text = String::new();
                let _ = file.read_to_string(&mut text);
                let owner = text.trim().parse::<u32>().map_or("unknown".to_string(), |p| p.to_string());
                return Err(RunnerError::InUse { out: out.to_path_buf(), owner });
            }
            return Err(RunnerError::Lock(path, err));
        }
        file.set_len(0).and_then(|_| file.rewind()).and_then(|_| writeln!(file, "{}", std::process::id()))
            .map_err(|e| RunnerError::Write(path.clone(), e))?;
        Ok(OutDirLock { _file: file })
    }
}

/// Readies every stream's directory: created, and the marks an earlier
/// run left there (ready, report and pid files) removed.
pub fn clear_marks(plan: &Plan) -> Result<()> {
    for dir in std::iter::once(&plan.out).chain(plan.streams.iter().map(|s| &s.out)) {
        std::fs::create_dir_all(dir).map_err(|e| RunnerError::Create(dir.clone(), e))?;
        for role in ["console", "emulator", "simulator"] {
            for ext in ["ready", "json", "pid"] {
                let _ = std::fs::remove_file(dir.join(format!("{role}.{ext}")));
            }
        }
    }
    Ok(())
}

/// Writes the scenario the emulator is to apply into a file of this run's
/// own, created exclusively (`scenario.<run id>.toml`, read-only): no other
/// run can have written or can overwrite it. `scenario.toml` beside it is
/// the copy kept for people.
fn write_run_scenario(spec: &ScenarioSpec, path: &Path, own: &Path) -> Result<()> {
    use std::io::Write;
    use std::os::unix::fs::OpenOptionsExt;
    let toml = spec.to_toml();
    std::fs::write(path, &toml).map_err(|e| RunnerError::Write(path.to_path_buf(), e))?;
    // A file left by an earlier run with this run id (given with --run-id).
    let _ = std::fs::remove_file(own);
    let mut f = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .mode(0o444)
        .open(own)
        .map_err(|e| RunnerError::Create(own.to_path_buf(), e))?;
    f.write_all(toml.as_bytes()).and_then(|_| f.sync_all()).map_err(|e| RunnerError::Write(own.to_path_buf(), e))
}

/// Writes every stream's scenario where the plan told the emulator to read it.
pub fn write_scenarios(streams: &[StreamPlan]) -> Result<()> {
    streams.iter().try_for_each(|s| write_run_scenario(&s.spec, &s.scenario_path, &s.own_scenario))
}

/// Removes the emulator's own copies once it has read them (the ones kept
/// are `scenario.toml`).
pub fn remove_own_scenarios(streams: &[StreamPlan]) {
    for s in streams {
        let _ = std::fs::remove_file(&s.own_scenario);
    }
}

/// Once every process of the run has ended: removes the nodes of the
/// runs `run_ids` in iceoryx2's node directory `nodes` that a process left
/// half created (its node's details written, its monitor not: killed, or
/// stopped while iceoryx2 synced the details to a busy disk). iceoryx2
/// neither lists nor cleans such a node; a node alive or killed later on
/// has its monitor, and is left to the reaping of dead peers.
pub fn remove_half_created_nodes(nodes: &Path, run_ids: &[&str]) {
    use crate::transport::{IpcConfig, RunId};
    let prefixes: Vec<String> = run_ids.iter().filter_map(|r| RunId::new(r).ok()).map(|r| IpcConfig::new(r).prefix().to_string()).collect();
    let Ok(rd) = std::fs::read_dir(nodes) else { return };
    for e in rd.filter_map(|e| e.ok()) {
        let id = e.file_name().to_string_lossy().into_owned();
        let half = |p: &String| e.path().join(format!("{p}node.details")).exists() && !nodes.join(format!("{p}{id}.node_monitor")).exists();
        if e.file_type().is_ok_and(|t| t.is_dir()) && prefixes.iter().any(half) && std::fs::remove_dir_all(e.path()).is_ok() {
            eprintln!("removed the half-created iceoryx2 node {id} of a process of this run");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_the_runs_half_created_nodes_are_removed() {
        let nodes = std::env::temp_dir().join(format!("netfi-half-nodes-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&nodes);
        let prefix = |run: &str| crate::transport::IpcConfig::new(crate::transport::RunId::new(run).unwrap()).prefix().to_string();
        let node = |id: &str, run: &str, monitor: bool| {
            std::fs::create_dir_all(nodes.join(id)).unwrap();
            std::fs::write(nodes.join(id).join(format!("{}node.details", prefix(run))), b"").unwrap();
            if monitor {
                std::fs::write(nodes.join(format!("{}{id}.node_monitor", prefix(run))), b"").unwrap();
            }
        };
        node("11", "r1", false);
        node("12", "r1-s1", false);
        node("13", "r1", true);
        node("14", "r2", false);
        remove_half_created_nodes(&nodes, &["r1", "r1-s1"]);
        let left = |id: &str| nodes.join(id).exists();
        assert!(!left("11") && !left("12"), "the run's half-created nodes stay");
        assert!(left("13"), "a node with its monitor is not this function's");
        assert!(left("14"), "another run's node was removed");
        std::fs::remove_dir_all(&nodes).unwrap();
    }
}
