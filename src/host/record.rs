//! The host-wide records of what runs changed and which processes they
//! started, so that whoever outlives a killed run can put the host back and
//! end what is left of it.
//!
//! Two kinds of record live in one private directory ([`state_dir`]:
//! `/run/netfi` for root, else `$XDG_RUNTIME_DIR/netfi` or
//! `/tmp/netfi-<uid>`, mode 0700, owned by the user; where that name is
//! taken by someone else, a fresh `/tmp/netfi-<uid>-XXXXXX` is used and
//! found again by later runs):
//!
//! - `isolation-*.json` ([`Record`]): a cleared core, written *before*
//!   anything is changed, naming the processes that own the clearing (the
//!   emulator and, under `netfi run`, the runner);
//! - `run-*.json` ([`RunRecord`]): a run's owner (the runner) and the
//!   processes it started, each added as it starts.
//!
//! Processes are named by pid and start time ([`Owner`]), so a recycled
//! pid is never taken for a live owner, nor killed for a member. A record
//! outlives its owners only when they were all killed; then its guardian
//! ([`super::guardian`]) acts at once, or, if the guardian was killed too,
//! `netfi restore` (which every `netfi run` performs first). Acting on a
//! record takes an exclusive lock on it and removes it while holding it,
//! so of several restorers exactly one acts.

use super::changes::{undo, widen_born_during, IsolationState};
use super::private_dir::{self, PrivateDir, PrivateDirError};
use super::process::{end_processes, Ended, Owner};
use serde::{Deserialize, Serialize};
use std::io;
use std::os::unix::fs::{MetadataExt, OpenOptionsExt};
use std::path::{Path, PathBuf};
use std::time::Duration;

/// How long the processes of a run whose owner is gone have to end on
/// SIGTERM (writing what they have) before they are killed.
pub const RUN_END_GRACE: Duration = Duration::from_millis(800);

/// What a clearing changed (or is about to change), with its owners.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct Record {
    /// Processes whose ending without restoring makes the record an orphan.
    pub owners: Vec<Owner>,
    /// When the clearing began, clock ticks after boot: threads started
    /// later inherited narrowed masks (see [`restore`]).
    pub started_ticks: u64,
    /// The CPUs online when it began.
    pub online: Vec<usize>,
    pub state: IsolationState,
}

impl Record {
    /// Whether every owner is gone (`except`, when given, counts as gone:
    /// a runner restoring after its emulator).
    pub fn orphaned(&self, except: Option<i32>) -> bool {
        self.owners.iter().all(|o| Some(o.pid) == except || !o.alive())
    }
}

/// The processes of one run: its owner, and the others, which must not
/// outlive it.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct RunRecord {
    pub owner: Owner,
    pub members: Vec<Owner>,
    /// The run's iceoryx2 run ids, whose shared memory goes once the run
    /// has ended.
    pub run_ids: Vec<String>,
}

/// The candidate places of the records, in order of preference.
fn preferred_dirs() -> Vec<PathBuf> {
    let uid = private_dir::uid();
    if uid == 0 {
        return vec![PathBuf::from("/run/netfi"), PathBuf::from("/tmp/netfi-0")];
    }
    let mut dirs: Vec<PathBuf> = private_dir::xdg_runtime_dir().map(|d| d.join("netfi")).into_iter().collect();
    dirs.push(PathBuf::from(format!("/tmp/netfi-{uid}")));
    dirs
}

/// The private directory of records, created 0700 if missing, with what
/// was passed over on the way (a directory of that name taken by another
/// user).
pub fn state_dir_resolved() -> Result<PrivateDir, PrivateDirError> {
    private_dir::resolve(&preferred_dirs(), Path::new("/tmp"), &format!("netfi-{}", private_dir::uid()))
}

/// The private directory of records (see [`state_dir_resolved`]).
pub fn state_dir() -> Result<PathBuf, PrivateDirError> {
    state_dir_resolved().map(|d| d.path)
}

/// Every private directory of this user's records: the one in use and any
/// other a process of this user may have used (the usual names, and the
/// replacements of a taken name).
fn all_state_dirs() -> Result<Vec<PathBuf>, PrivateDirError> {
    let mut dirs = vec![state_dir()?];
    let stem = format!("netfi-{}-", private_dir::uid());
    let replacements = std::fs::read_dir("/tmp")
        .map(|rd| rd.filter_map(|e| e.ok()).filter(|e| e.file_name().to_str().is_some_and(|n| n.starts_with(&stem))).map(|e| e.path()).collect())
        .unwrap_or_else(|_| Vec::new());
    for d in preferred_dirs().into_iter().chain(replacements) {
        if !dirs.contains(&d) && private_dir::is_private(&d) {
            dirs.push(d);
        }
    }
    Ok(dirs)
}

/// Why a record could not be written.
#[derive(Debug, thiserror::Error)]
#[error("writing the record {}: {source}", path.display())]
pub struct WriteError {
    pub path: PathBuf,
    #[source]
    pub source: io::Error,
}

/// Writes `record` to `path` atomically (a temporary file renamed over it),
/// mode 0600.
pub fn write(path: &Path, record: &impl Serialize) -> Result<(), WriteError> {
    let error = |source| WriteError { path: path.to_path_buf(), source };
    let tmp = path.with_extension("tmp");
    let bytes = serde_json::to_vec(record).map_err(|e| error(io::Error::other(e)))?;
    let mut f = std::fs::OpenOptions::new().write(true).create(true).truncate(true).mode(0o600).open(&tmp).map_err(error)?;
    io::Write::write_all(&mut f, &bytes).map_err(error)?;
    drop(f);
    std::fs::rename(&tmp, path).map_err(error)
}

/// Every record file of the directory whose name starts with `kind`.
fn list_kind(dir: &Path, kind: &str) -> Vec<PathBuf> {
    let Ok(rd) = std::fs::read_dir(dir) else { return Vec::new() };
    let mut v: Vec<PathBuf> = rd
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.file_name().and_then(|n| n.to_str()).is_some_and(|n| n.starts_with(kind) && n.ends_with(".json")))
        .collect();
    v.sort();
    v
}

/// Every record of a cleared core in the directory.
pub fn list(dir: &Path) -> Vec<PathBuf> {
    list_kind(dir, "isolation-")
}

/// Every record of a run in the directory.
pub fn list_runs(dir: &Path) -> Vec<PathBuf> {
    list_kind(dir, "run-")
}

/// Whether `path` names a record of a run (not of a cleared core).
pub fn is_run_record(path: &Path) -> bool {
    path.file_name().and_then(|n| n.to_str()).is_some_and(|n| n.starts_with("run-"))
}

/// What one restore did.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Restored {
    /// Changes undone (threads, interrupts, the workqueue mask).
    pub undone: usize,
    /// Threads started during the clearing that had inherited a narrowed
    /// mask, widened again.
    pub widened: usize,
}

/// What ending a run whose owner is gone did.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct EndedRun {
    pub ended: Ended,
    /// The run's iceoryx2 run ids.
    pub run_ids: Vec<String>,
}

/// Why a record could not be acted on.
#[derive(Debug, thiserror::Error)]
pub enum RestoreError {
    #[error("opening {}: {source}", path.display())]
    Open { path: PathBuf, source: io::Error },
    #[error("locking {}: {source}", path.display())]
    Lock { path: PathBuf, source: io::Error },
    /// Unreadable: not a record of this version (a record is renamed into
    /// place only when complete, so a kill cannot cut one).
    #[error("{}: {source}", path.display())]
    Unreadable { path: PathBuf, source: serde_json::Error },
    #[error("removing {}: {source}", path.display())]
    Remove { path: PathBuf, source: io::Error },
}

/// Opens and locks the record at `path` and reads it; `Ok(None)` when it
/// is gone, or was removed while this waited for the lock. The lock lasts
/// as long as the returned file.
fn lock_and_read<R: for<'de> Deserialize<'de>>(path: &Path) -> Result<Option<(std::fs::File, R)>, RestoreError> {
    let f = match std::fs::OpenOptions::new().read(true).open(path) {
        Ok(f) => f,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(None),
        Err(source) => return Err(RestoreError::Open { path: path.to_path_buf(), source }),
    };
    use std::os::fd::AsRawFd;
    // SAFETY: flock on a descriptor we own.
    if unsafe { libc::flock(f.as_raw_fd(), libc::LOCK_EX) } != 0 {
        return Err(RestoreError::Lock { path: path.to_path_buf(), source: io::Error::last_os_error() });
    }
    // Another restorer removed it while we waited for the lock.
    if f.metadata().map_err(|source| RestoreError::Open { path: path.to_path_buf(), source })?.nlink() == 0 {
        return Ok(None);
    }
    let record = serde_json::from_reader(io::BufReader::new(&f)).map_err(|source| RestoreError::Unreadable { path: path.to_path_buf(), source })?;
    Ok(Some((f, record)))
}

fn remove(path: &Path) -> Result<(), RestoreError> {
    std::fs::remove_file(path).map_err(|source| RestoreError::Remove { path: path.to_path_buf(), source })
}

/// Restores from the record at `path` if `orphaned_only` is false or the
/// record is an orphan (every owner but `except` gone), and removes it.
/// `Ok(None)`: nothing to do (removed meanwhile, or an owner lives).
pub fn restore(path: &Path, orphaned_only: bool, except: Option<i32>) -> Result<Option<Restored>, RestoreError> {
    let Some((_lock, record)) = lock_and_read::<Record>(path)? else { return Ok(None) };
    if orphaned_only && !record.orphaned(except) {
        return Ok(None);
    }
    let undone = undo(&record.state);
    let widened = widen_born_during(&record.state, record.started_ticks, &record.online);
    remove(path)?;
    Ok(Some(Restored { undone, widened }))
}

/// Ends the run of the record at `path` if its owner is gone (or
/// `orphaned_only` is false): its other processes are sent SIGTERM, then
/// SIGKILL after [`RUN_END_GRACE`]; the record is removed. `Ok(None)`:
/// nothing to do (removed meanwhile, or the owner lives).
pub fn end_run(path: &Path, orphaned_only: bool) -> Result<Option<EndedRun>, RestoreError> {
    let Some((_lock, record)) = lock_and_read::<RunRecord>(path)? else { return Ok(None) };
    if orphaned_only && record.owner.alive() {
        return Ok(None);
    }
    let ended = end_processes(&record.members, RUN_END_GRACE);
    remove(path)?;
    Ok(Some(EndedRun { ended, run_ids: record.run_ids }))
}

/// Why the orphaned records of this user could not all be acted on.
#[derive(Debug, thiserror::Error)]
pub enum RestoreOrphansError {
    #[error("the directory of records: {0}")]
    StateDir(#[from] PrivateDirError),
    #[error(transparent)]
    Restore(#[from] RestoreError),
}

/// Restores every orphaned record of a cleared core of this user; returns
/// the records restored with what each did. A record that cannot be read
/// is an error, and left.
pub fn restore_orphans(except: Option<i32>) -> Result<Vec<(PathBuf, Restored)>, RestoreOrphansError> {
    let mut done = Vec::new();
    for dir in all_state_dirs()? {
        for path in list(&dir) {
            if let Some(r) = restore(&path, true, except)? {
                done.push((path, r));
            }
        }
    }
    Ok(done)
}

/// Ends every run of this user whose owner is gone (its guardian killed
/// too); returns the records acted on with what each did.
pub fn end_orphaned_runs() -> Result<Vec<(PathBuf, EndedRun)>, RestoreOrphansError> {
    let mut done = Vec::new();
    for dir in all_state_dirs()? {
        for path in list_runs(&dir) {
            if let Some(r) = end_run(&path, true)? {
                done.push((path, r));
            }
        }
    }
    Ok(done)
}

/// The records of this user left in place: their owners live.
pub fn live_records() -> Result<Vec<PathBuf>, PrivateDirError> {
    Ok(all_state_dirs()?.iter().flat_map(|d| list_runs(d).into_iter().chain(list(d))).collect())
}
