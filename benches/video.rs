//! The emulator's cost per video frame against the frame's size: one frame
//! of 124 B, 1.5 kB, 64 kB and 1 MB taken off `video` (borrowed, not
//! copied), decided by the video link (scenario Normal), released (copied
//! once into a sample loaned on `video_out`) and sent — the emulator's two
//! polls of [`netfi::service::emulator::video::path`], timed by the thread's CPU
//! time. The camera's send and the console's receive are outside the
//! timing. From the medians: ns per frame at 124 B (the per-packet cost) and
//! ns per byte (the slope between 124 B and 1 MB: the copy).
//!
//! `cargo bench --bench video` (seconds); `-- --quick` takes fewer frames.

use netfi::sample::VideoHeader;
use netfi::service::emulator::video::path;
use netfi::service::video::VideoArgs;
use netfi::transport::{open_node, Channel, Role};

#[path = "common/cpu_time.rs"]
#[allow(dead_code)]
mod cpu_time;
use cpu_time::thread_cpu_ns;

const SIZES: [usize; 4] = [124, 1500, 64 * 1024, 1 << 20];

fn main() {
    if std::env::args().any(|a| a == "--list") {
        println!("video: benchmark");
        return;
    }
    let quick = std::env::args().any(|a| a == "--quick");
    let run = format!("vbench{}", std::process::id());
    let node = open_node(&run, Role::Tool).expect("a node");
    let dir = std::env::temp_dir().join(format!("netfi-bench-video-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("a directory");
    let args = VideoArgs { video_mbps: Some(1.0), ..VideoArgs::default() };
    let mut emulator = path(&args, &node, 1, &dir).expect("the video path").expect("video on");
    let mut camera = node.video_publisher(Channel::Video, args.video_max_bytes).expect("the camera's port");
    let mut console = node.video_subscriber(Channel::VideoOut).expect("the console's port");
    println!("{:>10}  {:>12}  {:>12}  {:>9}", "payload", "median ns", "p90 ns", "frames");
    let mut medians = Vec::new();
    for size in SIZES {
        let frames = match (quick, size) {
            (true, s) if s >= 1 << 20 => 50,
            (true, _) => 500,
            (false, s) if s >= 1 << 20 => 500,
            (false, _) => 5000,
        };
        let mut ns = Vec::with_capacity(frames);
        for i in 0..frames + frames / 10 {
            let h = VideoHeader { frame_index: i as u64, len: size as u32, ..VideoHeader::default() };
            camera.send_fill(&h, size, |k| k as u8, |h| h.send_ns = netfi::clock::now_ns()).expect("sent");
            let t0 = thread_cpu_ns();
            emulator.poll(); // receive, decide, queue
            emulator.poll(); // release: copy, send
            let t1 = thread_cpu_ns();
            while console.try_recv().expect("received").is_some() {}
            // The first tenth warms the pools (a larger frame grows them once).
            if i >= frames / 10 {
                ns.push(t1 - t0);
            }
        }
        ns.sort_unstable();
        let (median, p90) = (ns[ns.len() / 2], ns[ns.len() * 9 / 10]);
        println!("{size:>10}  {median:>12}  {p90:>12}  {frames:>9}");
        medians.push(median as f64);
    }
    let per_byte = (medians[3] - medians[0]) / ((SIZES[3] - SIZES[0]) as f64);
    println!("per frame (124 B): {:.0} ns; per byte (124 B → 1 MB): {per_byte:.3} ns ({:.1} GB/s)", medians[0], 1.0 / per_byte);
    let report = emulator.finish(1).expect("the report");
    assert!(report.balanced, "{report:?}");
    std::fs::remove_dir_all(&dir).ok();
}
