//! Ctrl-C and SIGTERM end a service cleanly: the handler only sets a flag
//! that the service's loop polls off its hot path.

use std::sync::atomic::{AtomicBool, Ordering};

static STOP: AtomicBool = AtomicBool::new(false);

extern "C" fn on_signal(_sig: libc::c_int) {
    STOP.store(true, Ordering::Relaxed);
}

/// Installs the handler for SIGINT and SIGTERM (idempotent).
pub fn install() {
    for sig in [libc::SIGINT, libc::SIGTERM] {
        // SAFETY: the handler is async-signal-safe (one atomic store), and
        // `sigaction` is given a zeroed, then filled, struct.
        unsafe {
            let mut sa: libc::sigaction = std::mem::zeroed();
            sa.sa_sigaction = on_signal as *const () as usize;
            libc::sigemptyset(&mut sa.sa_mask);
            sa.sa_flags = libc::SA_RESTART;
            libc::sigaction(sig, &sa, std::ptr::null_mut());
        }
    }
}

/// Puts this module's handler back for SIGINT and SIGTERM where something
/// else has since replaced it (iceoryx2 installs its own the first time a
/// process uses some of its parts, which would leave the flag unset and
/// Ctrl-C unseen). Returns whether it had been replaced. A process without
/// an iceoryx2 node to ask (the runner) calls it as it polls the flag.
pub fn ensure_installed() -> bool {
    let mut replaced = false;
    for sig in [libc::SIGINT, libc::SIGTERM] {
        // SAFETY: querying the current action into a zeroed struct.
        let current = unsafe {
            let mut old: libc::sigaction = std::mem::zeroed();
            libc::sigaction(sig, std::ptr::null(), &mut old);
            old.sa_sigaction
        };
        if current != on_signal as *const () as usize {
            replaced = true;
        }
    }
    if replaced {
        install();
    }
    replaced
}

/// Whether a stop was requested.
#[inline]
pub fn stop_requested() -> bool {
    STOP.load(Ordering::Relaxed)
}

/// A stop check for a busy loop: this process's own flag on every call, and
/// a second, costlier source (iceoryx2's latched termination request, which
/// costs a `nanosleep(0)` system call — a trip through the scheduler) only
/// on every `every`-th call, so that the loop's core is not handed away.
pub struct StopCheck<F: FnMut() -> bool> {
    costly: F,
    every: u32,
    calls: u32,
}

impl<F: FnMut() -> bool> StopCheck<F> {
    pub fn new(every: u32, costly: F) -> Self {
        StopCheck { costly, every: every.max(1), calls: 0 }
    }

    #[inline]
    pub fn requested(&mut self) -> bool {
        if stop_requested() {
            return true;
        }
        self.calls += 1;
        if self.calls >= self.every {
            self.calls = 0;
            return (self.costly)();
        }
        false
    }
}

