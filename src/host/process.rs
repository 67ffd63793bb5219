//! Processes as the host sees them: a process named so that a recycled pid
//! is never taken for it ([`Owner`]), a child that dies with its parent
//! ([`die_with_parent`]), and ending what is left of a run
//! ([`end_processes`]). A leaf: it reads `/proc` and calls the kernel,
//! and knows nothing of netfi's services.

use serde::{Deserialize, Serialize};
use std::path::Path;
use std::time::{Duration, Instant};

/// The environment variable through which `netfi run` names itself (its
/// pid) to the processes it starts: an emulator's record of a cleared core
/// then counts the runner among its owners, and each child dies with it
/// ([`die_with_runner`]).
pub const RUNNER_PID_ENV: &str = "NETFI_RUNNER_PID";

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

    /// Sends `signal` to this process if it is still this process.
    fn signal(&self, signal: i32) {
        if self.alive() {
            // SAFETY: kill has no memory-safety preconditions; the pid was
            // just checked to be this process (a recycled pid has another
            // start time).
            unsafe { libc::kill(self.pid, signal) };
        }
    }
}

/// Field 22 of a `/proc/…/stat` file: the start time in clock ticks after boot.
pub fn start_ticks(stat_path: &str) -> Option<u64> {
    let stat = std::fs::read_to_string(stat_path).ok()?;
    // The name may hold spaces and parentheses: fields after it start after
    // the last ')'; starttime is the 20th of those (field 22 overall).
    stat.rsplit_once(')')?.1.split_whitespace().nth(19)?.parse().ok()
}

/// Whether the process of `stat_path` is a zombie, or gone.
fn is_zombie(stat_path: &str) -> bool {
    std::fs::read_to_string(stat_path)
        .ok()
        .and_then(|s| s.rsplit_once(')').and_then(|(_, rest)| rest.split_whitespace().next().map(|x| x == "Z" || x == "X")))
        .unwrap_or(true)
}

/// Now, in clock ticks after boot (the unit of [`Owner::start_ticks`]).
pub fn now_ticks() -> u64 {
    // SAFETY: sysconf has no preconditions.
    let hz = unsafe { libc::sysconf(libc::_SC_CLK_TCK) }.max(1) as f64;
    let up: f64 = std::fs::read_to_string("/proc/uptime")
        .ok()
        .and_then(|t| t.split_whitespace().next()?.parse().ok())
        .unwrap_or(0.0);
    (up * hz) as u64
}

/// The numeric entries of a directory: the pids of `/proc`, the thread ids
/// of `/proc/<pid>/task`, the interrupts of `/proc/irq`.
pub fn numeric_entries(dir: &Path) -> Vec<u64> {
    let Ok(rd) = std::fs::read_dir(dir) else { return Vec::new() };
    rd.filter_map(|e| e.ok()?.file_name().to_str()?.parse().ok()).collect()
}

/// Kernel threads are children of kthreadd (pid 2), or kthreadd itself.
pub fn is_kernel_thread(pid: u64) -> bool {
    if pid == 2 {
        return true;
    }
    let Ok(stat) = std::fs::read_to_string(format!("/proc/{pid}/stat")) else { return false };
    // The name may hold spaces and parentheses: the fields after it start
    // after the last ')'. They are: state, ppid, ...
    stat.rsplit_once(')').and_then(|(_, rest)| rest.split_whitespace().nth(1)?.parse::<u64>().ok()) == Some(2)
}

/// The name of thread `tid`, or `tid N` where it cannot be read.
pub fn comm(tid: i32) -> String {
    std::fs::read_to_string(format!("/proc/{tid}/comm")).map(|s| s.trim().to_string()).unwrap_or_else(|_| format!("tid {tid}"))
}

/// The exit status of a child whose parent was already gone when it
/// looked: what SIGTERM, the parent-death signal, would have given.
pub const PARENT_GONE_EXIT: i32 = 128 + libc::SIGTERM;

/// Why [`die_with_parent`] could not tie this process to its parent.
#[derive(Debug, thiserror::Error)]
pub enum DieWithParentError {
    /// The kernel refused `prctl(PR_SET_PDEATHSIG)`.
    #[error("could not ask for SIGTERM when the parent dies (prctl PR_SET_PDEATHSIG): {0}")]
    Prctl(#[source] std::io::Error),
    /// [`RUNNER_PID_ENV`] holds no pid.
    #[error("{RUNNER_PID_ENV}={value:?} is not a process id")]
    BadRunnerPid {
        /// What the variable held.
        value: String,
    },
}

/// Ties this process's life to its parent's: the kernel sends it SIGTERM
/// when the parent ends, however it ends (kill -9, a panic, a crash). Call
/// it first thing in a child, with the pid the parent said it has: a
/// parent that died before this call cannot signal any more, so when the
/// parent is already gone (this process was re-parented) it exits at once,
/// with [`PARENT_GONE_EXIT`].
///
/// The signal comes when the parent's *thread* that started this process
/// ends: a parent must start such children from a thread that lives as
/// long as it does (its main thread), not from a pool's.
pub fn die_with_parent(expected_parent: i32) -> Result<(), DieWithParentError> {
    // SAFETY: prctl with PR_SET_PDEATHSIG takes a signal number and touches
    // no memory.
    if unsafe { libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM as libc::c_ulong, 0, 0, 0) } != 0 {
        return Err(DieWithParentError::Prctl(std::io::Error::last_os_error()));
    }
    // SAFETY: getppid has no preconditions.
    let parent = unsafe { libc::getppid() };
    if parent != expected_parent {
        let _ = std::io::Write::write_fmt(
            &mut std::io::stderr(),
            format_args!("netfi: the process that started this one (pid {expected_parent}) is gone: exiting\n"),
        );
        std::process::exit(PARENT_GONE_EXIT);
    }
    Ok(())
}

/// [`die_with_parent`] for a process started by `netfi run`, which names
/// itself in [`RUNNER_PID_ENV`]. `Ok(false)`: not started by a runner
/// (stand-alone), nothing done.
pub fn die_with_runner() -> Result<bool, DieWithParentError> {
    let Some(value) = std::env::var_os(RUNNER_PID_ENV) else { return Ok(false) };
    let value = value.to_string_lossy().into_owned();
    let pid = value.trim().parse::<i32>().map_err(|_| DieWithParentError::BadRunnerPid { value: value.clone() })?;
    die_with_parent(pid)?;
    Ok(true)
}

/// What [`end_processes`] did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Ended {
    /// Processes that were still there and were sent SIGTERM.
    pub terminated: usize,
    /// Of those, the ones still there after the grace time, sent SIGKILL.
    pub killed: usize,
}

/// Ends `processes`: SIGTERM to each still there, then, `grace` later,
/// SIGKILL to each that has not ended; returns once all are gone (or after
/// another second, should the kernel be slow to reap a killed process).
/// A process is signalled only while it is still the one named (pid and
/// start time), so a recycled pid is never hit.
pub fn end_processes(processes: &[Owner], grace: Duration) -> Ended {
    let live: Vec<Owner> = processes.iter().copied().filter(Owner::alive).collect();
    live.iter().for_each(|p| p.signal(libc::SIGTERM));
    let mut ended = Ended { terminated: live.len(), killed: 0 };
    let all_gone = |until: Instant| {
        while Instant::now() < until {
            if !live.iter().any(Owner::alive) {
                return true;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        !live.iter().any(Owner::alive)
    };
    if !all_gone(Instant::now() + grace) {
        let left: Vec<&Owner> = live.iter().filter(|p| p.alive()).collect();
        ended.killed = left.len();
        left.iter().for_each(|p| p.signal(libc::SIGKILL));
        all_gone(Instant::now() + Duration::from_secs(1));
    }
    ended
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_owner_is_its_pid_and_start_time() {
        let me = Owner::of(std::process::id() as i32).unwrap();
        assert!(me.alive());
        let recycled = Owner { start_ticks: me.start_ticks + 1, ..me };
        assert!(!recycled.alive(), "another start time is another process");
        assert!(now_ticks() >= me.start_ticks);
    }

    /// SIGTERM first; SIGKILL for what ignores it.
    #[test]
    fn ends_processes_gently_then_for_good() {
        let spawn = |script: &str| std::process::Command::new("sh").args(["-c", script]).spawn().unwrap();
        let mut polite = spawn("exec sleep 30");
        let mut deaf = spawn("trap '' TERM; while :; do sleep 0.05; done");
        // Give the shell time to install its trap.
        std::thread::sleep(Duration::from_millis(300));
        let owners: Vec<Owner> = [&polite, &deaf].iter().map(|c| Owner::of(c.id() as i32).unwrap()).collect();
        // A child not yet waited for is a zombie once it ends: reap both
        // from another thread so that `alive` sees them go.
        let ended = std::thread::scope(|s| {
            let h = s.spawn(|| end_processes(&owners, Duration::from_millis(300)));
            let a = polite.wait().unwrap();
            let b = deaf.wait().unwrap();
            (h.join().unwrap(), a, b)
        });
        assert_eq!(ended.0, Ended { terminated: 2, killed: 1 });
        use std::os::unix::process::ExitStatusExt;
        assert_eq!(ended.1.signal(), Some(libc::SIGTERM));
        assert_eq!(ended.2.signal(), Some(libc::SIGKILL));
        assert!(owners.iter().all(|o| !o.alive()));
    }
}
