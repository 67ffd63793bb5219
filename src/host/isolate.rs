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
//! mask; restoring widens them again (see [`super::changes`]). This is what
//! `tuna --isolate` or a `cpuset` partition does, for one run, without a
//! reboot (`isolcpus=` and `nohz_full=` do it for good, and better).
//!
//! Nothing of it outlives the run, whatever is killed: every change is in a
//! host-wide record before it is made, a guardian process restores when
//! the record's owners all die, and `netfi restore` (run first by every
//! `netfi run`) restores any record whose owners and guardian were all
//! killed ([`super::record`], [`super::guardian`]).
//!
//! Moving other users' threads and interrupts needs root or CAP_SYS_NICE;
//! without it only the caller's own processes move, and the summary says
//! what stayed and why.

use super::affinity::{format_mask, parse_mask, set_affinity};
use super::changes::{irq_list_path, WORKQUEUE_MASK};
use super::guardian;
use super::private_dir::PrivateDirError;
use super::process::{comm, is_kernel_thread, now_ticks, numeric_entries, Owner};
use super::record::{self, Record, WriteError};
use serde::{Deserialize, Serialize};
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

pub use super::affinity::{format_list, get_affinity, online_cpus, parse_list};
pub use super::changes::IsolationState;
pub use super::process::RUNNER_PID_ENV;

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


/// A cleared core; restores on drop.
#[derive(Debug)]
pub struct Isolation {
    summary: IsolationSummary,
    /// The host-wide record of what was changed (removed after restoring).
    record: Option<PathBuf>,
    /// The guardian watching the record, reaped once the record is gone.
    guardian: Option<std::process::Child>,
    restored: bool,
}

impl Isolation {
    /// A core that was not cleared, for the report: `warning` says why.
    pub fn not_cleared(core: usize, warning: String) -> Isolation {
        Isolation { summary: IsolationSummary::not_cleared(core, warning), record: None, guardian: None, restored: true }
    }

    pub fn summary(&self) -> &IsolationSummary {
        &self.summary
    }

    /// Puts back every thread, interrupt and workqueue mask changed, and
    /// returns the summary with `restored` set.
    pub fn restore(&mut self) -> IsolationSummary {
        if let (false, Some(path)) = (self.restored, &self.record) {
            self.restored = true;
            match record::restore(path, false, None) {
                Ok(Some(r)) => {
                    self.summary.restored = Some(r.undone);
                    self.summary.threads_widened = Some(r.widened);
                }
                // The guardian or `netfi restore` got there first (this
                // process was taken for dead, or the record was removed).
                Ok(None) => self.summary.restored = Some(0),
                Err(e) => self.summary.warnings.push(format!("restoring from {} failed: {e}; run `netfi restore`", path.display())),
            }
            if let Some(g) = self.guardian.as_mut() {
                guardian::reap(g, 4 * guardian::GUARD_POLL);
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

/// Why a core could not be cleared.
#[derive(Debug, thiserror::Error)]
pub enum IsolateError {
    #[error("core {core} is not online (online: {online})")]
    NotOnline { core: usize, online: String },
    #[error("only one core is online: nowhere to move anything to")]
    OneCore,
    #[error("the directory of records: {0}")]
    StateDir(#[from] PrivateDirError),
    #[error("cannot read this process's start time")]
    StartTime,
    /// The record could not be written: nothing was changed.
    #[error(transparent)]
    Record(#[from] WriteError),
}

/// Clears `core` of everything that may run elsewhere, except the threads
/// of the calling process (it places its own). Every change is put on the
/// host-wide record ([`super::record`]) *before* it is made (and the record
/// narrowed to what was made afterwards), and a guardian is started, so the
/// changes are undone should the caller (and the runner that started it,
/// named by [`RUNNER_PID_ENV`]) die at any point without restoring.
pub fn isolate(core: usize) -> Result<Isolation, IsolateError> {
    let online = online_cpus();
    if !online.contains(&core) {
        return Err(IsolateError::NotOnline { core, online: format_list(&online) });
    }
    if online.len() < 2 {
        return Err(IsolateError::OneCore);
    }
    let dir = record::state_dir_resolved()?;
    let (me, owners) = owners()?;
    let record_path = dir.path.join(format!("isolation-{}-{}.json", me.pid, me.start_ticks));
    let started_ticks = now_ticks();
    let mut summary = IsolationSummary { core, cleared: true, ..Default::default() };
    summary.warnings.extend(dir.warning());

    let plan = Plan::gather(core, &online, me.pid);
    summary.threads_bound_to_core = plan.threads_bound_to_core;
    // On record before anything moves: restoring a change that was never
    // made is harmless (a thread is put back only while its mask is still
    // the planned one; an interrupt or the workqueues get their own value
    // again). The guardian watches the record from now on.
    let online_list: Vec<usize> = online.iter().copied().collect();
    let save = |state: &IsolationState| {
        let r = Record { owners: owners.clone(), started_ticks, online: online_list.clone(), state: state.clone() };
        record::write(&record_path, &r)
    };
    save(&plan.state)?;
    summary.record = Some(record_path.clone());
    let guardian = match guardian::spawn(&record_path) {
        Ok(child) => {
            summary.guardian_pid = Some(child.id());
            Some(child)
        }
        Err(e) => {
            summary.warnings.push(format!(
                "no guardian ({e}): if this process and its runner are both killed, the core stays cleared until `netfi restore`"
            ));
            None
        }
    };
    let state = plan.apply(&mut summary);
    // The planned record, a superset, stays if this fails.
    let _ = save(&state);
    Ok(Isolation { summary, record: Some(record_path), guardian, restored: false })
}

/// This process, and the owners of what it clears: itself, and the runner
/// that started it when there is one ([`RUNNER_PID_ENV`] names the parent).
fn owners() -> Result<(Owner, Vec<Owner>), IsolateError> {
    let me = Owner::of(std::process::id() as i32).ok_or(IsolateError::StartTime)?;
    let mut owners = vec![me];
    // SAFETY: getppid has no preconditions.
    let parent = unsafe { libc::getppid() };
    if std::env::var(RUNNER_PID_ENV).ok().and_then(|v| v.parse::<i32>().ok()) == Some(parent) {
        owners.extend(Owner::of(parent));
    }
    Ok((me, owners))
}

/// What a clearing will change: every thread, the workqueue mask and every
/// interrupt that may run on the core and elsewhere.
struct Plan {
    /// Each change with its value before (the record).
    state: IsolationState,
    threads_bound_to_core: usize,
    kernel_tids: BTreeSet<i32>,
    /// The narrowed workqueue mask to write, when narrowed.
    workqueue_narrowed: Option<String>,
    /// The narrowed CPU list of each interrupt of `state.irqs`, in order.
    irq_narrowed: Vec<String>,
}

impl Plan {
    fn gather(core: usize, online: &BTreeSet<usize>, own: i32) -> Plan {
        let mut plan = Plan {
            state: IsolationState { core, ..Default::default() },
            threads_bound_to_core: 0,
            kernel_tids: BTreeSet::new(),
            workqueue_narrowed: None,
            irq_narrowed: Vec::new(),
        };
        plan.gather_threads(own);
        if let Ok(text) = std::fs::read_to_string(WORKQUEUE_MASK) {
            if let Some(mask) = parse_mask(text.trim()) {
                let narrowed: BTreeSet<usize> = mask.iter().copied().filter(|&c| c != core).collect();
                if mask.contains(&core) && !narrowed.is_empty() {
                    plan.state.workqueue = Some(text.trim().to_string());
                    plan.workqueue_narrowed = Some(format_mask(&narrowed));
                }
            }
        }
        for irq in numeric_entries(Path::new("/proc/irq")) {
            let Ok(text) = std::fs::read_to_string(irq_list_path(irq as u32)) else { continue };
            let Some(cpus) = parse_list(text.trim()) else { continue };
            let narrowed: BTreeSet<usize> = cpus.iter().copied().filter(|&c| c != core && online.contains(&c)).collect();
            if cpus.contains(&core) && !narrowed.is_empty() {
                plan.state.irqs.push((irq as u32, text.trim().to_string()));
                plan.irq_narrowed.push(format_list(&narrowed));
            }
        }
        plan
    }

    /// Every thread of other processes allowed on the core and elsewhere.
    fn gather_threads(&mut self, own: i32) {
        let core = self.state.core;
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
                    self.threads_bound_to_core += 1;
                    continue;
                }
                if kernel {
                    self.kernel_tids.insert(tid);
                }
                self.state.threads.push((tid, before.into_iter().collect(), after.into_iter().collect()));
            }
        }
    }

    /// Makes the changes, counting them in `summary`; returns what was
    /// changed.
    fn apply(self, summary: &mut IsolationSummary) -> IsolationState {
        let core = self.state.core;
        let mut state = IsolationState { core, ..Default::default() };
        let mut kernel_names = BTreeSet::new();
        let mut refused_names = BTreeSet::new();
        for (tid, before, after) in self.state.threads {
            match set_affinity(tid, &after.iter().copied().collect()) {
                Ok(()) => {
                    summary.threads_moved += 1;
                    if self.kernel_tids.contains(&tid) {
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
        if let (Some(before), Some(narrowed)) = (self.state.workqueue, self.workqueue_narrowed) {
            if std::fs::write(WORKQUEUE_MASK, narrowed).is_ok() {
                state.workqueue = Some(before);
                summary.workqueues_moved = true;
            }
        }
        for ((irq, before), narrowed) in self.state.irqs.into_iter().zip(self.irq_narrowed) {
            if std::fs::write(irq_list_path(irq), narrowed).is_ok() {
                summary.irqs_moved += 1;
                state.irqs.push((irq, before));
            } else {
                summary.irqs_refused += 1;
            }
        }
        summary.kernel_threads_moved = kernel_names.into_iter().collect();
        summary.refused_examples = refused_names.into_iter().collect();
        state
    }
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
        let path = iso.summary().record.clone().expect("a record");
        let moved = get_affinity(pid).unwrap();
        assert!(!moved.contains(&core), "child still allowed on core {core}: {moved:?}");
        assert_eq!(moved.len(), all.len() - 1);
        assert!(iso.summary().threads_moved >= 1);
        assert!(path.exists());
        let s = iso.restore();
        assert!(s.restored.unwrap() >= 1);
        assert_eq!(get_affinity(pid).unwrap(), all);
        assert!(!path.exists(), "record left after restoring");
        // Restoring from the record, as the guardian or `netfi restore` do.
        let iso2 = isolate(core).expect("isolate");
        let path = iso2.summary().record.clone().unwrap();
        assert!(!get_affinity(pid).unwrap().contains(&core));
        std::mem::forget(iso2);
        // Its owner (this process) lives: not an orphan.
        assert_eq!(record::restore(&path, true, None).unwrap(), None);
        let r = record::restore(&path, true, Some(std::process::id() as i32)).unwrap().unwrap();
        assert!(r.undone >= 1);
        assert_eq!(get_affinity(pid).unwrap(), all);
        assert!(!path.exists());
        drop(child);
    }
}
