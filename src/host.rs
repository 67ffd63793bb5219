//! Facts about the host that every measurement is reported beside: CPU steal
//! time (time the hypervisor ran someone else while this VM wanted to run).
//! Not part of the sans-IO core: it reads `/proc/stat`.

pub mod isolate;
pub mod record;

/// The set of this machine's cores without `core`, for keeping threads off
/// a busy-polling loop's core; `None` where no other core exists.
pub fn cores_except(core: usize) -> Option<libc::cpu_set_t> {
    let cores = core_affinity::get_core_ids().unwrap_or_default();
    // SAFETY: a zeroed cpu_set_t is a valid empty set; CPU_SET only writes into it.
    let mut set: libc::cpu_set_t = unsafe { std::mem::zeroed() };
    let mut any = false;
    for c in cores.iter().filter(|c| c.id != core) {
        // SAFETY: as above; c.id is a core index the kernel reported.
        unsafe { libc::CPU_SET(c.id, &mut set) };
        any = true;
    }
    any.then_some(set)
}

/// Moves `thread` off `core`: the CPUs it may use now, less `core`. Its own
/// set, not the caller's: the caller is usually the loop, already pinned to
/// `core`, whose set would leave nothing. `false` where `core` is the only
/// CPU the thread may use, or the kernel refused.
pub fn keep_thread_off_core(thread: libc::pthread_t, core: usize) -> bool {
    let size = std::mem::size_of::<libc::cpu_set_t>();
    // SAFETY: a zeroed cpu_set_t is a valid empty set; the calls only read
    // and write `set`, of the size given, for a thread the caller keeps alive.
    unsafe {
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        if libc::pthread_getaffinity_np(thread, size, &mut set) != 0 || core >= libc::CPU_SETSIZE as usize {
            return false;
        }
        libc::CPU_CLR(core, &mut set);
        libc::CPU_COUNT(&set) > 0 && libc::pthread_setaffinity_np(thread, size, &set) == 0
    }
}

/// Cumulative CPU times from `/proc/stat`, in clock ticks (USER_HZ, 100/s on
/// Linux).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct CpuTimes {
    /// All CPUs: the sum of every column.
    pub total: u64,
    /// All CPUs: the `steal` column.
    pub steal: u64,
    /// All CPUs: time running tasks (user, nice, system). Interrupt and
    /// softirq time is left out, as the kernel bills it to no process.
    pub busy: u64,
}

impl CpuTimes {
    /// Reads the aggregate `cpu` line; `None` where `/proc/stat` is missing
    /// or has no steal column.
    pub fn read() -> Option<CpuTimes> {
        let text = std::fs::read_to_string("/proc/stat").ok()?;
        Self::parse(&text)
    }

    pub fn parse(text: &str) -> Option<CpuTimes> {
        let line = text.lines().find(|l| l.starts_with("cpu "))?;
        let v: Vec<u64> = line.split_whitespace().skip(1).filter_map(|x| x.parse().ok()).collect();
        // user nice system idle iowait irq softirq steal guest guest_nice;
        // guest time is already counted in user, so it is not added again.
        let total = v.iter().take(8).sum();
        let busy = v.first()? + v.get(1)? + v.get(2)?;
        Some(CpuTimes { total, steal: *v.get(7)?, busy })
    }

    /// Steal over the interval from `earlier` to `self`.
    pub fn steal_since(&self, earlier: &CpuTimes) -> Steal {
        let ticks = self.steal.saturating_sub(earlier.steal);
        let total = self.total.saturating_sub(earlier.total);
        Steal { ms: ticks * 10, fraction: if total > 0 { ticks as f64 / total as f64 } else { 0.0 } }
    }
}

/// Measures steal time from its start to [`StealTimer::stop`].
#[derive(Debug, Clone, Copy)]
pub struct StealTimer(Option<CpuTimes>);

impl StealTimer {
    pub fn start() -> Self {
        StealTimer(CpuTimes::read())
    }

    /// Steal since the start (zero where `/proc/stat` is unreadable).
    pub fn stop(&self) -> Steal {
        match (self.0, CpuTimes::read()) {
            (Some(a), Some(b)) => b.steal_since(&a),
            _ => Steal::default(),
        }
    }
}

/// Steal time over an interval: milliseconds summed over all CPUs, and as a
/// fraction of all CPU time in the interval.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Steal {
    pub ms: u64,
    pub fraction: f64,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_the_aggregate_line() {
        let a = CpuTimes::parse("cpu  100 0 50 800 10 0 5 35 0 0\ncpu0 1 2 3\n").unwrap();
        assert_eq!(a, CpuTimes { total: 1000, steal: 35, busy: 150 });
        let b = CpuTimes::parse("cpu  200 0 100 1600 20 0 10 70 0 0\n").unwrap();
        let s = b.steal_since(&a);
        assert_eq!(s.ms, 350);
        assert!((s.fraction - 0.035).abs() < 1e-12);
        assert_eq!(CpuTimes::parse("intr 1 2\n"), None);
    }
}
