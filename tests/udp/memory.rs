//! The emulator's memory stays flat however long the run: the trace and
//! the histograms go to disk as the run goes. Its resident set after 2N
//! frames exceeds that after N by no more than a bound derived from the
//! writer's buffers, far less than the ≈ 64 bytes per frame a trace kept
//! in memory would add.

use super::bridge::{itp, out_dir, send_paced, socket, u, Emulator};
use crate::common::machine;
use std::time::Duration;

/// VmRSS of `pid`, bytes.
fn rss_bytes(pid: u32) -> u64 {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap();
    let kb: u64 = status.lines().find_map(|l| l.strip_prefix("VmRSS:")).and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok()).unwrap();
    kb * 1024
}

#[test]
fn the_emulators_memory_does_not_grow_with_the_frames() {
    let _guard = machine::alone();
    let out = out_dir("memory");
    // A robot that reads nothing: the kernel drops what its buffer cannot hold.
    let (console, robot) = (socket(), socket());
    let emu = Emulator::bridge(&out, "Normal", "1", &console.local_addr().to_string(), &format!("udp://{}", robot.local_addr()), &[]);
    let n: u32 = 100_000;
    let frame = |i: u32| itp(i).to_vec();
    // A warm-up that fills the writer's 1 MiB buffer and the allocator's
    // pools, then N frames, then N more.
    send_paced(&console, emu.ingress(), (0..20_000).map(frame), 50);
    std::thread::sleep(Duration::from_millis(1500));
    let rss0 = rss_bytes(emu.pid());
    send_paced(&console, emu.ingress(), (20_000..20_000 + n).map(frame), 50);
    std::thread::sleep(Duration::from_millis(1500));
    let rss1 = rss_bytes(emu.pid());
    send_paced(&console, emu.ingress(), (20_000 + n..20_000 + 2 * n).map(frame), 50);
    std::thread::sleep(Duration::from_millis(1500));
    let rss2 = rss_bytes(emu.pid());
    let (e, udp) = emu.stop();
    let entered = u(&e["frames"]["entered"]);
    // The robot's socket is not read: what the kernel drops there does not
    // matter; the frames must have entered the emulator.
    assert!(entered as f64 >= 0.9 * f64::from(20_000 + 2 * n), "{udp}");
    // Bound: what may still grow after the warm-up is the rows of frames
    // in flight (none pending long with Normal) and allocator slack; 2 MiB.
    // A trace kept in memory would add N × 64 B = 6.4 MB per step.
    let bound = 2u64 << 20;
    eprintln!("emulator VmRSS: {rss0} B after the warm-up, {rss1} B after N = {n} frames, {rss2} B after 2N ({entered} entered)");
    assert!(rss2.saturating_sub(rss1) < bound, "grew {} B from N to 2N frames", rss2 - rss1);
    assert!(rss1.saturating_sub(rss0) < bound, "grew {} B over the first N frames", rss1 - rss0);
    let trace = std::fs::read_to_string(out.join("trace_emulator.csv")).unwrap();
    assert_eq!(trace.lines().count() as u64, entered + 1, "one row per frame, on disk");
}
