//! The host over time: while a part runs, a thread reads `/proc/stat` and
//! the CPU time of this benchmark's processes once a window, so that every
//! frame can be put in a window with its steal and the CPU other processes
//! used, and figures can be taken over the quiet windows only.

use netfi::clock::now_ns;
use netfi::host::CpuTimes;
use serde::Serialize;
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

/// One window of a part.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Window {
    pub start_ns: u64,
    pub end_ns: u64,
    /// Steal, summed over all CPUs, and as a fraction of all CPU time.
    pub steal_ms: u64,
    pub steal_fraction: f64,
    /// Cores kept busy by processes other than this benchmark, the
    /// emulator and the Python console and robot.
    pub others_busy_cores: f64,
    /// Steal at most the quiet fraction.
    pub quiet: bool,
    /// Quiet, and other processes under the calm limit.
    pub calm: bool,
}

struct Sample {
    t_ns: u64,
    cpu: CpuTimes,
    /// CPU ticks of this process and its children (living or gone).
    ours: u64,
}

/// The sampling thread of one part.
pub struct Sampler {
    stop: Arc<AtomicBool>,
    handle: JoinHandle<Vec<Sample>>,
}

impl Sampler {
    pub fn start(window_s: f64) -> Sampler {
        let stop = Arc::new(AtomicBool::new(false));
        let flag = stop.clone();
        let handle = std::thread::spawn(move || {
            let mut ticks = BTreeMap::new();
            let mut samples = vec![sample(&mut ticks)];
            let step = Duration::from_secs_f64(window_s);
            while !flag.load(Ordering::Relaxed) {
                let next = samples.last().map_or(0, |s| s.t_ns) + step.as_nanos() as u64;
                while now_ns() < next && !flag.load(Ordering::Relaxed) {
                    std::thread::sleep(Duration::from_millis(5).min(Duration::from_nanos(next.saturating_sub(now_ns()))));
                }
                samples.push(sample(&mut ticks));
            }
            samples
        });
        Sampler { stop, handle }
    }

    /// Stops sampling; the windows, each marked quiet and calm or not.
    pub fn stop(self, quiet_steal: f64, quiet_others: f64) -> Vec<Window> {
        self.stop.store(true, Ordering::Relaxed);
        let samples = self.handle.join().unwrap_or_default();
        samples.windows(2).map(|w| window(&w[0], &w[1], quiet_steal, quiet_others)).collect()
    }
}

fn window(a: &Sample, b: &Sample, quiet_steal: f64, quiet_others: f64) -> Window {
    let steal = b.cpu.steal_since(&a.cpu);
    let secs = (b.t_ns - a.t_ns) as f64 / 1e9;
    let busy = b.cpu.busy.saturating_sub(a.cpu.busy) as f64 - b.ours.saturating_sub(a.ours) as f64;
    // /proc reports CPU time in USER_HZ ticks, 100 a second (as netfi::host).
    let others = (busy / 100.0 / secs).max(0.0);
    Window {
        start_ns: a.t_ns,
        end_ns: b.t_ns,
        steal_ms: steal.ms,
        steal_fraction: steal.fraction,
        others_busy_cores: others,
        quiet: steal.fraction <= quiet_steal,
        calm: steal.fraction <= quiet_steal && others <= quiet_others,
    }
}

fn sample(ticks: &mut BTreeMap<u32, u64>) -> Sample {
    let me = std::process::id();
    ticks.insert(me, proc_ticks(me).map_or(0, |(_, t)| t));
    for pid in children(me) {
        if let Some((_, t)) = proc_ticks(pid) {
            ticks.insert(pid, t);
        }
    }
    Sample { t_ns: now_ns(), cpu: CpuTimes::read().unwrap_or_default(), ours: ticks.values().sum() }
}

/// (parent pid, user + system ticks) of `pid`, from `/proc/<pid>/stat`.
fn proc_ticks(pid: u32) -> Option<(u32, u64)> {
    let text = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // The fields after the command name (which may hold spaces): state,
    // ppid, …; utime and stime are fields 14 and 15 of the line.
    let rest: Vec<&str> = text.rsplit_once(')')?.1.split_whitespace().collect();
    let field = |i: usize| rest.get(i).and_then(|v| v.parse::<u64>().ok());
    Some((field(1)? as u32, field(11)? + field(12)?))
}

/// The processes whose parent is `parent`.
fn children(parent: u32) -> Vec<u32> {
    let Ok(dir) = std::fs::read_dir("/proc") else { return Vec::new() };
    dir.filter_map(|e| e.ok()?.file_name().to_str()?.parse::<u32>().ok()).filter(|&pid| proc_ticks(pid).is_some_and(|(pp, _)| pp == parent)).collect()
}

/// The index of the window `t_ns` falls in, if any.
pub fn find(windows: &[Window], t_ns: u64) -> Option<usize> {
    let i = windows.partition_point(|w| w.end_ns <= t_ns);
    (i < windows.len() && windows[i].start_ns <= t_ns).then_some(i)
}
