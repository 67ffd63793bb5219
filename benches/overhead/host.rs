//! The host: steal time, load average and other processes' CPU around
//! every interval; the facts the report opens with; thread placement.

use crate::args::Settings;
use netfi::host::{CpuTimes, StealTimer};
use netfi::service::signals::stop_requested;
use serde::Serialize;
use serde_json::{json, Value};
use std::time::{Duration, Instant};

/// The host's state over one interval.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct HostWindow {
    pub steal_ms: u64,
    pub steal_fraction: f64,
    /// 1-minute load average at the start and at the end. It counts this
    /// benchmark's own busy threads too (up to 2 during an interval) and
    /// lags by about a minute.
    pub load_start: f64,
    pub load_end: f64,
    /// Cores kept busy by other processes over the half second before the
    /// interval, while this benchmark was idle: the background load.
    pub background_busy_cores: f64,
    /// Cores kept busy by other processes during the interval: all busy
    /// CPU time less this benchmark's and its children's, over the
    /// interval's length (10 ms resolution).
    pub others_busy_cores: f64,
    /// Seconds spent waiting for a quiet host before the interval.
    pub waited_for_quiet_s: f64,
}

/// Started before an interval, stopped after it: its [`HostWindow`].
pub struct HostTimer {
    steal: StealTimer,
    load: f64,
    background: f64,
    waited_s: f64,
    busy: Option<CpuTimes>,
    own_s: f64,
    t0: Instant,
}

impl HostTimer {
    /// Starts an interval: first waits (up to the configured time) for the
    /// background load to fall to the configured level, if one is set.
    pub fn start(quiet: Option<(f64, f64)>) -> HostTimer {
        let t_wait = Instant::now();
        let mut background = busy_cores(Duration::from_millis(500));
        if let Some((cores, max_wait_s)) = quiet {
            let mut said = false;
            while background > cores && t_wait.elapsed().as_secs_f64() < max_wait_s && !stop_requested() {
                if !said {
                    println!("  (waiting for a quiet host: other processes keep {background:.2} cores busy, more than {cores})");
                    said = true;
                }
                std::thread::sleep(Duration::from_secs(5));
                background = busy_cores(Duration::from_millis(500));
            }
        }
        let waited_s = t_wait.elapsed().as_secs_f64() - 0.5;
        HostTimer {
            steal: StealTimer::start(),
            load: load_average(),
            background,
            waited_s,
            busy: CpuTimes::read(),
            own_s: own_cpu_s(),
            t0: Instant::now(),
        }
    }

    pub fn stop(&self) -> HostWindow {
        let steal = self.steal.stop();
        let elapsed = self.t0.elapsed().as_secs_f64();
        let others = match (self.busy, CpuTimes::read()) {
            (Some(a), Some(b)) if elapsed > 0.0 => {
                let busy_s = (b.busy - a.busy) as f64 / ticks_per_s();
                ((busy_s - (own_cpu_s() - self.own_s)) / elapsed).max(0.0)
            }
            _ => f64::NAN,
        };
        HostWindow {
            steal_ms: steal.ms,
            steal_fraction: steal.fraction,
            load_start: self.load,
            load_end: load_average(),
            background_busy_cores: self.background,
            others_busy_cores: others,
            waited_for_quiet_s: self.waited_s.max(0.0),
        }
    }
}

fn ticks_per_s() -> f64 {
    // SAFETY: sysconf only reads a configuration value.
    let t = unsafe { libc::sysconf(libc::_SC_CLK_TCK) };
    if t > 0 {
        t as f64
    } else {
        100.0
    }
}

/// CPU seconds used by this process and by its children that have been
/// waited for (the emulator, `netfi run` and its services).
fn own_cpu_s() -> f64 {
    let secs = |who: libc::c_int| {
        // SAFETY: a zeroed rusage is a valid output buffer for getrusage.
        let mut u: libc::rusage = unsafe { std::mem::zeroed() };
        // SAFETY: `u` is a valid, writable rusage.
        if unsafe { libc::getrusage(who, &mut u) } != 0 {
            return 0.0;
        }
        let tv = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 / 1e6;
        tv(u.ru_utime) + tv(u.ru_stime)
    };
    secs(libc::RUSAGE_SELF) + secs(libc::RUSAGE_CHILDREN)
}

/// Cores busy on average over `window` (NaN where `/proc/stat` is
/// unreadable). Busy is time running tasks ([`CpuTimes::busy`]): interrupt
/// and softirq time is left out, as the kernel bills it to no process (UDP
/// loopback delivery runs there), and steal is reported on its own.
fn busy_cores(window: Duration) -> f64 {
    let cores = core_affinity::get_core_ids().map_or(1, |c| c.len()) as f64;
    let a = CpuTimes::read();
    std::thread::sleep(window);
    match (a, CpuTimes::read()) {
        (Some(a), Some(b)) if b.total > a.total => (b.busy - a.busy) as f64 / (b.total - a.total) as f64 * cores,
        _ => f64::NAN,
    }
}

fn load_average() -> f64 {
    std::fs::read_to_string("/proc/loadavg").ok().and_then(|s| s.split_whitespace().next().and_then(|x| x.parse().ok())).unwrap_or(f64::NAN)
}

/// The machine: cores, CPU model, kernel, clock source, and where the
/// benchmark placed the emulator and its own ends.
pub fn host_facts(s: &Settings) -> Value {
    let read = |p: &str| std::fs::read_to_string(p).map(|t| t.trim().to_string()).unwrap_or_default();
    let cpuinfo = read("/proc/cpuinfo");
    let model = cpuinfo.lines().find(|l| l.starts_with("model name")).and_then(|l| l.split(':').nth(1)).unwrap_or("").trim().to_string();
    json!({
        "cores": core_affinity::get_core_ids().map_or(0, |c| c.len()),
        "cpu_model": model,
        "kernel": read("/proc/sys/kernel/osrelease"),
        "clocksource": read("/sys/devices/system/clocksource/clocksource0/current_clocksource"),
        "emulator_core": s.emulator_core,
        "driver_core": s.driver_core,
    })
}

/// Pins the calling thread to `core` and, when asked, moves it to
/// SCHED_FIFO at `rt_priority`.
pub fn pin(core: Option<usize>, rt_priority: Option<i32>) {
    if let Some(c) = core {
        if !core_affinity::set_for_current(core_affinity::CoreId { id: c }) {
            eprintln!("overhead: could not pin a thread to core {c}");
        }
    }
    if let Some(p) = rt_priority {
        if let Err(e) = netfi::service::set_realtime(p) {
            eprintln!("overhead: SCHED_FIFO {p} refused ({e}); staying at normal priority");
        }
    }
}

/// How fast the calling thread's core runs right now, in two fixed
/// workloads, ns a step: a chain of dependent integer operations, and a
/// pointer chase over 16 MiB (past a core's L2, within this machine's L3).
/// The host of a virtual machine can slow both by half for minutes (clock
/// frequency, other guests on the same caches and memory bus) with no
/// steal time at all; a trial run in such a phase says so here.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Speed {
    pub alu_ns: f64,
    pub chase_ns: f64,
}

/// Measures [`Speed`] (about 60 ms; the chase's table is built once).
pub fn speed() -> Speed {
    static CYCLE: std::sync::OnceLock<Vec<u32>> = std::sync::OnceLock::new();
    let cycle = CYCLE.get_or_init(|| {
        // One cycle through every slot, in a seeded random order (Sattolo).
        let n = 4 << 20;
        let mut order: Vec<u32> = (0..n as u32).collect();
        for i in (1..n).rev() {
            let j = (netfi::scenario::splitmix64(i as u64) % i as u64) as usize;
            order.swap(i, j);
        }
        let mut next = vec![0u32; n];
        for k in 0..n {
            next[order[k] as usize] = order[(k + 1) % n];
        }
        next
    });
    const ALU: u64 = 20_000_000;
    let t = Instant::now();
    let mut x = 0x9e37_79b9_7f4a_7c15u64;
    for _ in 0..ALU {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
    }
    std::hint::black_box(x);
    let alu_ns = t.elapsed().as_nanos() as f64 / ALU as f64;
    const CHASE: usize = 500_000;
    let t = Instant::now();
    let mut at = 0u32;
    for _ in 0..CHASE {
        at = cycle[at as usize];
    }
    std::hint::black_box(at);
    Speed { alu_ns, chase_ns: t.elapsed().as_nanos() as f64 / CHASE as f64 }
}
