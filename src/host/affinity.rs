//! CPU sets and thread affinity: the primitives every placement is made of.
//! A leaf: it knows nothing of netfi, only the kernel's interfaces
//! (`sched_{get,set}affinity`, `/sys/devices/system/cpu/online`) and the
//! kernel's two ways of writing a CPU set (a list `0-3,8`, a hexadecimal
//! mask `ff,00000003`).

use std::collections::BTreeSet;

/// The CPUs online (`/sys/devices/system/cpu/online`), whatever this
/// process's own mask.
pub fn online_cpus() -> BTreeSet<usize> {
    std::fs::read_to_string("/sys/devices/system/cpu/online")
        .ok()
        .and_then(|t| parse_list(t.trim()))
        .unwrap_or_else(|| core_affinity::get_core_ids().unwrap_or_default().iter().map(|c| c.id).collect())
}

/// The CPUs thread `tid` (0: the calling thread) may run on.
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

/// Lets thread `tid` (0: the calling thread) run on `cpus` only.
pub fn set_affinity(tid: i32, cpus: &BTreeSet<usize>) -> std::io::Result<()> {
    let set = cpu_set(cpus);
    // SAFETY: `set` is a valid cpu_set_t of the size passed.
    if unsafe { libc::sched_setaffinity(tid, std::mem::size_of::<libc::cpu_set_t>(), &set) } == 0 {
        Ok(())
    } else {
        Err(std::io::Error::last_os_error())
    }
}

/// `cpus` as the kernel's `cpu_set_t` (CPUs past its size left out).
fn cpu_set(cpus: &BTreeSet<usize>) -> libc::cpu_set_t {
    // SAFETY: a zeroed cpu_set_t is a valid empty set.
    let mut set: libc::cpu_set_t = unsafe { std::mem::zeroed() };
    for &c in cpus.iter().filter(|&&c| c < libc::CPU_SETSIZE as usize) {
        // SAFETY: CPU_SET writes within the set's size (checked above).
        unsafe { libc::CPU_SET(c, &mut set) };
    }
    set
}

/// Pins the calling thread to `core`.
pub fn pin_current(core: usize) -> std::io::Result<()> {
    set_affinity(0, &BTreeSet::from([core]))
}

/// The cores this process may run on (its CPU mask), in order.
pub fn allowed_cores() -> Vec<usize> {
    core_affinity::get_core_ids().unwrap_or_default().iter().map(|c| c.id).collect()
}

/// The set of this machine's cores without `core`, for keeping threads off
/// a busy-polling loop's core; `None` where no other core exists.
pub fn cores_except(core: usize) -> Option<libc::cpu_set_t> {
    let others: BTreeSet<usize> = core_affinity::get_core_ids().unwrap_or_default().iter().map(|c| c.id).filter(|&c| c != core).collect();
    (!others.is_empty()).then(|| cpu_set(&others))
}

/// Lets the calling thread run on every core of this machine but `core`.
/// `Ok(false)` where no other core exists (nothing changed).
pub fn keep_current_off(core: usize) -> std::io::Result<bool> {
    let Some(set) = cores_except(core) else { return Ok(false) };
    // SAFETY: `set` is a valid cpu_set_t; pid 0 is the calling thread.
    if unsafe { libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set) } == 0 {
        Ok(true)
    } else {
        Err(std::io::Error::last_os_error())
    }
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

/// The set of `cpus`, for tests.
#[cfg(test)]
pub(crate) fn set(cpus: &[usize]) -> BTreeSet<usize> {
    cpus.iter().copied().collect()
}

#[cfg(test)]
mod tests {
    use super::*;

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

    /// A thread kept off a core keeps every other CPU it had.
    #[test]
    fn a_thread_is_kept_off_one_core_only() {
        let mine = get_affinity(0).unwrap();
        if mine.len() < 2 {
            eprintln!("skipped: this process may use one CPU only");
            return;
        }
        let core = *mine.iter().next_back().unwrap();
        let t = std::thread::spawn(move || {
            // SAFETY: pthread_self has no preconditions.
            let me = unsafe { libc::pthread_self() };
            assert!(keep_thread_off_core(me, core));
            get_affinity(0).unwrap()
        });
        let now = t.join().unwrap();
        let want: BTreeSet<usize> = mine.iter().copied().filter(|&c| c != core).collect();
        assert_eq!(now, want);
    }
}
