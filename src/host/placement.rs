//! Where a service, or the emulator's loop, runs: everything that decides
//! it, in one place.
//!
//! - A service ([`place`]) is pinned to a core, or kept off one (the
//!   emulator's busy core), or left to the scheduler.
//! - The emulator's loop ([`place_loop`]) is pinned to its core; the loop's
//!   own other threads (trace writers, the control thread: anything that
//!   is [`KeepOff`]) are moved off that core, and with `keep_process_off`
//!   every other thread of the process too (a DDS library's own threads),
//!   each listed where it may run ([`ThreadPlace`]) and put back after; with `isolate`, everything
//!   else that may run elsewhere is moved off it for the run
//!   ([`super::isolate`]), loudly when it cannot be; with a real-time
//!   priority the loop runs at SCHED_FIFO, with a warning when the
//!   kernel's real-time throttling will stop it for part of every period.
//!   What was done comes back as a [`Placement`], whose isolation is put
//!   back by [`Placement::restore`] (or on drop).
//!
//! What cannot be honoured is said on stderr, prefixed with the role, and
//! kept in [`Placement::warnings`].

use super::affinity::{format_list, get_affinity, keep_current_off, pin_current, set_affinity};
use super::isolate::{isolate, pin_problem, Isolation, IsolationSummary};
use super::process::{comm, numeric_entries};
use serde::{Deserialize, Serialize};
use std::collections::BTreeSet;

/// One of a loop's own threads that can be moved off the loop's core.
pub trait KeepOff {
    /// Moves the thread off `core`; `false` where it may use no other core.
    fn keep_off_core(&self, core: usize) -> bool;
    /// What the thread is, for the warning: `the trace writer`.
    fn what(&self) -> &str;
}

/// A [`KeepOff`] made of a name and a function: `KeepOffFn("the trace
/// writer", |core| link.keep_trace_off_core(core))`.
pub struct KeepOffFn<'a, F: Fn(usize) -> bool>(pub &'a str, pub F);

impl<F: Fn(usize) -> bool> KeepOff for KeepOffFn<'_, F> {
    fn keep_off_core(&self, core: usize) -> bool {
        (self.1)(core)
    }

    fn what(&self) -> &str {
        self.0
    }
}

/// Why a process could not be placed as asked.
#[derive(Debug, thiserror::Error)]
pub enum PlaceError {
    /// The kernel refused the pin (the core is offline, or outside the CPUs
    /// this process may use).
    #[error("could not pin the {role} to core {core}: {source}")]
    Pin {
        role: String,
        core: usize,
        #[source]
        source: std::io::Error,
    },
    #[error("could not keep the {role} off core {core}: {source}")]
    KeepOff {
        role: String,
        core: usize,
        #[source]
        source: std::io::Error,
    },
}

/// Places the calling thread of a service: pinned to `core`, or anywhere
/// but `avoid` (the emulator's busy core; nothing is done where no other
/// core exists), or wherever the scheduler likes.
pub fn place(role: &str, core: Option<usize>, avoid: Option<usize>) -> Result<(), PlaceError> {
    if let Some(core) = core {
        pin_current(core).map_err(|source| PlaceError::Pin { role: role.to_string(), core, source })?;
    } else if let Some(core) = avoid {
        keep_current_off(core).map_err(|source| PlaceError::KeepOff { role: role.to_string(), core, source })?;
    }
    Ok(())
}

/// Where the emulator's loop should run.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LoopPlacement {
    /// The core to pin the loop to (`None`: not pinned).
    pub core: Option<usize>,
    /// Clear the core of everything else for the run (`--isolate`).
    pub isolate: bool,
    /// SCHED_FIFO priority (1–99) for the loop (`--rt-priority`).
    pub rt_priority: Option<i32>,
    /// Move every other thread of the process off the loop's core, not only
    /// those it names (a library's threads: RustDDS's receive, discovery
    /// and send threads), and list where each may run.
    pub keep_process_off: bool,
}

/// Threads of the loop's process of one name, and where they may run once
/// the loop was placed.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ThreadPlace {
    /// Their name (the kernel's `comm`: at most 15 bytes).
    pub name: String,
    /// How many of that name.
    pub threads: usize,
    /// The CPUs they may use, as a list (`0,2-3`).
    pub cpus: String,
    /// Whether they were moved off the loop's core for the run.
    pub moved_off_loop_core: bool,
}

/// How the loop was placed.
#[derive(Debug, Default)]
pub struct Placement {
    /// What was moved off the loop's core (`--isolate`), or why nothing
    /// was; put back by [`restore`](Self::restore) or on drop.
    pub isolation: Option<Isolation>,
    /// The SCHED_FIFO priority the loop got, if any.
    pub realtime_priority: Option<i32>,
    /// What could not be honoured, as said on stderr.
    pub warnings: Vec<String>,
    /// The process's other threads and where they may run, with
    /// `keep_process_off` (else empty).
    pub threads: Vec<ThreadPlace>,
    /// The threads moved off the loop's core, with the CPUs each had.
    moved: Vec<(i32, BTreeSet<usize>)>,
}

impl Placement {
    /// Puts back what the isolation moved, and the process's threads moved
    /// off the loop's core; the isolation's summary for the report.
    pub fn restore(&mut self) -> Option<IsolationSummary> {
        self.put_threads_back();
        self.isolation.as_mut().map(Isolation::restore)
    }

    /// Gives each thread moved off the loop's core its CPUs back, once.
    fn put_threads_back(&mut self) {
        for (tid, cpus) in self.moved.drain(..) {
            // A thread gone since is nothing to put back.
            let _ = set_affinity(tid, &cpus);
        }
    }
}

impl Drop for Placement {
    fn drop(&mut self) {
        self.put_threads_back();
    }
}

/// Places the calling thread as `role`'s busy loop: pins it to
/// `want.core`, keeps each of `keep_off` off that core, clears the core
/// when `want.isolate`, and raises the thread to `want.rt_priority`. Only a
/// pin the kernel refuses is an error; everything else that cannot be done
/// is a warning.
pub fn place_loop(role: &str, want: &LoopPlacement, keep_off: &[&dyn KeepOff]) -> Result<Placement, PlaceError> {
    let mut placement = Placement::default();
    if let Some(core) = want.core {
        pin_current(core).map_err(|source| PlaceError::Pin { role: role.to_string(), core, source })?;
        for k in keep_off {
            if !k.keep_off_core(core) {
                warn(
                    &mut placement,
                    role,
                    format!("{} could not be kept off core {core} (it may use no other): the loop loses its core whenever that thread runs", k.what()),
                );
            }
        }
        if want.keep_process_off {
            keep_process_off(role, core, &mut placement);
        }
    }
    // After pinning: the loop's own threads are placed; everything else that
    // may run elsewhere leaves the core until the run ends.
    placement.isolation = match (want.isolate, want.core) {
        (true, Some(core)) => Some(clear(role, core)),
        (true, None) => {
            let why = pin_problem().unwrap_or_else(|| "--isolate needs a pinned core; nothing cleared".into());
            warn(&mut placement, role, why.clone());
            Some(Isolation::not_cleared(0, why))
        }
        (false, _) => None,
    };
    if let Some(p) = want.rt_priority {
        placement.realtime_priority = realtime(role, p, &mut placement.warnings);
    }
    Ok(placement)
}

/// Moves every other thread of this process that may run on `core` and
/// elsewhere off `core` (each keeps the rest of its own set), remembering
/// its set to put back; a thread that may run on `core` alone is a warning.
/// Lists every other thread, by name, where it may run now.
fn keep_process_off(role: &str, core: usize, placement: &mut Placement) {
    // SAFETY: gettid has no preconditions.
    let me = unsafe { libc::gettid() };
    let mut by: std::collections::BTreeMap<(String, String, bool), usize> = Default::default();
    for tid in numeric_entries(std::path::Path::new("/proc/self/task")) {
        let tid = tid as i32;
        let Some(cpus) = get_affinity(tid).filter(|_| tid != me) else { continue };
        let name = comm(tid);
        let mut now = cpus.clone();
        let mut moved = false;
        if cpus.contains(&core) {
            now.remove(&core);
            if now.is_empty() {
                warn(placement, role, format!("its thread {name} may run on core {core} only: the loop loses its core whenever that thread runs"));
                now = cpus.clone();
            } else if let Err(e) = set_affinity(tid, &now) {
                warn(placement, role, format!("could not move its thread {name} off core {core} ({e}): the loop loses its core whenever that thread runs"));
                now = cpus.clone();
            } else {
                placement.moved.push((tid, cpus));
                moved = true;
            }
        }
        *by.entry((name, format_list(&now), moved)).or_default() += 1;
    }
    placement.threads = by.into_iter().map(|((name, cpus, moved_off_loop_core), threads)| ThreadPlace { name, threads, cpus, moved_off_loop_core }).collect();
}

fn warn(placement: &mut Placement, role: &str, warning: String) {
    eprintln!("{role}: WARNING: {warning}");
    placement.warnings.push(warning);
}

/// Clears `core` for the run, saying what was done, or loudly why not.
fn clear(role: &str, core: usize) -> Isolation {
    match isolate(core) {
        Ok(iso) => {
            eprintln!("{role}: {}", iso.summary());
            iso
        }
        Err(e) => {
            eprintln!("{role}: WARNING: could not clear core {core}: {e}");
            Isolation::not_cleared(core, format!("could not clear core {core}: {e}"))
        }
    }
}

/// Moves the calling thread to SCHED_FIFO at `priority` (1–99), so ordinary
/// processes on its core cannot preempt it. Needs root or CAP_SYS_NICE.
/// Under the kernel's real-time throttling ([`rt_throttling`]) a thread
/// that never sleeps is stopped for the rest of each period once it has
/// used its share: 50 ms of every second by default.
pub fn set_realtime(priority: i32) -> std::io::Result<()> {
    let param = libc::sched_param { sched_priority: priority };
    // SAFETY: `param` is a valid sched_param; pid 0 is the calling thread.
    if unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &param) } == 0 {
        Ok(())
    } else {
        Err(std::io::Error::last_os_error())
    }
}

/// The kernel's real-time throttling, `(runtime_us, period_us)`, when it is
/// on (`kernel.sched_rt_runtime_us` is not -1): a SCHED_FIFO busy loop is
/// then stopped for `period − runtime` of every period.
pub fn rt_throttling() -> Option<(i64, i64)> {
    let read = |name: &str| std::fs::read_to_string(format!("/proc/sys/kernel/{name}")).ok()?.trim().parse::<i64>().ok();
    let runtime = read("sched_rt_runtime_us")?;
    let period = read("sched_rt_period_us")?;
    (runtime >= 0 && runtime < period).then_some((runtime, period))
}

/// Moves the loop to SCHED_FIFO `p`, warning of real-time throttling; the
/// priority it got, if any.
fn realtime(role: &str, p: i32, warnings: &mut Vec<String>) -> Option<i32> {
    match set_realtime(p) {
        Ok(()) => {
            if let Some((runtime, period)) = rt_throttling() {
                let w = format!(
                    "real-time throttling is on (kernel.sched_rt_runtime_us = {runtime} of {period}): this busy loop at SCHED_FIFO will be stopped for {} ms of every {} ms; set it to -1, or use --isolate without --rt-priority",
                    (period - runtime) / 1000,
                    period / 1000
                );
                eprintln!("{role}: WARNING: {w}");
                warnings.push(w);
            }
            Some(p)
        }
        Err(e) => {
            eprintln!("{role}: staying at normal priority: SCHED_FIFO {p} refused ({e})");
            None
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::host::affinity::get_affinity;
    use std::cell::Cell;

    /// Each thread kept off is asked once, with the loop's core; one that
    /// cannot move is a warning naming it; nothing else is touched.
    #[test]
    fn the_loops_threads_are_kept_off_its_core_and_refusals_named() {
        let mine = get_affinity(0).unwrap();
        let core = *mine.iter().next().unwrap();
        // On a thread of its own: the pin would outlast the test.
        let (asked, placement) = std::thread::spawn(move || {
            let asked = Cell::new(None);
            let movable = KeepOffFn("the trace writer", |c| {
                asked.set(Some(c));
                true
            });
            let stuck = KeepOffFn("the control thread", |_| false);
            let p = place_loop("emulator", &LoopPlacement { core: Some(core), ..Default::default() }, &[&movable, &stuck]).unwrap();
            (asked.get(), p)
        })
        .join()
        .unwrap();
        assert_eq!(asked, Some(core));
        assert_eq!(placement.warnings.len(), 1, "{:?}", placement.warnings);
        assert!(placement.warnings[0].starts_with("the control thread could not be kept off core"), "{:?}", placement.warnings);
        assert!(placement.isolation.is_none() && placement.realtime_priority.is_none());
    }

    /// With `keep_process_off`, another thread of the process that could
    /// run on the loop's core cannot while the loop is placed, is listed
    /// by name, and may again once the placement is restored.
    #[test]
    fn the_processs_other_threads_leave_the_loops_core_and_come_back() {
        let mine = get_affinity(0).unwrap();
        if mine.len() < 2 {
            eprintln!("skipped: one CPU, no core to keep a thread off");
            return;
        }
        let core = *mine.iter().next_back().unwrap();
        let (tx, rx) = std::sync::mpsc::channel::<()>();
        let other = std::thread::Builder::new()
            .name("netfi-sleeper".into())
            .spawn(move || {
                // SAFETY: gettid has no preconditions.
                let tid = unsafe { libc::gettid() };
                let _ = rx.recv();
                tid
            })
            .unwrap();
        std::thread::sleep(std::time::Duration::from_millis(20));
        let (during, after, threads) = std::thread::spawn(move || {
            let want = LoopPlacement { core: Some(core), keep_process_off: true, ..Default::default() };
            let mut p = place_loop("emulator", &want, &[]).unwrap();
            let sleeper: Vec<i32> = numeric_entries(std::path::Path::new("/proc/self/task")).into_iter().map(|t| t as i32).filter(|&t| comm(t) == "netfi-sleeper").collect();
            let during = get_affinity(sleeper[0]).unwrap();
            p.restore();
            (during, get_affinity(sleeper[0]).unwrap(), p.threads.clone())
        })
        .join()
        .unwrap();
        tx.send(()).unwrap();
        other.join().unwrap();
        assert!(!during.contains(&core) && !during.is_empty(), "{during:?}");
        assert_eq!(after, mine, "put back");
        let t = threads.iter().find(|t| t.name == "netfi-sleeper").expect("listed");
        assert!(t.moved_off_loop_core && t.cpus == format_list(&during), "{t:?}");
    }

    /// `--isolate` without a core to clear is said, and reported as not
    /// cleared.
    #[test]
    fn isolating_without_a_pin_is_a_warning_not_a_clearing() {
        let mut p = place_loop("emulator", &LoopPlacement { isolate: true, ..Default::default() }, &[]).unwrap();
        assert_eq!(p.warnings.len(), 1);
        let s = p.restore().unwrap();
        assert!(!s.cleared);
        assert_eq!(s.warnings, p.warnings);
    }

    #[test]
    fn a_pin_outside_this_machine_is_an_error() {
        let e = std::thread::spawn(|| place("console", Some(libc::CPU_SETSIZE as usize + 1), None)).join().unwrap().unwrap_err();
        assert!(e.to_string().starts_with("could not pin the console to core"), "{e}");
    }
}
