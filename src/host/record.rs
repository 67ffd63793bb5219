//! The host-wide record of cleared cores, and the guardian that undoes a
//! clearing whose owners died.
//!
//! Every [`isolate`](super::isolate::isolate) puts what it is about to change
//! into one file of a private directory ([`state_dir`]: `/run/netfi` for
//! root, else `$XDG_RUNTIME_DIR/netfi` or `/tmp/netfi-<uid>`, mode 0700,
//! owned by the user) *before* changing anything. The file names the
//! processes that own the clearing (the emulator and, under `netfi run`, the
//! runner), each by pid and start time, so a recycled pid is never taken
//! for a live owner. A record outlives its owners only when they were all
//! killed without restoring; then
//!
//! - the **guardian**, a small `netfi restore --guard RECORD` process the
//!   clearing process starts in a session of its own (so Ctrl-C and kill of
//!   the run's process group do not reach it), sees every owner gone and
//!   restores from the record at once; it exits as soon as the record is
//!   removed, which the owners do when they restore themselves;
//! - if the guardian itself was killed too, `netfi restore` — which every
//!   `netfi run` performs first — restores every record whose owners are
//!   all dead.
//!
//! Restoring takes an exclusive lock on the record and removes it while
//! holding it, so of several restorers exactly one restores.

use serde::{Deserialize, Serialize};
use std::collections::BTreeSet;
use std::io;
use std::os::unix::fs::{DirBuilderExt, MetadataExt, OpenOptionsExt};
use std::path::{Path, PathBuf};

/// How often the guardian looks at its owners and its record.
const GUARD_POLL: std::time::Duration = std::time::Duration::from_millis(100);

/// A process, by pid and start time (clock ticks after boot), so that a
/// recycled pid is not mistaken for it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Owner {
    pub pid: i32,
    pub start_ticks: u64,
}

impl Owner {
    /// The process `pid`, if it exists.
    pub fn of(pid: i32) -> Option<Owner> {
        Some(Owner { pid, start_ticks: start_ticks(&format!("/proc/{pid}/stat"))? })
    }

    /// Whether this very process is still there (not a zombie).
    pub fn alive(&self) -> bool {
        let path = format!("/proc/{}/stat", self.pid);
        start_ticks(&path) == Some(self.start_ticks) && !is_zombie(&path)
    }
}

/// Field 22 of a `/proc/…/stat` file: the start time in clock ticks after boot.
pub(crate) fn start_ticks(stat_path: &str) -> Option<u64> {
    let stat = std::fs::read_to_string(stat_path).ok()?;
    // The name may hold spaces and parentheses: fields after it start after
    // the last ')'; starttime is the 20th of those (field 22 overall).
    stat.rsplit_once(')')?.1.split_whitespace().nth(19)?.parse().ok()
}

fn is_zombie(stat_path: &str) -> bool {
    std::fs::read_to_string(stat_path)
        .ok()
        .and_then(|s| s.rsplit_once(')').and_then(|(_, rest)| rest.split_whitespace().next().map(|x| x == "Z" || x == "X")))
        .unwrap_or(true)
}

/// Now, in clock ticks after boot (the unit of [`Owner::start_ticks`]).
pub(crate) fn now_ticks() -> u64 {
    // SAFETY: sysconf has no preconditions.
    let hz = unsafe { libc::sysconf(libc::_SC_CLK_TCK) }.max(1) as f64;
    let up: f64 = std::fs::read_to_string("/proc/uptime")
        .ok()
        .and_then(|t| t.split_whitespace().next()?.parse().ok())
        .unwrap_or(0.0);
    (up * hz) as u64
}

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
    pub state: super::isolate::IsolationState,
}

impl Record {
    /// Whether every owner is gone (`except`, when given, counts as gone:
    /// a runner restoring after its emulator).
    pub fn orphaned(&self, except: Option<i32>) -> bool {
        self.owners.iter().all(|o| Some(o.pid) == except || !o.alive())
    }
}

/// The private directory of records, created 0700 if missing. Refused when
/// it is not a directory owned by this user and closed to everyone else.
pub fn state_dir() -> io::Result<PathBuf> {
    // SAFETY: geteuid has no preconditions.
    let uid = unsafe { libc::geteuid() };
    let dir = if uid == 0 {
        PathBuf::from("/run/netfi")
    } else {
        match std::env::var_os("XDG_RUNTIME_DIR") {
            Some(d) if !d.is_empty() => PathBuf::from(d).join("netfi"),
            _ => PathBuf::from(format!("/tmp/netfi-{uid}")),
        }
    };
    match std::fs::DirBuilder::new().mode(0o700).create(&dir) {
        Ok(()) => {}
        Err(e) if e.kind() == io::ErrorKind::AlreadyExists => {}
        Err(e) => return Err(io::Error::new(e.kind(), format!("creating {}: {e}", dir.display()))),
    }
    let meta = std::fs::symlink_metadata(&dir)?;
    if !meta.is_dir() || meta.uid() != uid || meta.mode() & 0o077 != 0 {
        return Err(io::Error::new(
            io::ErrorKind::PermissionDenied,
            format!(
                "{} is not a private directory of uid {uid} (a directory, owner {}, mode {:o}): refusing to keep records there",
                dir.display(),
                meta.uid(),
                meta.mode() & 0o7777
            ),
        ));
    }
    Ok(dir)
}

/// Writes `record` to `path` atomically (a temporary file renamed over it),
/// mode 0600.
pub fn write(path: &Path, record: &Record) -> io::Result<()> {
    let tmp = path.with_extension("tmp");
    let bytes = serde_json::to_vec(record).map_err(io::Error::other)?;
    let mut f = std::fs::OpenOptions::new().write(true).create(true).truncate(true).mode(0o600).open(&tmp)?;
    io::Write::write_all(&mut f, &bytes)?;
    drop(f);
    std::fs::rename(&tmp, path)
}

/// Every record file of the directory.
pub fn list(dir: &Path) -> Vec<PathBuf> {
    let Ok(rd) = std::fs::read_dir(dir) else { return Vec::new() };
    let mut v: Vec<PathBuf> = rd
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.file_name().and_then(|n| n.to_str()).is_some_and(|n| n.starts_with("isolation-") && n.ends_with(".json")))
        .collect();
    v.sort();
    v
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

/// Restores from the record at `path` if `orphaned_only` is false or the
/// record is an orphan (every owner but `except` gone), and removes it.
/// `Ok(None)`: nothing to do (removed meanwhile, or an owner lives).
pub fn restore(path: &Path, orphaned_only: bool, except: Option<i32>) -> io::Result<Option<Restored>> {
    let f = match std::fs::OpenOptions::new().read(true).open(path) {
        Ok(f) => f,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(e),
    };
    use std::os::fd::AsRawFd;
    // SAFETY: flock on a descriptor we own.
    if unsafe { libc::flock(f.as_raw_fd(), libc::LOCK_EX) } != 0 {
        return Err(io::Error::last_os_error());
    }
    // Another restorer removed it while we waited for the lock.
    if f.metadata()?.nlink() == 0 {
        return Ok(None);
    }
    let record: Record = match serde_json::from_reader(io::BufReader::new(&f)) {
        Ok(r) => r,
        Err(e) => {
            // Unreadable (cut by a kill while being written: the temporary
            // file is renamed only when complete, so this is not ours).
            return Err(io::Error::new(io::ErrorKind::InvalidData, format!("{}: {e}", path.display())));
        }
    };
    if orphaned_only && !record.orphaned(except) {
        return Ok(None);
    }
    let undone = super::isolate::restore_state(&record.state);
    let widened = widen_born_during(&record);
    std::fs::remove_file(path)?;
    Ok(Some(Restored { undone, widened }))
}

/// Restores every orphaned record of this user's directory; returns the
/// records restored with what each did. Records that cannot be read are
/// reported as errors and left.
pub fn restore_orphans(except: Option<i32>) -> io::Result<Vec<(PathBuf, Restored)>> {
    let dir = state_dir()?;
    let mut done = Vec::new();
    for path in list(&dir) {
        if let Some(r) = restore(&path, true, except)? {
            done.push((path, r));
        }
    }
    Ok(done)
}

/// Threads started while the core was cleared inherited their parent's
/// narrowed mask and would keep it for good. Each thread started after the
/// clearing began whose mask is exactly one of the narrowed masks of the
/// record gets the mask that one had before (within the CPUs online now).
/// A thread started during the run and deliberately kept to exactly such a
/// set is widened too: the record cannot tell it from an inherited mask.
fn widen_born_during(record: &Record) -> usize {
    let core = record.state.core;
    let online = super::isolate::online_cpus();
    // Narrowed mask → the mask it came from; ambiguous ones are skipped.
    let mut map: std::collections::BTreeMap<BTreeSet<usize>, Option<BTreeSet<usize>>> = Default::default();
    for (_, before, after) in &record.state.threads {
        let (b, a): (BTreeSet<usize>, BTreeSet<usize>) = (before.iter().copied().collect(), after.iter().copied().collect());
        map.entry(a).and_modify(|v| if v.as_ref() != Some(&b) { *v = None }).or_insert(Some(b));
    }
    // Threads of processes that had nothing to move (already off the
    // core) but narrowed by inheritance from the runner's placement are
    // covered by the common case: all online CPUs but the core.
    let all: BTreeSet<usize> = record.online.iter().copied().collect();
    let narrowed_all: BTreeSet<usize> = all.iter().copied().filter(|&c| c != core).collect();
    map.entry(narrowed_all).or_insert(Some(all));
    let recorded: BTreeSet<i32> = record.state.threads.iter().map(|t| t.0).collect();
    let own = std::process::id() as i32;
    let mut widened = 0;
    for pid in super::isolate::numeric_entries(Path::new("/proc")) {
        if pid as i32 == own {
            continue;
        }
        for tid in super::isolate::numeric_entries(&Path::new("/proc").join(pid.to_string()).join("task")) {
            let tid = tid as i32;
            if recorded.contains(&tid) {
                continue;
            }
            let Some(born) = start_ticks(&format!("/proc/{pid}/task/{tid}/stat")) else { continue };
            if born < record.started_ticks {
                continue;
            }
            let Some(mask) = super::isolate::get_affinity(tid) else { continue };
            let Some(Some(before)) = map.get(&mask) else { continue };
            let target: BTreeSet<usize> = before.intersection(&online).copied().collect();
            if !target.is_empty() && super::isolate::set_affinity(tid, &target).is_ok() {
                widened += 1;
            }
        }
    }
    widened
}

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

/// Starts the guardian of the record at `path` in a session of its own,
/// off `core`. Returns its pid.
pub fn spawn_guardian(path: &Path) -> io::Result<u32> {
    let program = guardian_program().ok_or_else(|| io::Error::new(io::ErrorKind::NotFound, "no `netfi` executable found to guard the record"))?;
    use std::os::unix::process::CommandExt;
    let mut cmd = std::process::Command::new(program);
    cmd.arg("restore")
        .arg("--guard")
        .arg(path)
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null());
    // SAFETY: setsid is async-signal-safe; it only detaches the child from
    // the run's session and process group.
    unsafe {
        cmd.pre_exec(|| {
            libc::setsid();
            Ok(())
        });
    }
    Ok(cmd.spawn()?.id())
}

/// The guardian's loop (`netfi restore --guard RECORD`): waits until the
/// record is gone (its owners restored) or every owner has ended, then
/// restores from it. Returns what it restored, if anything.
pub fn guard(path: &Path) -> io::Result<Option<Restored>> {
    // Off the cleared core: the guardian was started by a pinned process.
    if let Ok(text) = std::fs::read(path) {
        if let Ok(r) = serde_json::from_slice::<Record>(&text) {
            let off: BTreeSet<usize> = r.online.iter().copied().filter(|&c| c != r.state.core).collect();
            if !off.is_empty() {
                let _ = super::isolate::set_affinity(0, &off);
            }
        }
    }
    loop {
        let record: Record = match std::fs::read(path) {
            Ok(text) => match serde_json::from_slice(&text) {
                Ok(r) => r,
                Err(e) => return Err(io::Error::new(io::ErrorKind::InvalidData, format!("{}: {e}", path.display()))),
            },
            Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(None),
            Err(e) => return Err(e),
        };
        if record.orphaned(None) {
            return restore(path, true, None);
        }
        std::thread::sleep(GUARD_POLL);
    }
}
