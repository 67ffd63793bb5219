//! The one clock (docs/spec.md §1): CLOCK_MONOTONIC nanoseconds, shared by every
//! process on a host, and the waiting strategies built on it. Used by the
//! services only; the sans-IO core never reads a clock.

/// CLOCK_MONOTONIC now, in ns. A vDSO call: no system call on Linux.
#[inline]
pub fn now_ns() -> u64 {
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: `ts` is a valid, writable timespec; CLOCK_MONOTONIC always exists.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    debug_assert_eq!(rc, 0);
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

/// CLOCK_MONOTONIC now, or as soon as it reaches `t_ns`: busy-waits on the
/// clock alone until then. For a release prepared ahead of its time.
#[inline]
pub fn now_from_ns(t_ns: u64) -> u64 {
    loop {
        let now = now_ns();
        if now >= t_ns {
            return now;
        }
        std::hint::spin_loop();
    }
}

/// Sleeps until the absolute CLOCK_MONOTONIC time `t_ns` (may wake late by
/// the scheduler's latency; never early).
pub fn sleep_until_ns(t_ns: u64) {
    let ts = libc::timespec { tv_sec: (t_ns / 1_000_000_000) as libc::time_t, tv_nsec: (t_ns % 1_000_000_000) as libc::c_long };
    loop {
        // SAFETY: `ts` is a valid timespec; the remainder pointer may be null with TIMER_ABSTIME.
        let rc = unsafe { libc::clock_nanosleep(libc::CLOCK_MONOTONIC, libc::TIMER_ABSTIME, &ts, std::ptr::null_mut()) };
        if rc != libc::EINTR {
            return;
        }
    }
}

/// How a process waits for a moment or for work.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Wait {
    /// Pure busy-wait: for a process pinned to a core of its own.
    Spin,
    /// Busy-wait, but offer the core to other runnable threads on each turn
    /// (`sched_yield`): for processes that share a core.
    SpinYield,
    /// Sleep this many nanoseconds between polls: for many processes that
    /// share few cores, none of which may spin.
    Nap(u64),
}

impl Wait {
    /// One turn of a polling loop.
    #[inline]
    pub fn relax(self) {
        match self {
            Wait::Spin => std::hint::spin_loop(),
            Wait::SpinYield => std::thread::yield_now(),
            Wait::Nap(ns) => std::thread::sleep(std::time::Duration::from_nanos(ns)),
        }
    }
}

/// Waits until `t_ns`: sleeps until `slack_ns` before it, then polls.
/// Returns the time it woke.
pub fn wait_until_ns(t_ns: u64, slack_ns: u64, wait: Wait) -> u64 {
    let now = now_ns();
    if t_ns > now + slack_ns {
        sleep_until_ns(t_ns - slack_ns);
    }
    loop {
        let now = now_ns();
        if now >= t_ns {
            return now;
        }
        wait.relax();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_clock_is_monotonic_and_waits_are_never_early() {
        let a = now_ns();
        let target = a + 2_000_000;
        let woke = wait_until_ns(target, 500_000, Wait::SpinYield);
        assert!(woke >= target);
        assert!(now_ns() >= woke);
        // The same clock as std's Instant (both CLOCK_MONOTONIC on Linux):
        // an interval measured both ways agrees to well under a millisecond.
        let (i0, c0) = (std::time::Instant::now(), now_ns());
        std::thread::sleep(std::time::Duration::from_millis(5));
        let (di, dc) = (i0.elapsed().as_nanos() as i128, (now_ns() - c0) as i128);
        assert!((di - dc).abs() < 1_000_000, "Instant {di} ns vs clock {dc} ns");
    }
}
