//! A run's output directory: refused when another user's, locked for the
//! run, cleared of an earlier run's marks (its report replaced is said),
//! marked unfinished until the run's report is written, the scenarios
//! written for the emulator, and at the end the run's half-created
//! iceoryx2 nodes removed. Every file here is opened relative to the
//! directory, never through a symbolic link ([`crate::durable`]).

use crate::durable::Dir;
use crate::scenario::ScenarioSpec;
use crate::service::plan::{Plan, StreamPlan};
use crate::service::report::files::UNFINISHED_MARK;
use super::RunnerError;
use std::os::unix::fs::MetadataExt;
use std::path::{Path, PathBuf};

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
    /// Takes the lock in `out` without waiting; a directory another run
    /// holds is an error naming it and that run's pid. A symbolic link at
    /// the lock's name is refused, not followed.
    pub fn take(out: &Dir) -> Result<OutDirLock> {
        use std::io::{Read, Seek, Write};
        use std::os::fd::AsRawFd;
        let path = out.join(LOCK_FILE);
        // Not truncated on open: until the lock is ours the pid in it is
        // the owner's.
        let mut file = out.open_or_create(LOCK_FILE.as_ref(), crate::durable::FILE_MODE).map_err(|e| RunnerError::OpenLock(path.clone(), e))?;
        // SAFETY: flock on a descriptor this function owns.
        if unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) } != 0 {
            let err = std::io::Error::last_os_error();
            if err.raw_os_error() == Some(libc::EWOULDBLOCK) {
                let mut text = String::new();
                let _ = (&mut file).take(64).read_to_string(&mut text);
                let owner = text.trim().parse::<u32>().map_or("unknown".to_string(), |p| p.to_string());
                return Err(RunnerError::InUse { out: out.path().to_path_buf(), owner });
            }
            return Err(RunnerError::Lock(path, err));
        }
        file.set_len(0).and_then(|_| file.rewind()).and_then(|_| writeln!(file, "{}", std::process::id()))
            .map_err(|e| RunnerError::Write(path.clone(), e))?;
        Ok(OutDirLock { _file: file })
    }
}

/// The user this process acts as.
fn euid() -> u32 {
    // SAFETY: geteuid has no preconditions.
    unsafe { libc::geteuid() }
}

/// Opens the run's output directory `out` (never through a symbolic link
/// at its name) and checks whose it is: a directory of another user, or
/// one inside a directory of another user but root, could have files or
/// links planted in it by that user, and is refused unless `other_owner`
/// says it is meant.
pub fn open_checked(out: &Path, other_owner: bool) -> Result<Dir> {
    let dir = Dir::open(out).map_err(|e| RunnerError::OutDir(out.to_path_buf(), e))?;
    if other_owner {
        return Ok(dir);
    }
    let me = euid();
    let uid = dir.metadata().map_err(|e| RunnerError::OutDir(out.to_path_buf(), e))?.uid();
    if uid != me {
        return Err(RunnerError::OwnedByOther { dir: out.to_path_buf(), what: "it belongs to", uid, me });
    }
    let parent = match out.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    if let Ok(m) = std::fs::metadata(&parent) {
        if m.uid() != me && m.uid() != 0 {
            return Err(RunnerError::OwnedByOther { dir: out.to_path_buf(), what: "it lies in a directory of", uid: m.uid(), me });
        }
    }
    Ok(dir)
}

/// A run's directories (its own; each stream's), each opened once.
pub struct Dirs(Vec<Dir>);

impl Dirs {
    /// Creates each stream's directory in the run's `out` and opens every
    /// one (a symbolic link among them is refused).
    pub fn open(plan: &Plan, out: Dir) -> Result<Dirs> {
        let mut dirs = vec![out];
        for s in plan.streams.iter().filter(|s| s.out != plan.out) {
            std::fs::create_dir_all(&s.out).map_err(|e| RunnerError::Create(s.out.clone(), e))?;
            dirs.push(Dir::open(&s.out).map_err(|e| RunnerError::OutDir(s.out.clone(), e))?);
        }
        Ok(Dirs(dirs))
    }

    /// Readies every directory: the marks an earlier run left there
    /// (ready, report and pid files) removed, and its report, replaced,
    /// said: the notes for the run's report (also on stderr). Each is
    /// then marked unfinished until [`Dirs::finished`].
    pub fn clear_and_mark(&self, run_id: &str) -> Result<Vec<String>> {
        let mut notes = Vec::new();
        for dir in &self.0 {
            for role in ["console", "emulator", "simulator"] {
                for ext in ["ready", "json", "pid"] {
                    let _ = dir.remove(format!("{role}.{ext}").as_ref());
                }
            }
            if let Some(note) = earlier_report(dir) {
                eprintln!("note: {note}");
                notes.push(note);
            }
            for name in ["report.json", "report.json.partial"] {
                dir.remove(name.as_ref()).map_err(|e| RunnerError::Create(dir.join(name), e))?;
            }
            let said = format!("netfi run {run_id}, runner pid {}", std::process::id());
            crate::durable::write_whole(&dir.join(UNFINISHED_MARK), format!("{said}\n").as_bytes())
                .map_err(|e| RunnerError::Write(dir.join(UNFINISHED_MARK), std::io::Error::other(e)))?;
        }
        Ok(notes)
    }

    /// Removes the unfinished marks: the runner has come to the run's end
    /// (its report written, or its failure to be written among its
    /// faults). A mark that cannot be removed is said.
    pub fn finished(&self) {
        for dir in &self.0 {
            if let Err(e) = dir.remove(UNFINISHED_MARK.as_ref()) {
                eprintln!("WARNING: {} not removed: {e}; `netfi report` will take the run as unfinished", dir.join(UNFINISHED_MARK).display());
            }
        }
    }
}

/// What to say of an earlier run's report in `dir`, if one is there.
fn earlier_report(dir: &Dir) -> Option<String> {
    use std::io::Read;
    let name: &std::ffi::OsStr = "report.json".as_ref();
    dir.entry(name).ok()??;
    // Only the run's id is read from it, never through a link.
    let mut text = String::new();
    let run = dir.open_read(name).ok().and_then(|f| f.take(1 << 24).read_to_string(&mut text).ok()).and_then(|_| {
        let v: serde_json::Value = serde_json::from_str(&text).ok()?;
        v.get("run_id")?.as_str().map(str::to_string)
    });
    let which = run.map_or("an earlier run".to_string(), |r| format!("earlier run {r}"));
    Some(format!("{} held the report of {which}: replaced by this run's", dir.join(name).display()))
}

/// Writes the scenario the emulator is to apply into a file of this run's
/// own (`scenario.<run id>.toml`, read-only), whatever was at its name
/// before removed, never followed: no other run can have written or can
/// overwrite it. `scenario.toml` beside it is the copy kept for people.
fn write_run_scenario(spec: &ScenarioSpec, path: &Path, own: &Path) -> Result<()> {
    let toml = spec.to_toml();
    crate::durable::write_whole(path, toml.as_bytes()).map_err(|e| RunnerError::Write(path.to_path_buf(), std::io::Error::other(e)))?;
    crate::durable::write_whole_mode(own, toml.as_bytes(), 0o444).map_err(|e| RunnerError::Create(own.to_path_buf(), std::io::Error::other(e)))
}

/// Writes every stream's scenario where the plan told the emulator to read it.
pub fn write_scenarios(streams: &[StreamPlan]) -> Result<()> {
    streams.iter().try_for_each(|s| write_run_scenario(&s.spec, &s.scenario_path, &s.own_scenario))
}

/// Removes the emulator's own copies once it has read them (the ones kept
/// are `scenario.toml`).
pub fn remove_own_scenarios(streams: &[StreamPlan]) {
    for s in streams {
        if let Ok((dir, name)) = Dir::of(&s.own_scenario) {
            let _ = dir.remove(&name);
        }
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
