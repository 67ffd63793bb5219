//! Who shares the machine with whom. The tests of the `all` binary run in
//! one process, as many at a time as the machine has cores (two on the CI
//! machine). A run of netfi's processes (a busy-polling emulator pinned to
//! a core, deadlines, a browser) needs the machine to itself, as far as a
//! test process can give it: it holds [`alone`], and no other run, nor any
//! test that holds [`not_beside_a_run`], goes on meanwhile. Every test of
//! the tiers that simulate (`statistical`, `fit`, `integration`: millions
//! of frames, in this process or through `netfi scenario check`, on every
//! core) and the transport tests whose killed peers a run's start-up
//! clean-up would remove hold [`not_beside_a_run`]; they run beside each
//! other. The other tests are cheap and hold neither.

use std::sync::{RwLock, RwLockReadGuard, RwLockWriteGuard};

static MACHINE: RwLock<()> = RwLock::new(());

/// The machine to this test alone, for as long as the guard lives; a test
/// that panicked while holding it does not keep the others out.
pub fn alone() -> RwLockWriteGuard<'static, ()> {
    MACHINE.write().unwrap_or_else(|e| e.into_inner())
}

/// No run beside this test while the guard lives; other such tests may be.
pub fn not_beside_a_run() -> RwLockReadGuard<'static, ()> {
    MACHINE.read().unwrap_or_else(|e| e.into_inner())
}
