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
//! mask; restoring widens them again (see [`super::record`]). This is what
//! `tuna --isolate` or a `cpuset` partition does, for one run, without a
//! reboot (`isolcpus=` and `nohz_full=` do it for good, and better).
//!
//! Nothing of it outlives the run, whatever is killed: every change is in a
//! host-wide record before it is made, a guardian process restores when
//! the record's owners all die, and `netfi restore` (run first by every
//! `netfi run`) restores any record whose owners and guardian were all
//! killed ([`super::record`]).
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
    /// Set by [`Isolation::restore`]: threads started during the run that
    /// had inherited a narrowed mask, widened again.
    #[serde(default)]
    pub threads_widened: Option<usize>,
    /// Whether the core was cleared at all (false: see `warnings`).
    #[serde(default = "yes")]
    pub cleared: bool,
    /// What the user must know: a pin that could not be honoured, no
    /// guardian, a record that could not be kept.
    #[serde(default)]
    pub warnings: Vec<String>,
    /// The host-wide record of the changes while they last.
    #[serde(default)]
    pub record: Option<PathBuf>,
    /// The guardian process watching the record.
    #[serde(default)]
    pub guardian_pid: Option<u32>,
}

fn yes() -> bool {
    true
}

impl IsolationSummary {
    /// A core that was not cleared, and why.
    pub fn not_cleared(core: usize, warning: String) -> IsolationSummary {
        IsolationSummary { core, cleared: false, warnings: vec![warning], ..Default::default() }
    }
}

impl std::fmt::Display for IsolationSummary {
    /// One line: `core 1 cleared: 39 threads moved (kernel: kdamond.0 …), 9
    /// bound to it, 22 refused; 18 interrupts moved, 1 refused[; 58 restored]`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if !self.cleared {
            return write!(f, "nothing cleared: WARNING: {}", self.warnings.join("; WARNING: "));
        }
        let kernel = if self.kernel_threads_moved.is_empty() { "none".to_string() } else { self.kernel_threads_moved.join(" ") };
        write!(
            f,
            "core {} cleared: {} threads moved (kernel: {kernel}), {} bound to it, {} refused; {} interrupts moved, {} refused",
            self.core, self.threads_moved, self.threads_bound_to_core, self.threads_refused, self.irqs_moved, self.irqs_refused
        )?;
        if let Some(n) = self.restored {
            write!(f, "; {n} restored")?;
        }
        if let Some(n) = self.threads_widened.filter(|n| *n > 0) {
            write!(f, ", {n} threads started during the run widened")?;
        }
        for w in &self.warnings {
            write!(f, "; WARNING: {w}")?;
        }
        Ok(())
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
    summary: IsolationSummary,
    /// The host-wide record of what was changed (removed after restoring).
    record: Option<PathBuf>,
    restored: bool,
}

impl Isolation {
    /// A core that was not cleared, for the report: `warning` says why.
    pub fn not_cleared(core: usize, warning: String) -> Isolation {
        Isolation { summary: IsolationSummary::not_cleared(core, warning), record: None, restored: true }
    }

    pub fn summary(&self) -> &IsolationSummary {
        &self.summary
    }

    /// Puts back every thread, interrupt and workqueue mask changed, and
    /// returns the summary with `restored` set.
    pub fn restore(&mut self) -> IsolationSummary {
        if let (false, Some(record)) = (self.restored, &self.record) {
            self.restored = true;
            match super::record::restore(record, false, None) {
                Ok(Some(r)) => {
                    self.summary.restored = Some(r.undone);
                    self.summary.threads_widened = Some(r.widened);
                }
                // The guardian or `netfi restore` got there first (this
                // process was taken for dead, or the record was removed).
                Ok(None) => self.summary.restored = Some(0),
                Err(e) => self.summary.warnings.push(format!("restoring from {} failed: {e}; run `netfi restore`", record.display())),
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

/// The environment variable through which `netfi run` names itself to the
/// processes it starts, so that an emulator's record counts the runner
/// among its owners.
pub const RUNNER_PID_ENV: &str = "NETFI_RUNNER_PID";

/// Clears `core` of everything that may run elsewhere, except the threads
/// of the calling process (it places its own). Every change is put on the
/// host-wide record ([`super::record`]) *before* it is made (and the record
/// narrowed to what was made afterwards), and a guardian is started, so the
/// changes are undone should the caller (and the runner that started it,
/// named by [`RUNNER_PID_ENV`]) die at any point without restoring.
/// `_state_file` is no longer used (the record is host-wide), and kept for
/// callers of the earlier interface.
pub fn isolate(core: usize) -> std::io::Result<Isolation> {
    let online = online_cpus();
    if !online.contains(&core) {
        return Err(std::io::Error::new(std::io::ErrorKind::InvalidInput, format!("core {core} is not online (online: {})", format_list(&online))));
    }
    if online.len() < 2 {
        return Err(std::io::Error::new(std::io::ErrorKind::InvalidInput, "only one core is online: nowhere to move anything to"));
    }
    let own = std::process::id() as i32;
    let mut summary = IsolationSummary { core, cleared: true, ..Default::default() };
    let dir = super::record::state_dir()?;
    let me = super::record::Owner::of(own).ok_or_else(|| std::io::Error::other("cannot read this process's start time"))?;
    let mut owners = vec![me];
    // SAFETY: getppid has no preconditions.
    let parent = unsafe { libc::getppid() };
    if std::env::var(RUNNER_PID_ENV).ok().and_then(|v| v.parse::<i32>().ok()) == Some(parent) {
        owners.extend(super::record::Owner::of(parent));
    }
    let record_path = dir.join(format!("isolation-{own}-{}.json", me.start_ticks));
    let started_ticks = super::record::now_ticks();

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
    // value again). The guardian watches the record from now on.
    let online_list: Vec<usize> = online.iter().copied().collect();
    let save = |state: &IsolationState| -> std::io::Result<()> {
        let record = super::record::Record { owners: owners.clone(), started_ticks, online: online_list.clone(), state: state.clone() };
        super::record::write(&record_path, &record)
    };
    save(&plan)?;
    summary.record = Some(record_path.clone());
    match super::record::spawn_guardian(&record_path) {
        Ok(pid) => summary.guardian_pid = Some(pid),
        Err(e) => summary.warnings.push(format!(
            "no guardian ({e}): if this process and its runner are both killed, the core stays cleared until `netfi restore`"
        )),
    }

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
    Ok(Isolation { summary, record: Some(record_path), restored: false })
}

/// Why a process cannot have a core of its own here: it may run on fewer
/// than two of the online CPUs (it inherited a narrow mask: started under
/// `taskset`, or by a process that was). `None` when it can.
pub fn pin_problem() -> Option<String> {
    let online = online_cpus();
    let allowed = get_affinity(0).unwrap_or_default();
    (online.len() >= 2 && allowed.len() < 2).then(|| {
        format!(
            "the emulator is not pinned and its core not cleared: this process may run on CPU {} only of {} online (it inherited a narrow CPU mask: started under `taskset`, or left narrowed by a killed run — see `netfi restore`); the emulator's release lateness will suffer; start it with the full mask or pass a core it may use",
            format_list(&allowed),
            format_list(&online)
        )
    })
}

pub(crate) fn restore_state(state: &IsolationState) -> usize {
    let mut undone = 0;
    for (tid, before, after) in &state.threads {
        // Only where the mask is still ours: a later change by someone else stands.
        let now = get_affinity(*tid);
        let ours: BTreeSet<usize> = after.iter().copied().collect();
        if now.as_ref() == Some(&ours) && set_affinity(*tid, &before.iter().copied().collect()).is_ok() {
            undone += 1;
        }
    }
    // Interrupts and the workqueues likewise: put back only while they
    // still have the narrowed value this clearing wrote (a change not yet
    // made, or made since by someone else, stands). Two runs clearing
    // cores at once thus never restore each other's narrowed values.
    let online = online_cpus();
    let narrowed = |before: Option<BTreeSet<usize>>| -> Option<BTreeSet<usize>> {
        Some(before?.into_iter().filter(|&c| c != state.core && online.contains(&c)).collect())
    };
    for (irq, before) in &state.irqs {
        let now = std::fs::read_to_string(irq_list_path(*irq)).ok().and_then(|t| parse_list(t.trim()));
        if now.is_some() && now == narrowed(parse_list(before)) && std::fs::write(irq_list_path(*irq), before).is_ok() {
            undone += 1;
        }
    }
    if let Some(before) = &state.workqueue {
        let now = std::fs::read_to_string(WORKQUEUE_MASK).ok().and_then(|t| parse_mask(t.trim()));
        // Narrowed as `isolate` did: the core taken out, nothing else.
        let ours = parse_mask(before).map(|m| m.into_iter().filter(|&c| c != state.core).collect::<BTreeSet<usize>>());
        if now.is_some() && now == ours && std::fs::write(WORKQUEUE_MASK, before).is_ok() {
            undone += 1;
        }
    }
    undone
}

fn irq_list_path(irq: u32) -> PathBuf {
    PathBuf::from(format!("/proc/irq/{irq}/smp_affinity_list"))
}

pub(crate) fn numeric_entries(dir: &Path) -> Vec<u64> {
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

/// The CPUs online (`/sys/devices/system/cpu/online`), whatever this
/// process's own mask.
pub fn online_cpus() -> BTreeSet<usize> {
    std::fs::read_to_string("/sys/devices/system/cpu/online")
        .ok()
        .and_then(|t| parse_list(t.trim()))
        .unwrap_or_else(|| core_affinity::get_core_ids().unwrap_or_default().iter().map(|c| c.id).collect())
}

/// The CPUs thread `tid` (0: the caller) may run on.
pub fn get_affinity(tid: i32) -> Option<BTreeSet<usize>> {
    // SAFETY: a zeroed cpu_set_t is a valid empty set, filled by the kernel.
    let mut set: libc::cpu_set_t = unsafe { std::mem::zeroed() };
    // SAFETY: `set` is valid for writes of its size.
    if unsafe { libc::sched_getaffinity(tid, std::mem::size_of::<libc::cpu_set_t>(), &mut set) } != 0 {
        return None;
    }
    // SAFETY: CPU_ISSET reads the set only, for indices within its size.
    Some((0..libc::CPU_SETSIZE as usize).filter(|&c| unsafe { libc::CPU_ISSET(c, &set) }).collect())
}

pub(crate) fn set_affinity(tid: i32, cpus: &BTreeSet<usize>) -> std::io::Result<()> {
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
        let mut iso = isolate(core).expect("isolate");
        let record = iso.summary().record.clone().expect("a record");
        let moved = get_affinity(pid).unwrap();
        assert!(!moved.contains(&core), "child still allowed on core {core}: {moved:?}");
        assert_eq!(moved.len(), all.len() - 1);
        assert!(iso.summary().threads_moved >= 1);
        assert!(record.exists());
        let s = iso.restore();
        assert!(s.restored.unwrap() >= 1);
        assert_eq!(get_affinity(pid).unwrap(), all);
        assert!(!record.exists(), "record left after restoring");
        // Restoring from the record, as the guardian or `netfi restore` do.
        let iso2 = isolate(core).expect("isolate");
        let record = iso2.summary().record.clone().unwrap();
        assert!(!get_affinity(pid).unwrap().contains(&core));
        std::mem::forget(iso2);
        // Its owner (this process) lives: not an orphan.
        assert_eq!(super::super::record::restore(&record, true, None).unwrap(), None);
        let r = super::super::record::restore(&record, true, Some(std::process::id() as i32)).unwrap().unwrap();
        assert!(r.undone >= 1);
        assert_eq!(get_affinity(pid).unwrap(), all);
        assert!(!record.exists());
        drop(child);
    }
}
