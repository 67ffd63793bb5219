//! A guest on the host: what `netfi run` changes on the machine must not
//! outlive the run, whatever is killed, and several users share a machine.
//!
//! - `isolation`: the kill -9 matrix (emulator; runner; runner and
//!   emulator; the guardian; all three, then `netfi restore`) against the
//!   interrupt affinities, the workqueue mask and the kernel threads' masks
//!   as they were before; a process started mid-run gets its mask back; a
//!   pin that cannot be honoured is an error or a warning in the report.
//! - `users`: a run leaves nothing in `/dev/shm`; another user runs after
//!   root; a file another user planted under root's names is refused at
//!   once.
//!
//! Moving other processes' threads and interrupts, and acting as another
//! user, need root: without it each test says so and skips. The runs are
//! serialized (one busy-polling emulator at a time).

mod isolation;
mod users;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Mutex;
use std::time::{Duration, Instant};

static ONE_RUN_AT_A_TIME: Mutex<()> = Mutex::new(());

fn lock() -> std::sync::MutexGuard<'static, ()> {
    ONE_RUN_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner())
}

fn netfi_exe() -> &'static str {
    env!("CARGO_BIN_EXE_netfi")
}

fn netfi() -> Command {
    Command::new(netfi_exe())
}

fn is_root() -> bool {
    // SAFETY: geteuid has no preconditions.
    unsafe { libc::geteuid() == 0 }
}

fn out_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("netfi-host-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
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
