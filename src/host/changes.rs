//! What clearing a core changed on the host, and putting it back: the part
//! of a clearing that outlives the process that made it (the record holds
//! an [`IsolationState`]; any process may [`undo`] it).

use super::affinity::{get_affinity, online_cpus, parse_list, parse_mask, set_affinity};
use super::process::{numeric_entries, start_ticks};
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The unbound workqueues' CPU mask.
pub(crate) const WORKQUEUE_MASK: &str = "/sys/devices/virtual/workqueue/cpumask";

/// Where interrupt `irq`'s CPU list is read and written.
pub(crate) fn irq_list_path(irq: u32) -> PathBuf {
    PathBuf::from(format!("/proc/irq/{irq}/smp_affinity_list"))
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

/// Puts back each change of `state` that still holds what the clearing
/// wrote; returns how many were put back.
pub fn undo(state: &IsolationState) -> usize {
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
        // Narrowed as the clearing did: the core taken out, nothing else.
        let ours = parse_mask(before).map(|m| m.into_iter().filter(|&c| c != state.core).collect::<BTreeSet<usize>>());
        if now.is_some() && now == ours && std::fs::write(WORKQUEUE_MASK, before).is_ok() {
            undone += 1;
        }
    }
    undone
}

/// Threads started while the core was cleared inherited their parent's
/// narrowed mask and would keep it for good. Each thread started after
/// `started_ticks` whose mask is exactly one of the narrowed masks of
/// `state` gets the mask that one had before (within the CPUs online now).
/// A thread started during the run and deliberately kept to exactly such a
/// set is widened too: the record cannot tell it from an inherited mask.
/// `online_then`: the CPUs online when the clearing began.
pub fn widen_born_during(state: &IsolationState, started_ticks: u64, online_then: &[usize]) -> usize {
    let online = online_cpus();
    let map = narrowed_to_before(state, online_then);
    let recorded: BTreeSet<i32> = state.threads.iter().map(|t| t.0).collect();
    let own = std::process::id() as i32;
    let mut widened = 0;
    for pid in numeric_entries(Path::new("/proc")) {
        if pid as i32 == own {
            continue;
        }
        for tid in numeric_entries(&Path::new("/proc").join(pid.to_string()).join("task")) {
            let tid = tid as i32;
            if recorded.contains(&tid) {
                continue;
            }
            let Some(born) = start_ticks(&format!("/proc/{pid}/task/{tid}/stat")) else { continue };
            if born < started_ticks {
                continue;
            }
            let Some(mask) = get_affinity(tid) else { continue };
            let Some(Some(before)) = map.get(&mask) else { continue };
            let target: BTreeSet<usize> = before.intersection(&online).copied().collect();
            if !target.is_empty() && set_affinity(tid, &target).is_ok() {
                widened += 1;
            }
        }
    }
    widened
}

/// Each narrowed mask of `state` → the mask it came from; `None` where two
/// threads narrowed to the same mask came from different ones.
fn narrowed_to_before(state: &IsolationState, online_then: &[usize]) -> BTreeMap<BTreeSet<usize>, Option<BTreeSet<usize>>> {
    let mut map: BTreeMap<BTreeSet<usize>, Option<BTreeSet<usize>>> = BTreeMap::new();
    for (_, before, after) in &state.threads {
        let (b, a): (BTreeSet<usize>, BTreeSet<usize>) = (before.iter().copied().collect(), after.iter().copied().collect());
        map.entry(a).and_modify(|v| if v.as_ref() != Some(&b) { *v = None }).or_insert(Some(b));
    }
    // Threads of processes that had nothing to move (already off the
    // core) but narrowed by inheritance from the runner's placement are
    // covered by the common case: all online CPUs but the core.
    let all: BTreeSet<usize> = online_then.iter().copied().collect();
    let narrowed_all: BTreeSet<usize> = all.iter().copied().filter(|&c| c != state.core).collect();
    map.entry(narrowed_all).or_insert(Some(all));
    map
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::host::affinity::set;

    #[test]
    fn a_narrowed_mask_maps_back_only_when_unambiguous() {
        let state = IsolationState {
            core: 3,
            threads: vec![(10, vec![0, 1, 3], vec![0, 1]), (11, vec![1, 2, 3], vec![1, 2]), (12, vec![1, 2, 3, 4], vec![1, 2])],
            ..Default::default()
        };
        let map = narrowed_to_before(&state, &[0, 1, 2, 3]);
        assert_eq!(map[&set(&[0, 1])], Some(set(&[0, 1, 3])));
        assert_eq!(map[&set(&[1, 2])], None, "two origins: ambiguous");
        assert_eq!(map[&set(&[0, 1, 2])], Some(set(&[0, 1, 2, 3])));
    }
}
