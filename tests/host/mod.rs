//! A guest on the host: what `netfi run` changes on the machine must not
//! outlive the run, whatever is killed, and several users share a machine.
//!
//! - `isolation`: the kill -9 matrix (emulator; runner; runner and
//!   emulator; the guardian; all three, then `netfi restore`) against the
//!   interrupt affinities, the workqueue mask and the kernel threads' masks
//!   as they were before; a process started mid-run gets its mask back; a
//!   pin that cannot be honoured is an error or a warning in the report.
//!   Killing the runner (alone, with the emulator, or with the guardian
//!   too) leaves no process of the run after about 2 s, and nothing of it
//!   in `/dev/shm`.
//! - `users`: a run leaves nothing in `/dev/shm`; another user runs after
//!   root; a file another user planted under root's names is refused at
//!   once; directories another user took first under a user's names do
//!   not lock that user out.
//! - `orphans`: a child dies with its parent; the guardian ends a run
//!   whose owner was killed; `netfi restore` ends one whose guardian was
//!   killed too, and removes a dead run's shared memory.
//!
//! Moving other processes' threads and interrupts, and acting as another
//! user, need root: without it each such test says so and skips, or fails
//! where `NETFI_REQUIRE_ROOT` is set (`.ci/run` runs as root). The runs are
//! serialized (one busy-polling emulator at a time).

mod isolation;
mod orphans;
mod users;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use crate::common::machine;

use crate::common::netfi::{netfi, netfi_exe};

fn uid() -> u32 {
    // SAFETY: geteuid has no preconditions.
    unsafe { libc::geteuid() }
}

fn is_root() -> bool {
    uid() == 0
}

/// Whether a test that needs root must skip: says why, or fails where
/// `NETFI_REQUIRE_ROOT` is set.
fn skip_unless_root(what: &str) -> bool {
    if is_root() {
        return false;
    }
    assert!(std::env::var_os("NETFI_REQUIRE_ROOT").is_none(), "NETFI_REQUIRE_ROOT is set but this test runs as uid {}: {what} needs root", uid());
    eprintln!("skipped: {what} needs root");
    true
}

fn out_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("netfi-host-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

/// A child process, killed and reaped however the test ends.
struct Reaped(std::process::Child);

impl Drop for Reaped {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn read_pid(out: &Path, role: &str) -> Option<i32> {
    std::fs::read_to_string(out.join(format!("{role}.pid"))).ok()?.trim().parse().ok()
}

fn wait_for(what: &str, limit: Duration, mut cond: impl FnMut() -> bool) {
    let t0 = Instant::now();
    while !cond() {
        assert!(t0.elapsed() < limit, "{what}: not within {limit:?}");
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn alive(pid: i32) -> bool {
    // Zombies count as gone.
    std::fs::read_to_string(format!("/proc/{pid}/stat"))
        .ok()
        .and_then(|s| s.rsplit_once(')').map(|(_, r)| !r.trim_start().starts_with('Z')))
        .unwrap_or(false)
}

/// The files of iceoryx2 run `run_id` in `/dev/shm` and under this user's
/// iceoryx2 root directory.
fn ipc_files_of(run_id: &str) -> Vec<String> {
    let root = netfi::transport::ipc::user_root_dir();
    let needle = format!("_{run_id}_");
    let mut found = Vec::new();
    let mut dirs = vec![PathBuf::from("/dev/shm"), root];
    while let Some(dir) = dirs.pop() {
        for e in std::fs::read_dir(&dir).into_iter().flatten().filter_map(|e| e.ok()) {
            if e.file_type().is_ok_and(|t| t.is_dir()) {
                dirs.push(e.path());
            } else if e.file_name().to_string_lossy().contains(&needle) {
                found.push(e.path().display().to_string());
            }
        }
    }
    found
}

fn sigkill(pid: i32) {
    // SAFETY: signalling a process this test started (directly or through
    // the runner).
    unsafe { libc::kill(pid, libc::SIGKILL) };
}

/// `netfi restore`, which must succeed.
fn restore() -> String {
    let o = netfi().arg("restore").output().unwrap();
    assert!(o.status.success(), "netfi restore failed: {}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8_lossy(&o.stdout).into_owned()
}
