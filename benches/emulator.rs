//! The emulator's own cost a frame, in one process, timed by the thread's
//! CPU time (`common/cpu_time.rs`: it stands still while the thread waits
//! for a core):
//!
//! - **forward**: one frame through the emulator's forward loop over
//!   in-memory ports (take, classify, decide, trace, histograms, queue,
//!   release; no transport). `batch 1` puts one frame at the ingress a
//!   turn (a slow stream), `batch 64` puts 64 (a fast one). Normal releases
//!   each frame the turn after it came; PLM-2 + DLM-2 holds them for
//!   210 ms and more, so the queue runs deep.
//! - **video**: one video frame of 124 B, 1.5 kB, 64 kB and 1 MB taken off
//!   `video` (borrowed), decided (Normal), copied once into a sample loaned
//!   on `video_out` and sent: the video path's two polls; the camera's send
//!   and the console's receive are outside the timing. From the medians:
//!   ns a frame at 124 B and ns a byte (the slope to 1 MB, the copy); the
//!   curve in `cost.csv` (axis `payload`).
//!
//! ```sh
//! cargo bench --bench emulator
//! cargo bench --bench emulator -- --parts video --frames 20000
//! ```
//!
//! This is the one benchmark that drives the emulator's internals rather
//! than its processes.

#[path = "common/mod.rs"]
mod common;
#[path = "common/cpu_time.rs"]
#[allow(dead_code)]
mod cpu_time;

use anyhow::{anyhow, ensure, Context, Result};
use common::args::Common;
use common::out::{CostRow, Out};
use cpu_time::thread_cpu_ns;
use netfi::sample::FrameSample;
use netfi::transport::ipc::video::VideoHeader;
use netfi::scenario::{self, Scenario};
use netfi::service::channel::video::path::path;
use netfi::service::emulator::opening::PathPlan;
use netfi::service::emulator::{lane::Lane, path::Path, Forward};
use netfi::service::link::Link;
use netfi::service::channel::video::VideoArgs;
use netfi::transport::ipc::video::{VIDEO, VIDEO_OUT};
use netfi::transport::{open_node, MemoryPort, Role};
use serde::Serialize;
use serde_json::json;
use std::fmt::Write as _;

/// Payload sizes of the video case.
const SIZES: [usize; 4] = [124, 1500, 64 * 1024, 1 << 20];

/// `cargo bench --bench emulator -- [FLAGS]`.
#[derive(Debug, clap::Parser, Serialize)]
#[command(name = "emulator", bin_name = "cargo bench --bench emulator --", about = "The emulator's own CPU time a frame, in one process: the forward loop and the video path")]
struct Args {
    #[command(flatten)]
    common: Common,
    #[arg(long, value_delimiter = ',', default_value = "forward,video", value_parser = ["forward", "video"])]
    parts: Vec<String>,
    /// Seconds of each forward case, after half a second of warm-up
    #[arg(long, default_value_t = 2.0)]
    seconds: f64,
    /// Video frames of each size up to 64 kB (a tenth as many of 1 MB)
    #[arg(long, default_value_t = 5000)]
    frames: usize,
}

/// The CPU time of one frame in a case: the median and the 90th
/// percentile over its samples.
#[derive(Debug, Serialize)]
struct Case {
    name: String,
    median_ns: f64,
    p90_ns: f64,
    samples: usize,
}

impl Case {
    fn of(name: String, mut ns: Vec<f64>) -> Case {
        ns.sort_by(f64::total_cmp);
        let at = |q: f64| ns.get(((ns.len() as f64 * q) as usize).min(ns.len().saturating_sub(1))).copied().unwrap_or(f64::NAN);
        Case { name, median_ns: at(0.5), p90_ns: at(0.9), samples: ns.len() }
    }
}

fn main() {
    common::args::main("emulator", "the emulator's own CPU time a frame (seconds)", run);
}

fn run(a: Args) -> Result<()> {
    ensure!(a.seconds > 0.0 && a.frames >= 10, "--seconds must be positive, --frames at least 10");
    let out = Out::create(&a.common, "emulator")?;
    let mut md = String::from("CPU time of the benchmark thread a frame: median (90th percentile).\n\n| case | ns a frame |\n|---|---|\n");
    let mut cases = Vec::new();
    if a.parts.iter().any(|p| p == "forward") {
        cases.extend(forward(a.seconds)?);
    }
    let mut per_byte = None;
    if a.parts.iter().any(|p| p == "video") {
        let video = video(a.frames)?;
        per_byte = Some((video[3].median_ns - video[0].median_ns) / (SIZES[3] - SIZES[0]) as f64);
        let rows: Vec<CostRow> = SIZES.iter().zip(&video).map(|(s, c)| CostRow { axis: "payload", x: *s as f64, series: "video path per frame (emulator benchmark)".into(), ns: c.median_ns }).collect();
        out.write_cost(&rows)?;
        cases.extend(video);
    }
    for c in &cases {
        let _ = writeln!(md, "| {} | {:.0} ({:.0}) |", c.name, c.median_ns, c.p90_ns);
    }
    if let Some(b) = per_byte {
        let _ = writeln!(md, "\nThe video path: {b:.3} ns a byte from 124 B to 1 MB ({:.1} GB/s).", 1.0 / b);
    }
    out.finish(&a, json!({"cases": cases, "video_ns_per_byte": per_byte}), &md)
}

/// The forward cases: per scenario and batch, blocks of turns timed.
fn forward(seconds: f64) -> Result<Vec<Case>> {
    let mut template = FrameSample::ZERO;
    netfi::frame::ItpFrame::default().write_to_sample(&mut template);
    let plm2_dlm2 = scenario::parse_str("[[stage]]\npreset = \"PLM-2\"\n[[stage]]\npreset = \"DLM-2\"\n", "bench", "bench").map_err(|e| anyhow!("{e}"))?;
    let normal = netfi::load::resolve("Normal").map_err(|e| anyhow!("{e}"))?;
    let mut cases = Vec::new();
    for (name, spec) in [("Normal", &normal), ("PLM-2 + DLM-2", &plm2_dlm2)] {
        for batch in [1u64, 64] {
            let link = Link::new(Scenario::new(spec, 1).map_err(|e| anyhow!("{e}"))?, 1 << 21, 1 << 22).map_err(|e| anyhow!("{e}"))?;
            let chan = Forward::new(MemoryPort::with_capacity(64), MemoryPort::with_capacity(1 << 16), false, true);
            let mut lane = Lane::new(Path::of(link, chan, 1, std::env::temp_dir().join("netfi-bench-unused.csv"), false), Vec::new());
            let mut i = 0u64;
            let mut turn = || {
                for _ in 0..batch {
                    let mut s = template;
                    s.console_index = i;
                    s.send_ns = netfi::clock::now_ns();
                    lane.forward.chan.source.queue.push_back(s);
                    i += 1;
                }
                lane.turn();
                lane.forward.chan.sink.queue.clear();
            };
            // A block of turns a sample: the clock read's own cost spread
            // over many frames.
            const TURNS: u64 = 256;
            let (mut ns, t_end) = (Vec::new(), netfi::clock::now_ns() + ((seconds + 0.5) * 1e9) as u64);
            let t_warm = netfi::clock::now_ns() + 500_000_000;
            while netfi::clock::now_ns() < t_end {
                let t0 = thread_cpu_ns();
                (0..TURNS).for_each(|_| turn());
                if netfi::clock::now_ns() > t_warm {
                    ns.push((thread_cpu_ns() - t0) as f64 / (TURNS * batch) as f64);
                }
            }
            cases.push(Case::of(format!("forward, {name}, batch {batch}"), ns));
        }
    }
    Ok(cases)
}

/// The video cases: each frame's two polls timed.
fn video(frames: usize) -> Result<Vec<Case>> {
    let run = format!("vbench{}", std::process::id());
    let node = open_node(&run, Role::Tool).map_err(|e| anyhow!("an iceoryx2 node: {e}"))?;
    common::args::keep_signals();
    let dir = std::env::temp_dir().join(format!("netfi-bench-video-{}", std::process::id()));
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let args = VideoArgs { video_mbps: Some(1.0), ..VideoArgs::default() };
    let plan = PathPlan::resolve("--video-scenario", None, None, 1, netfi::service::seeds::VIDEO_TAG, 1).map_err(|e| anyhow!("the video path: {e}"))?;
    let mut emulator = path(&args, &node, &plan, &dir).map_err(|e| anyhow!("the video path: {e}"))?;
    let mut camera = node.video_publisher(VIDEO, args.video_max_bytes).map_err(|e| anyhow!("the camera's port: {e}"))?;
    let mut console = node.video_subscriber(VIDEO_OUT).map_err(|e| anyhow!("the console's port: {e}"))?;
    let mut cases = Vec::new();
    for size in SIZES {
        let n = if size >= 1 << 20 { frames / 10 } else { frames };
        let mut ns = Vec::with_capacity(n);
        for i in 0..n + n / 10 {
            let h = VideoHeader { frame_index: i as u64, len: size as u32, ..VideoHeader::default() };
            camera.send_fill(&h, size, |k| k as u8, |h| h.send_ns = netfi::clock::now_ns()).map_err(|e| anyhow!("the camera's send: {e}"))?;
            let t0 = thread_cpu_ns();
            emulator.poll(); // receive, decide, queue
            emulator.poll(); // release: copy, send
            let t1 = thread_cpu_ns();
            while console.try_recv().map_err(|e| anyhow!("the console's receive: {e}"))?.is_some() {}
            // The first tenth warms the pools (a larger frame grows them once).
            if i >= n / 10 {
                ns.push((t1 - t0) as f64);
            }
        }
        cases.push(Case::of(format!("video, {size} B"), ns));
    }
    let report = emulator.finish(1).map_err(|e| anyhow!("the video path's report: {e}"))?;
    let _ = std::fs::remove_dir_all(&dir);
    ensure!(report.balanced, "the video path's account does not balance: {report:?}");
    Ok(cases)
}
