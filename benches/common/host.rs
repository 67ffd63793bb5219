//! The host: what machine it is ([`HostFacts`]), its state over a
//! measurement ([`HostTimer`]: steal time, load average, the CPU other
//! processes used), how fast its core runs right now ([`speed`]), thread
//! placement ([`pin`]) and the emulator's core cleared ([`clear_core`]).

use crate::common::args::{online_cores, stopped, Placement};
use netfi::host::isolate::Isolation;
use netfi::host::{CpuTimes, StealTimer};
use serde::Serialize;
use std::time::{Duration, Instant};

/// The machine.
#[derive(Debug, Clone, Serialize)]
pub struct HostFacts {
    pub cores: usize,
    pub cpu_model: String,
    pub kernel: String,
    pub clocksource: String,
}

impl HostFacts {
    pub fn read() -> HostFacts {
        let read = |p: &str| std::fs::read_to_string(p).map(|t| t.trim().to_string()).unwrap_or_default();
        let cpuinfo = read("/proc/cpuinfo");
        let model = cpuinfo.lines().find(|l| l.starts_with("model name")).and_then(|l| l.split(':').nth(1)).unwrap_or("").trim();
        HostFacts {
            cores: online_cores().len(),
            cpu_model: model.to_string(),
            kernel: read("/proc/sys/kernel/osrelease"),
            clocksource: read("/sys/devices/system/clocksource/clocksource0/current_clocksource"),
        }
    }

    /// One line: "2 cores (MODEL), kernel K, clock source C".
    pub fn line(&self) -> String {
        format!("{} cores ({}), kernel {}, clock source {}", self.cores, self.cpu_model, self.kernel, self.clocksource)
    }
}

/// The host's state over one measurement.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct HostWindow {
    pub seconds: f64,
    pub steal_ms: u64,
    pub steal_fraction: f64,
    /// 1-minute load average at the start and at the end. It counts the
    /// benchmark's own busy threads too and lags by about a minute.
    pub load_start: f64,
    pub load_end: f64,
    /// Cores other processes kept busy over the half second before the
    /// measurement, while the benchmark was idle.
    pub background_busy_cores: f64,
    /// Cores other processes kept busy during it: all busy CPU time less
    /// the benchmark's and its children's, over its length (10 ms
    /// resolution).
    pub others_busy_cores: f64,
    /// Seconds spent waiting for a quiet host first (`--quiet-cores`).
    pub waited_for_quiet_s: f64,
}

impl HostWindow {
    /// "steal 0.12%, load 1.0→1.2, others 0.01 cores".
    pub fn line(&self) -> String {
        format!("steal {:.2}%, load {:.1}→{:.1}, others {:.2} cores", self.steal_fraction * 100.0, self.load_start, self.load_end, self.others_busy_cores)
    }
}

/// Started before a measurement, stopped after it: its [`HostWindow`].
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
    /// Starts a measurement; with `quiet` (`cores`, `wait_s`), first waits
    /// up to `wait_s` for other processes to keep at most `cores` busy.
    pub fn start(quiet: Option<(f64, f64)>) -> HostTimer {
        let t_wait = Instant::now();
        let mut background = busy_cores(Duration::from_millis(500));
        if let Some((cores, wait_s)) = quiet {
            while background > cores && t_wait.elapsed().as_secs_f64() < wait_s && !stopped() {
                std::thread::sleep(Duration::from_secs(5));
                background = busy_cores(Duration::from_millis(500));
            }
        }
        HostTimer {
            steal: StealTimer::start(),
            load: load_average(),
            background,
            waited_s: (t_wait.elapsed().as_secs_f64() - 0.5).max(0.0),
            busy: CpuTimes::read(),
            own_s: own_cpu_s(),
            t0: Instant::now(),
        }
    }

    /// Starts a window without the half-second look at the background
    /// (for a whole program, or windows back to back).
    pub fn now() -> HostTimer {
        HostTimer { steal: StealTimer::start(), load: load_average(), background: f64::NAN, waited_s: 0.0, busy: CpuTimes::read(), own_s: own_cpu_s(), t0: Instant::now() }
    }

    pub fn stop(&self) -> HostWindow {
        let steal = self.steal.stop();
        let seconds = self.t0.elapsed().as_secs_f64();
        let others = match (self.busy, CpuTimes::read()) {
            (Some(a), Some(b)) if seconds > 0.0 => {
                let busy_s = (b.busy - a.busy) as f64 / ticks_per_s();
                ((busy_s - (own_cpu_s() - self.own_s)) / seconds).max(0.0)
            }
            _ => f64::NAN,
        };
        HostWindow {
            seconds,
            steal_ms: steal.ms,
            steal_fraction: steal.fraction,
            load_start: self.load,
            load_end: load_average(),
            background_busy_cores: self.background,
            others_busy_cores: others,
            waited_for_quiet_s: self.waited_s,
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

/// CPU seconds of this process and of its children that have been waited
/// for (the emulators, `netfi run` and its services).
fn own_cpu_s() -> f64 {
    cpu_s(libc::RUSAGE_SELF) + cpu_s(libc::RUSAGE_CHILDREN)
}

/// User and system CPU seconds of `who` (`RUSAGE_SELF`, or the children
/// waited for so far: `RUSAGE_CHILDREN`).
pub fn cpu_s(who: libc::c_int) -> f64 {
    // SAFETY: a zeroed rusage is a valid output buffer for getrusage.
    let mut u: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: `u` is a valid, writable rusage.
    if unsafe { libc::getrusage(who, &mut u) } != 0 {
        return f64::NAN;
    }
    let tv = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 / 1e6;
    tv(u.ru_utime) + tv(u.ru_stime)
}

/// Cores busy on average over `window` (NaN where `/proc/stat` is
/// unreadable). Interrupt time is left out ([`CpuTimes::busy`]): the kernel
/// bills it to no process; steal is reported on its own.
fn busy_cores(window: Duration) -> f64 {
    let cores = online_cores().len().max(1) as f64;
    let a = CpuTimes::read();
    std::thread::sleep(window);
    match (a, CpuTimes::read()) {
        (Some(a), Some(b)) if b.total > a.total => (b.busy - a.busy) as f64 / (b.total - a.total) as f64 * cores,
        _ => f64::NAN,
    }
}

pub fn load_average() -> f64 {
    std::fs::read_to_string("/proc/loadavg").ok().and_then(|s| s.split_whitespace().next().and_then(|x| x.parse().ok())).unwrap_or(f64::NAN)
}

/// Pins the calling thread to `core` and, when asked, moves it to
/// SCHED_FIFO at `rt_priority`; says so where either is refused.
pub fn pin(core: Option<usize>, rt_priority: Option<i32>) {
    if let Some(c) = core {
        if !core_affinity::set_for_current(core_affinity::CoreId { id: c }) {
            eprintln!("could not pin a thread to core {c}");
        }
    }
    if let Some(p) = rt_priority {
        if let Err(e) = netfi::host::placement::set_realtime(p) {
            eprintln!("SCHED_FIFO {p} refused ({e}); staying at normal priority");
        }
    }
}

/// Clears the emulator's core for the program, when `p.isolate`: every
/// thread of other processes that may run elsewhere and every device
/// interrupt moved off it (`netfi::host::isolate`, what `netfi run` does
/// for a run), all put back when the value is dropped. The floors and
/// probes run on the cleared core too. First puts back what an interrupted
/// earlier program left moved.
pub fn clear_core(p: &Placement) -> Option<Isolation> {
    if let Ok(done) = netfi::host::record::restore_orphans(None) {
        for (path, r) in done {
            println!("  (restored {} placement(s) left moved by an interrupted earlier run, from {})", r.undone, path.display());
        }
    }
    let core = p.emulator_core.filter(|_| p.isolate)?;
    match netfi::host::isolate::isolate(core) {
        Ok(iso) => {
            println!("  {} (for the benchmark)", iso.summary());
            Some(iso)
        }
        Err(e) => {
            println!("  (could not clear core {core}: {e}; measuring without)");
            None
        }
    }
}

/// Puts back what [`clear_core`] moved; what it had done, in words and as
/// JSON.
pub fn restore_core(iso: Option<Isolation>) -> (String, serde_json::Value) {
    match iso {
        Some(mut i) => {
            let s = i.restore();
            (format!("The emulator's core was cleared for the benchmark and put back after: {s}."), serde_json::json!(s))
        }
        None => ("The emulator's core was not cleared: other threads could run on it.".into(), serde_json::Value::Null),
    }
}

/// How fast the calling thread's core runs right now, in two fixed
/// workloads, ns a step: a chain of dependent integer operations, and a
/// pointer chase over 16 MiB (past a core's L2). A virtual machine's host
/// can slow both by half for minutes with no steal time at all; a
/// measurement taken in such a phase says so here.
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
            order.swap(i, (netfi::scenario::splitmix64(i as u64) % i as u64) as usize);
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

/// [`speed`] measured on `core`.
pub fn speed_on(core: Option<usize>) -> Speed {
    std::thread::scope(|sc| {
        sc.spawn(|| {
            pin(core, None);
            speed()
        })
        .join()
        .unwrap_or(Speed { alu_ns: f64::NAN, chase_ns: f64::NAN })
    })
}
