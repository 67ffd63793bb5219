//! Clearing a core for a busy-polling loop, for the length of a run.
//!
//! Pinning the emulator to a core keeps it from moving, not others from
//! coming: every thread allowed on that core may still be scheduled there,
//! and the loop then loses the core for as long as that thread runs. On a
//! virtual machine the worst offenders are kernel threads — a memory
//! monitor (`kdamond`) waking every few milliseconds and running for up to
//! seven, RCU, unbound workqueue workers — and device interrupts. Each such
//! preemption makes every frame due in it late by what is left of it.
//!
//! [`isolate`] moves every thread of other processes that is allowed on
//! the core *and elsewhere* off it, narrows the unbound workqueues' CPU mask
//! and the device interrupts' affinity the same way, and remembers what it
//! changed; [`Isolation::restore`] (also on drop) puts each back, unless
//! something else changed it meanwhile. Threads bound to that core alone
//! (per-CPU kernel threads, the timer interrupt) stay: nothing can move
//! them. Threads created while isolated inherit their parent's narrowed
//! mask and keep it. This is what `tuna --isolate` or a `cpuset` partition
//! does, for one run, without a reboot (`isolcpus=` and `nohz_full=` do it
//! for good, and better).
//!
//! Moving other users' threads and interrupts needs root or CAP_SYS_NICE;
//! without it only the caller's own processes move, and the summary says
//! what stayed and why.

use serde::{Deserialize, Serialize};
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

const WORKQUEUE_MASK: &str = "/sys/devices/virtual/workqueue/cpumask";

/// What [`isolate`] did, for reports.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct IsolationSummary {
    /// The core cleared.
    pub core: usize,
    /// Threads of other processes moved off the core.
    pub threads_moved: usize,
    /// Names of the kernel threads among them (e.g. `kdamond.0`, `rcu_preempt`).
    pub kernel_threads_moved: Vec<String>,
    /// Threads allowed on that core only (per-CPU kernel threads): left there.
    pub threads_bound_to_core: usize,
    /// Threads that could have moved but the kernel refused (no permission,
    /// or a kernel thread whose affinity is fixed), with a few names.
    pub threads_refused: usize,
    pub refused_examples: Vec<String>,
    /// Device interrupts whose affinity no longer includes the core.
    pub irqs_moved: usize,
    /// Interrupts that could not be moved (managed by their driver, or no
    /// permission).
    pub irqs_refused: usize,
    /// Whether the unbound workqueues' CPU mask was narrowed.
    pub workqueues_moved: bool,
    /// Set by [`Isolation::restore`]: how many changes were undone.
    #[serde(default)]
    pub restored: Option<usize>,
}

impl std::fmt::Display for IsolationSummary {
    /// One line: `core 1 cleared: 39 threads moved (kernel: kdamond.0 …), 9
    /// bound to it, 22 refused; 18 interrupts moved, 1 refused[; 58 restored]`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let kernel = if self.kernel_threads_moved.is_empty() { "none".to_string() } else { self.kernel_threads_moved.join(" ") };
        write!(
            f,
            "core {} cleared: {} threads moved (kernel: {kernel}), {} bound to it, {} refused; {} interrupts moved, {} refused",
            self.core, self.threads_moved, self.threads_bound_to_core, self.threads_refused, self.irqs_moved, self.irqs_refused
        )?;
        match self.restored {
            Some(n) => write!(f, "; {n} restored"),
            None => Ok(()),
        }
    }
}

/// What was changed, so it can be undone, also by another process (the
/// runner, when the emulator that isolated its core was killed).
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct IsolationState {
    pub core: usize,
    /// (thread id, CPUs allowed before, CPUs allowed after).
    pub threads: Vec<(i32, Vec<usize>, Vec<usize>)>,
    /// (irq number, `smp_affinity_list` before).
    pub irqs: Vec<(u32, String)>,
    /// The workqueue mask before, when narrowed.
    pub workqueue: Option<String>,
}

/// A cleared core; restores on drop.
#[derive(Debug)]
pub struct Isolation {
    state: IsolationState,
    summary: IsolationSummary,
    /// Where the state is saved while isolated (removed after restoring).
    state_file: Option<PathBuf>,
    restored: bool,
}

impl Isolation {
    pub fn summary(&self) -> &IsolationSummary {
        &self.summary
    }

    /// Puts back every thread, interrupt and workqueue mask changed, and
    /// returns the summary with `restored` set.
    pub fn restore(&mut self) -> IsolationSummary {
        if !self.restored {
            self.restored = true;
            self.summary.restored = Some(restore_state(&self.state));
            if let Some(f) = &self.state_file {
                let _ = std::fs::remove_file(f);
            }
        }
        self.summary.clone()
    }
}

impl Drop for Isolation {
    fn drop(&mut self) {
        self.restore();
    }
}

/// Clears `core` of everything that may run elsewhere, except the threads
/// of the calling process (it places its own). When `state_file` is given,
/// every change is put on record there *before* it is made (and the record
/// narrowed to what was made afterwards), so [`restore_from_file`] can undo
/// it should the caller die at any point without restoring.
pub fn isolate(core: usize, state_file: Option<&Path>) -> std::io::Result<Isolation> {
    let online = online_cpus();
    if !online.contains(&core) {
        return Err(std::io::Error::new(std::io::ErrorKind::InvalidInput, format!("core {core} is not online (online: {})", format_list(&online))));
    }
    if online.len() < 2 {
        return Err(std::io::Error::new(std::io::ErrorKind::InvalidInput, "only one core is online: nowhere to move anything to"));
    }
    let own = std::process::id() as i32;
    let mut summary = IsolationSummary { core, ..Default::default() };

    // 1. The plan: every thread, the workqueue mask and every interrupt
    // that may run on `core` and elsewhere.
    let mut plan = IsolationState { core, ..Default::default() };
    let mut kernel_tids = BTreeSet::new();
    for pid in numeric_entries(Path::new("/proc")) {
        if pid as i32 == own {
            continue;
        }
        let kernel = is_kernel_thread(pid);
        for tid in numeric_entries(&Path::new("/proc").join(pid.to_string()).join("task")) {
            let tid = tid as i32;
            let Some(before) = get_affinity(tid) else { continue };
            if !before.contains(&core) {
                continue;
            }
            let after: BTreeSet<usize> = before.iter().copied().filter(|&c| c != core).collect();
            if after.is_empty() {
                summary.threads_bound_to_core += 1;
                continue;
            }
            if kernel {
                kernel_tids.insert(tid);
            }
            plan.threads.push((tid, before.into_iter().collect(), after.into_iter().collect()));
        }
    }
    let mut workqueue_narrowed = None;
    if let Ok(text) = std::fs::read_to_string(WORKQUEUE_MASK) {
        if let Some(mask) = parse_mask(text.trim()) {
            let narrowed: BTreeSet<usize> = mask.iter().copied().filter(|&c| c != core).collect();
            if mask.contains(&core) && !narrowed.is_empty() {
                plan.workqueue = Some(text.trim().to_string());
                workqueue_narrowed = Some(format_mask(&narrowed));
            }
        }
    }
    let mut irq_narrowed = Vec::new();
    for irq in numeric_entries(Path::new("/proc/irq")) {
        let Ok(text) = std::fs::read_to_string(irq_list_path(irq as u32)) else { continue };
        let Some(cpus) = parse_list(text.trim()) else { continue };
        let narrowed: BTreeSet<usize> = cpus.iter().copied().filter(|&c| c != core && online.contains(&c)).collect();
        if cpus.contains(&core) && !narrowed.is_empty() {
            plan.irqs.push((irq as u32, text.trim().to_string()));
            irq_narrowed.push(format_list(&narrowed));
        }
    }
    // 2. On record before anything moves: restoring a change that was
    // never made is harmless (a thread is put back only while its mask is
    // still the planned one; an interrupt or the workqueues get their own
    // value again).
    let save = |state: &IsolationState| -> std::io::Result<()> {
        match state_file {
            Some(f) => std::fs::write(f, serde_json::to_vec(state).map_err(std::io::Error::other)?),
            None => Ok(()),
        }
    };
    save(&plan)?;

    // 3. The moves.
    let mut state = IsolationState { core, ..Default::default() };
    let mut kernel_names = BTreeSet::new();
    let mut refused_names = BTreeSet::new();
    for (tid, before, after) in plan.threads {
        match set_affinity(tid, &after.iter().copied().collect()) {
            Ok(()) => {
                summary.threads_moved += 1;
                if kernel_tids.contains(&tid) {
                    kernel_names.insert(comm(tid));
                }
                state.threads.push((tid, before, after));
            }
            Err(e) if e.raw_os_error() == Some(libc::ESRCH) => {}
            Err(_) => {
                summary.threads_refused += 1;
                if refused_names.len() < 8 {
                    refused_names.insert(comm(tid));
                }
            }
        }
    }
    // Unbound workqueue workers cannot be moved one by one; their mask can.
    if let (Some(before), Some(narrowed)) = (plan.workqueue, workqueue_narrowed) {
        if std::fs::write(WORKQUEUE_MASK, narrowed).is_ok() {
            state.workqueue = Some(before);
            summary.workqueues_moved = true;
        }
    }
    for ((irq, before), narrowed) in plan.irqs.into_iter().zip(irq_narrowed) {
        if std::fs::write(irq_list_path(irq), narrowed).is_ok() {
            summary.irqs_moved += 1;
            state.irqs.push((irq, before));
        } else {
            summary.irqs_refused += 1;
        }
    }
    summary.kernel_threads_moved = kernel_names.into_iter().collect();
    summary.refused_examples = refused_names.into_iter().collect();
    // The planned record, a superset, stays if this fails.
    let _ = save(&state);
    Ok(Isolation { state, summary, state_file: state_file.map(Path::to_path_buf), restored: false })
}

/// Undoes what an [`isolate`] that saved its state to `path` changed, when
/// the file is still there (its owner died before restoring), and removes
/// the file. Returns how many changes were undone, `None` without a file.
pub fn restore_from_file(path: &Path) -> Option<usize> {
    let text = std::fs::read(path).ok()?;
    let _ = std::fs::remove_file(path);
    let state: IsolationState = serde_json::from_slice(&text).ok()?;
    Some(restore_state(&state))
}

fn restore_state(state: &IsolationState) -> usize {
    let mut undone = 0;
    for (tid, before, after) in &state.threads {
        // Only where the mask is still ours: a later change by someone else stands.
        let now = get_affinity(*tid);
        let ours: BTreeSet<usize> = after.iter().copied().collect();
        if now.as_ref() == Some(&ours) && set_affinity(*tid, &before.iter().copied().collect()).is_ok() {
            undone += 1;
        }
    }
    for (irq, before) in &state.irqs {
        if std::fs::write(irq_list_path(*irq), before).is_ok() {
            undone += 1;
        }
    }
    if let Some(before) = &state.workqueue {
        if std::fs::write(WORKQUEUE_MASK, before).is_ok() {
            undone += 1;
        }
    }
    undone
}

fn irq_list_path(irq: u32) -> PathBuf {
    PathBuf::from(format!("/proc/irq/{irq}/smp_affinity_list"))
}

fn numeric_entries(dir: &Path) -> Vec<u64> {
    let Ok(rd) = std::fs::read_dir(dir) else { return Vec::new() };
    rd.filter_map(|e| e.ok()?.file_name().to_str()?.parse().ok()).collect()
}

/// Kernel threads are children of kthreadd (pid 2), or kthreadd itself.
fn is_kernel_thread(pid: u64) -> bool {
    if pid == 2 {
        return true;
    }
    let Ok(stat) = std::fs::read_to_string(format!("/proc/{pid}/stat")) else { return false };
    // The name may hold spaces and parentheses: the fields after it start
    // after the last ')'. They are: state, ppid, ...
    stat.rsplit_once(')').and_then(|(_, rest)| rest.split_whitespace().nth(1)?.parse::<u64>().ok()) == Some(2)
}

fn comm(tid: i32) -> String {
    std::fs::read_to_string(format!("/proc/{tid}/comm")).map(|s| s.trim().to_string()).unwrap_or_else(|_| format!("tid {tid}"))
}

fn online_cpus() -> BTreeSet<usize> {
    std::fs::read_to_string("/sys/devices/system/cpu/online")
        .ok()
        .and_then(|t| parse_list(t.trim()))
        .unwrap_or_else(|| core_affinity::get_core_ids().unwrap_or_default().iter().map(|c| c.id).collect())
}

fn get_affinity(tid: i32) -> Option<BTreeSet<usize>> {
    // SAFETY: a zeroed cpu_set_t is a valid empty set, filled by the kernel.
    let mut set: libc::cpu_set_t = unsafe { std::mem::zeroed() };
    // SAFETY: `set` is valid for writes of its size.
    if unsafe { libc::sched_getaffinity(tid, std::mem::size_of::<libc::cpu_set_t>(), &mut set) } != 0 {
        return None;
    }
    // SAFETY: CPU_ISSET reads the set only, for indices within its size.
    Some((0..libc::CPU_SETSIZE as usize).filter(|&c| unsafe { libc::CPU_ISSET(c, &set) }).collect())
}

fn set_affinity(tid: i32, cpus: &BTreeSet<usize>) -> std::io::Result<()> {
    // SAFETY: as in `get_affinity`; CPU_SET writes within the set's size.
    let mut set: libc::cpu_set_t = unsafe { std::mem::zeroed() };
    for &c in cpus.iter().filter(|&&c| c < libc::CPU_SETSIZE as usize) {
        unsafe { libc::CPU_SET(c, &mut set) };
    }
    // SAFETY: `set` is a valid cpu_set_t of the size passed.
    if unsafe { libc::sched_setaffinity(tid, std::mem::size_of::<libc::cpu_set_t>(), &set) } == 0 {
        Ok(())
    } else {
        Err(std::io::Error::last_os_error())
    }
}

/// Parses a CPU list as the kernel writes it: `0-3,8,10-11`.
pub fn parse_list(text: &str) -> Option<BTreeSet<usize>> {
    let mut set = BTreeSet::new();
    if text.is_empty() {
        return Some(set);
    }
    for part in text.split(',') {
        match part.split_once('-') {
            Some((a, b)) => {
                let (a, b): (usize, usize) = (a.trim().parse().ok()?, b.trim().parse().ok()?);
                if a > b {
                    return None;
                }
                set.extend(a..=b);
            }
            None => {
                set.insert(part.trim().parse().ok()?);
            }
        }
    }
    Some(set)
}

/// Writes a CPU list in the kernel's form, ranges folded: `0-3,8`.
pub fn format_list(cpus: &BTreeSet<usize>) -> String {
    let mut parts = Vec::new();
    let mut it = cpus.iter().copied().peekable();
    while let Some(start) = it.next() {
        let mut end = start;
        while it.peek() == Some(&(end + 1)) {
            end = it.next().unwrap_or(end);
        }
        parts.push(if start == end { start.to_string() } else { format!("{start}-{end}") });
    }
    parts.join(",")
}

/// Parses a hexadecimal CPU mask as the kernel writes it: 32-bit groups,
/// most significant first, separated by commas (`ff,00000003`).
pub fn parse_mask(text: &str) -> Option<BTreeSet<usize>> {
    let mut set = BTreeSet::new();
    let groups: Vec<&str> = text.split(',').collect();
    for (i, g) in groups.iter().rev().enumerate() {
        let v = u32::from_str_radix(g.trim(), 16).ok()?;
        for bit in 0..32 {
            if v & (1 << bit) != 0 {
                set.insert(i * 32 + bit);
            }
        }
    }
    Some(set)
}

/// Writes a CPU set as a hexadecimal mask in 32-bit groups.
pub fn format_mask(cpus: &BTreeSet<usize>) -> String {
    let groups = cpus.iter().next_back().map_or(1, |&m| m / 32 + 1);
    (0..groups)
        .rev()
        .map(|g| {
            let v: u32 = cpus.iter().filter(|&&c| c / 32 == g).fold(0, |v, &c| v | 1 << (c % 32));
            if g == groups - 1 {
                format!("{v:x}")
            } else {
                format!("{v:08x}")
            }
        })
        .collect::<Vec<_>>()
        .join(",")
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A child process, killed and reaped however the test ends.
    struct Witness(std::process::Child);

    impl Drop for Witness {
        fn drop(&mut self) {
            let _ = self.0.kill();
            let _ = self.0.wait();
        }
    }

    fn set(v: &[usize]) -> BTreeSet<usize> {
        v.iter().copied().collect()
    }

    #[test]
    fn cpu_lists_round_trip() {
        assert_eq!(parse_list("0-3,8,10-11"), Some(set(&[0, 1, 2, 3, 8, 10, 11])));
        assert_eq!(format_list(&set(&[0, 1, 2, 3, 8, 10, 11])), "0-3,8,10-11");
        assert_eq!(parse_list("1"), Some(set(&[1])));
        assert_eq!(format_list(&set(&[1])), "1");
        assert_eq!(parse_list(""), Some(set(&[])));
        assert_eq!(parse_list("3-1"), None);
        assert_eq!(parse_list("a"), None);
    }

    #[test]
    fn cpu_masks_round_trip() {
        assert_eq!(parse_mask("3"), Some(set(&[0, 1])));
        assert_eq!(parse_mask("00000003"), Some(set(&[0, 1])));
        assert_eq!(parse_mask("1,80000001"), Some(set(&[0, 31, 32])));
        assert_eq!(format_mask(&set(&[0, 31, 32])), "1,80000001");
        assert_eq!(format_mask(&set(&[1])), "2");
        assert_eq!(parse_mask("xyz"), None);
    }

    /// A child process of ours is moved off the core and put back; this
    /// needs no privilege (it is our own process) and two cores.
    #[test]
    fn moves_a_child_off_the_core_and_back() {
        let cores = online_cpus();
        if cores.len() < 2 {
            eprintln!("skipped: one core only");
            return;
        }
        let core = *cores.iter().next_back().unwrap();
        let child = Witness(std::process::Command::new("sleep").arg("30").spawn().expect("sleep"));
        let pid = child.0.id() as i32;
        let all = get_affinity(pid).unwrap();
        if !all.contains(&core) {
            eprintln!("skipped: this process may not run on core {core}");
            return;
        }
        let dir = std::env::temp_dir().join(format!("netfi-isolate-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("isolation.json");
        let mut iso = isolate(core, Some(&file)).expect("isolate");
        let moved = get_affinity(pid).unwrap();
        assert!(!moved.contains(&core), "child still allowed on core {core}: {moved:?}");
        assert_eq!(moved.len(), all.len() - 1);
        assert!(iso.summary().threads_moved >= 1);
        assert!(file.exists());
        let s = iso.restore();
        assert!(s.restored.unwrap() >= 1);
        assert_eq!(get_affinity(pid).unwrap(), all);
        assert!(!file.exists(), "state file left after restoring");
        // Restoring from a saved state, as the runner does for a killed emulator.
        let iso2 = isolate(core, Some(&file)).expect("isolate");
        assert!(!get_affinity(pid).unwrap().contains(&core));
        std::mem::forget(iso2);
        assert!(restore_from_file(&file).unwrap() >= 1);
        assert_eq!(get_affinity(pid).unwrap(), all);
        assert_eq!(restore_from_file(&file), None);
        drop(child);
        let _ = std::fs::remove_dir_all(&dir);
    }
}
