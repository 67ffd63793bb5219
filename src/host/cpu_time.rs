//! CPU time and steal time from `/proc/stat`: the host's facts every
//! measurement is reported beside (steal: time the hypervisor ran someone
//! else while this VM wanted to run). A leaf: it knows nothing of netfi.

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
