//! The guardian: a small `netfi restore --guard RECORD` process that acts
//! on a record ([`super::record`]) the moment its owners are all gone.
//!
//! It is started by the process that writes the record, in a session of
//! its own (so Ctrl-C and a kill of the run's process group do not reach
//! it), and watches the record every [`GUARD_POLL`]:
//!
//! - a record of a cleared core: once every owner has ended, it restores
//!   the host from it;
//! - a record of a run ([`RunGuard`]): once the owner has ended, it ends
//!   the run's other processes (SIGTERM, then SIGKILL after
//!   [`RUN_END_GRACE`](super::record::RUN_END_GRACE)) and restores any
//!   cleared core whose owners are now all gone.
//!
//! Either way it exits as soon as the record is removed, which its owners
//! do when they end normally.

use super::affinity::set_affinity;
use super::process::{Owner, RUNNER_PID_ENV};
use super::record::{self, EndedRun, Record, RestoreError, RestoreOrphansError, Restored, RunRecord, WriteError};
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// How often the guardian looks at its owners and its record.
pub const GUARD_POLL: Duration = Duration::from_millis(100);

/// The `netfi` executable that can act as guardian (`netfi restore
/// --guard`): this program when it is `netfi`, else a `netfi` beside it or
/// one directory up (a test or benchmark binary in `target/*/deps`).
pub fn guardian_program() -> Option<PathBuf> {
    let exe = std::env::current_exe().ok()?;
    if exe.file_name().is_some_and(|n| n == "netfi") {
        return Some(exe);
    }
    let dir = exe.parent()?;
    [dir.join("netfi"), dir.parent()?.join("netfi")].into_iter().find(|p| p.is_file())
}

/// Starts the guardian of the record at `path` in a session of its own.
pub fn spawn(path: &Path) -> std::io::Result<Child> {
    let program = guardian_program().ok_or_else(|| std::io::Error::new(std::io::ErrorKind::NotFound, "no `netfi` executable found to guard the record"))?;
    let mut cmd = Command::new(program);
    cmd.arg("restore")
        .arg("--guard")
        .arg(path)
        // The guardian must outlive its starter: it is no child of a runner
        // that it should die with.
        .env_remove(RUNNER_PID_ENV)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null());
    // No `pre_exec`: with one the standard library must fork, and the fork
    // makes every private page of its starter (the emulator's trace rings
    // and queue, already written) copy-on-write, so the loop then takes a
    // page fault at the first write to each; without one it spawns by
    // vfork. The guardian leaves the run's session itself ([`guard`]).
    cmd.spawn()
}

/// Waits up to `limit` for the guardian to exit (it does within
/// [`GUARD_POLL`] of its record's removal), so that it leaves no zombie;
/// one still watching after that is left to its work.
pub(crate) fn reap(guardian: &mut Child, limit: Duration) {
    let until = Instant::now() + limit;
    while Instant::now() < until {
        if !matches!(guardian.try_wait(), Ok(None)) {
            return;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// What the guardian did.
#[derive(Debug)]
pub enum Guarded {
    /// The record was removed by its owners: nothing to do.
    Released,
    /// The owners of a cleared core ended: the host was restored.
    Restored(Restored),
    /// The owner of a run ended: what was left of it was ended, and the
    /// cleared cores whose owners were all gone restored.
    RunEnded { run: EndedRun, restored: Vec<(PathBuf, Restored)> },
}

/// Why the guardian stopped without acting.
#[derive(Debug, thiserror::Error)]
pub enum GuardError {
    #[error(transparent)]
    Restore(#[from] RestoreError),
    #[error(transparent)]
    RestoreOrphans(#[from] RestoreOrphansError),
    #[error("reading {}: {source}", path.display())]
    Read { path: PathBuf, source: std::io::Error },
    #[error("{}: {source}", path.display())]
    Unreadable { path: PathBuf, source: serde_json::Error },
}

/// Reads the record at `path`; `Ok(None)` once it is gone.
fn read<R: for<'de> serde::Deserialize<'de>>(path: &Path) -> Result<Option<R>, GuardError> {
    match std::fs::read(path) {
        Ok(text) => serde_json::from_slice(&text).map(Some).map_err(|source| GuardError::Unreadable { path: path.to_path_buf(), source }),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
        Err(source) => Err(GuardError::Read { path: path.to_path_buf(), source }),
    }
}

/// The guardian's loop (`netfi restore --guard RECORD`): waits until the
/// record is gone or its owners have ended, then acts on it.
pub fn guard(path: &Path) -> Result<Guarded, GuardError> {
    // A session of its own: the run's Ctrl-C (sent to its process group)
    // and the end of its session do not reach the guardian.
    // SAFETY: setsid takes no arguments and touches no memory.
    unsafe { libc::setsid() };
    if record::is_run_record(path) {
        return guard_run(path);
    }
    // Off the cleared core: the guardian was started by a pinned process.
    if let Ok(Some(r)) = read::<Record>(path) {
        let off: BTreeSet<usize> = r.online.iter().copied().filter(|&c| c != r.state.core).collect();
        if !off.is_empty() {
            let _ = set_affinity(0, &off);
        }
    }
    loop {
        let Some(r) = read::<Record>(path)? else { return Ok(Guarded::Released) };
        if r.orphaned(None) {
            return Ok(record::restore(path, true, None)?.map_or(Guarded::Released, Guarded::Restored));
        }
        std::thread::sleep(GUARD_POLL);
    }
}

fn guard_run(path: &Path) -> Result<Guarded, GuardError> {
    loop {
        let Some(r) = read::<RunRecord>(path)? else { return Ok(Guarded::Released) };
        if !r.owner.alive() {
            let Some(run) = record::end_run(path, true)? else { return Ok(Guarded::Released) };
            // The run's emulator, ended above, may have left its core
            // cleared; its own guardian may be gone too.
            let restored = record::restore_orphans(None)?;
            return Ok(Guarded::RunEnded { run, restored });
        }
        std::thread::sleep(GUARD_POLL);
    }
}

/// Why a run could not be put under a guardian's watch.
#[derive(Debug, thiserror::Error)]
pub enum RunGuardError {
    #[error("the directory of records: {0}")]
    StateDir(#[from] super::private_dir::PrivateDirError),
    #[error("cannot read the start time of process {pid}: is it gone?")]
    NoProcess { pid: i32 },
    #[error(transparent)]
    Write(#[from] WriteError),
}

/// The record of a run owned by this process, watched by a guardian: if
/// this process ends without dropping it (killed, aborted), the guardian
/// ends every process [`add`](Self::add)ed to it. Dropped, it ends those
/// still running (a run left by an error or a panic takes its processes
/// with it), removes the record, and lets the guardian go.
#[derive(Debug)]
pub struct RunGuard {
    path: PathBuf,
    record: RunRecord,
    guardian: Option<Child>,
    warnings: Vec<String>,
}

impl RunGuard {
    /// Writes the record of a run of this process (iceoryx2 run ids
    /// `run_ids`, whose shared memory goes when the run is ended) and
    /// starts its guardian. A guardian that cannot be started is a warning
    /// ([`warnings`](Self::warnings)), not an error: the record still lets
    /// `netfi restore` end the run.
    pub fn start(run_ids: &[&str]) -> Result<RunGuard, RunGuardError> {
        let dir = record::state_dir_resolved()?;
        let own = std::process::id() as i32;
        let owner = Owner::of(own).ok_or(RunGuardError::NoProcess { pid: own })?;
        let path = dir.path.join(format!("run-{own}-{}.json", owner.start_ticks));
        let record = RunRecord { owner, members: Vec::new(), run_ids: run_ids.iter().map(|r| r.to_string()).collect() };
        record::write(&path, &record)?;
        let mut warnings: Vec<String> = dir.warning().into_iter().collect();
        let guardian = match spawn(&path) {
            Ok(child) => Some(child),
            Err(e) => {
                warnings.push(format!(
                    "no guardian ({e}): if this process is killed, its children end by the parent-death signal only; `netfi restore` ends the rest"
                ));
                None
            }
        };
        Ok(RunGuard { path, record, guardian, warnings })
    }

    /// Adds process `pid` to the run: it will not outlive this process.
    pub fn add(&mut self, pid: u32) -> Result<(), RunGuardError> {
        let pid = pid as i32;
        let member = Owner::of(pid).ok_or(RunGuardError::NoProcess { pid })?;
        self.record.members.push(member);
        record::write(&self.path, &self.record)?;
        Ok(())
    }

    /// What the user must know: no guardian, a records directory taken by
    /// another user.
    pub fn warnings(&self) -> &[String] {
        &self.warnings
    }

    /// The guardian's pid, when one runs.
    pub fn guardian_pid(&self) -> Option<u32> {
        self.guardian.as_ref().map(Child::id)
    }

    /// The record's path.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

impl Drop for RunGuard {
    fn drop(&mut self) {
        super::process::end_processes(&self.record.members, record::RUN_END_GRACE);
        let _ = std::fs::remove_file(&self.path);
        if let Some(g) = self.guardian.as_mut() {
            reap(g, 4 * GUARD_POLL);
        }
    }
}
