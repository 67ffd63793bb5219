//! The video stream of a run (`netfi run --video-mbps R`): a synthetic
//! camera on the robot side (a thread of the simulator) publishes one
//! variable-size frame every period on `netfi/<run>/video`; the emulator
//! passes each through a path of its own ([`super::emulator::video`]),
//! shaped by `--video-scenario` (default `Normal`), and releases survivors
//! on `netfi/<run>/video_out`, where the console (a thread of its own)
//! measures each frame's delay, whether it arrived whole, and the freezes
//! ([`crate::video`]). Here: the flags, the camera, the receiver, and the
//! run report's section.

use crate::clock::now_ns;
use crate::metrics::{LatencyHistogram, Summary};
use crate::sample::VideoHeader;
use crate::service::schema::VideoExtra;
use crate::service::schema::PathReport;
use crate::transport::ipc::video::{VideoSubscriber, DEFAULT_VIDEO_MAX_BYTES};
use crate::transport::{Channel, Role};
use crate::video::{Freezes, Gop};
use anyhow::Context;
use clap::Args;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// The largest `--video-max-bytes`: the link stages' largest payload, 64 MiB.
pub const MAX_VIDEO_MAX_BYTES: usize = crate::model::backlog::MAX_PAYLOAD_BYTES as usize;

/// The video stream's flags, the same for `netfi run` and each service.
#[derive(Debug, Clone, Args)]
pub struct VideoArgs {
    /// Add a synthetic camera on the robot side streaming video back to the
    /// console at this mean bit rate, Mbit/s (default: no video).
    #[arg(long, value_name = "MBIT_S")]
    pub video_mbps: Option<f64>,
    /// The camera's frame rate, Hz.
    #[arg(long, default_value_t = 60.0)]
    pub video_hz: f64,
    /// Frames per group of pictures (one key frame, then delta frames).
    #[arg(long, default_value_t = 30)]
    pub video_gop: u32,
    /// A key frame's size over a delta frame's.
    #[arg(long, default_value_t = 8.0)]
    pub video_key_ratio: f64,
    /// The largest video payload of the run, bytes; a larger frame is the
    /// emulator's drop `too_large`.
    #[arg(long, default_value_t = DEFAULT_VIDEO_MAX_BYTES)]
    pub video_max_bytes: usize,
    /// The scenario (file or preset) the video goes through, robot →
    /// console (default Normal: nothing injected).
    #[arg(long, value_name = "SCENARIO")]
    pub video_scenario: Option<String>,
    /// Seed of the video scenario (default: derived from the run's seed).
    #[arg(long)]
    pub video_seed: Option<u64>,
}

impl Default for VideoArgs {
    /// No video.
    fn default() -> Self {
        VideoArgs {
            video_mbps: None,
            video_hz: 60.0,
            video_gop: 30,
            video_key_ratio: 8.0,
            video_max_bytes: DEFAULT_VIDEO_MAX_BYTES,
            video_scenario: None,
            video_seed: None,
        }
    }
}

impl VideoArgs {
    /// Whether the run has video.
    pub fn on(&self) -> bool {
        self.video_mbps.is_some()
    }

    /// The group of pictures asked for, checked.
    pub fn gop(&self) -> anyhow::Result<Gop> {
        let mbps = self.video_mbps.unwrap_or(1.0);
        Gop::new(mbps * 1e6, self.video_hz, self.video_gop, self.video_key_ratio).map_err(|e| anyhow::anyhow!("--video-*: {e}"))
    }

    /// Checks the flags: a bit rate, frame rate and group that make sense,
    /// a maximum payload in range, and no video options without video.
    pub fn validate(&self) -> anyhow::Result<()> {
        if !self.on() {
            anyhow::ensure!(
                self.video_scenario.is_none() && self.video_seed.is_none(),
                "--video-scenario and --video-seed need --video-mbps (the video stream is off)"
            );
            return Ok(());
        }
        self.gop()?;
        anyhow::ensure!(
            (1..=MAX_VIDEO_MAX_BYTES).contains(&self.video_max_bytes),
            "--video-max-bytes must be from 1 to {MAX_VIDEO_MAX_BYTES} bytes, got {}",
            self.video_max_bytes
        );
        Ok(())
    }

    /// The flags as an argv (nothing when off).
    pub fn argv(&self) -> Vec<String> {
        let Some(mbps) = self.video_mbps else { return Vec::new() };
        let mut a = vec![
            "--video-mbps".to_string(),
            mbps.to_string(),
            "--video-hz".into(),
            self.video_hz.to_string(),
            "--video-gop".into(),
            self.video_gop.to_string(),
            "--video-key-ratio".into(),
            self.video_key_ratio.to_string(),
            "--video-max-bytes".into(),
            self.video_max_bytes.to_string(),
        ];
        if let Some(s) = &self.video_scenario {
            a.extend(["--video-scenario".to_string(), s.clone()]);
        }
        if let Some(s) = self.video_seed {
            a.extend(["--video-seed".to_string(), s.to_string()]);
        }
        a
    }
}

/// What the camera did.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CameraReport {
    pub frame_hz: f64,
    pub gop_frames: u32,
    pub key_bytes: u64,
    pub delta_bytes: u64,
    /// The sizes' mean bit rate, bit/s.
    pub bit_rate_bit_s: f64,
    pub frames_sent: u64,
    pub bytes_sent: u64,
    /// Frames the channel refused (no emulator's queue room, a loan).
    pub send_errors: u64,
    /// Frames published while no emulator was subscribed.
    pub sent_unsubscribed: u64,
}

/// A thread that runs until told to stop, then hands back its report.
pub struct Worker<R> {
    stop: Arc<AtomicBool>,
    handle: std::thread::JoinHandle<anyhow::Result<R>>,
}

impl<R> Worker<R> {
    /// Tells the thread to stop and waits for its report.
    pub fn finish(self) -> anyhow::Result<R> {
        self.stop.store(true, Ordering::Relaxed);
        self.handle.join().map_err(|_| anyhow::anyhow!("the video thread panicked"))?
    }
}

fn spawn<R: Send + 'static>(name: &str, f: impl FnOnce(Arc<AtomicBool>) -> anyhow::Result<R> + Send + 'static) -> anyhow::Result<Worker<R>> {
    let stop = Arc::new(AtomicBool::new(false));
    let s = stop.clone();
    let handle = std::thread::Builder::new().name(name.into()).spawn(move || f(s)).context("starting the video thread")?;
    Ok(Worker { stop, handle })
}

/// Starts the camera (in the simulator): a thread of its own, on its own
/// node, publishing on `video` once the emulator subscribes, until stopped.
pub fn camera(run_id: &str, args: &VideoArgs) -> anyhow::Result<Option<Worker<CameraReport>>> {
    if !args.on() {
        return Ok(None);
    }
    args.validate()?;
    let (run_id, args) = (run_id.to_string(), args.clone());
    spawn("netfi-camera", move |stop| run_camera(&run_id, &args, &stop)).map(Some)
}

fn run_camera(run_id: &str, args: &VideoArgs, stop: &AtomicBool) -> anyhow::Result<CameraReport> {
    let gop = args.gop()?;
    let node = crate::transport::open_node(run_id, Role::Simulator)?;
    // The camera writes what its sizes say; the run's maximum is the emulator's check.
    let max = args.video_max_bytes.max(gop.key_bytes as usize);
    let mut port = node.video_publisher(Channel::Video, max).context("opening the robot → emulator video port")?;
    let mut r = CameraReport {
        frame_hz: args.video_hz,
        gop_frames: gop.frames,
        key_bytes: gop.key_bytes,
        delta_bytes: gop.delta_bytes,
        bit_rate_bit_s: gop.bit_rate(args.video_hz),
        frames_sent: 0,
        bytes_sent: 0,
        send_errors: 0,
        sent_unsubscribed: 0,
    };
    while port.peers_connected() == 0 && !stop.load(Ordering::Relaxed) {
        std::thread::sleep(std::time::Duration::from_millis(1));
    }
    let period_ns = 1e9 / args.video_hz;
    let t0 = now_ns();
    let mut i = 0u64;
    while !stop.load(Ordering::Relaxed) {
        let target = t0 + (i as f64 * period_ns) as u64;
        let now = now_ns();
        if now < target {
            std::thread::sleep(std::time::Duration::from_nanos((target - now).min(2_000_000)));
            continue;
        }
        let (len, key) = gop.size(i);
        let h = VideoHeader {
            frame_index: i,
            len: len as u32,
            flags: if key { VideoHeader::FLAG_KEY } else { 0 },
            gop_index: (i % u64::from(gop.frames)) as u32,
            ..VideoHeader::default()
        };
        match port.send_fill(&h, len as usize, |k| pattern(i, k), |h| h.send_ns = now_ns()) {
            Ok(0) => r.sent_unsubscribed += 1,
            Ok(_) => {}
            Err(_) => r.send_errors += 1,
        }
        r.frames_sent += 1;
        r.bytes_sent += len;
        i += 1;
    }
    let _ = port.send_end(r.frames_sent);
    Ok(r)
}

/// Byte `k` of frame `i`: what the console checks.
#[inline]
fn pattern(i: u64, k: usize) -> u8 {
    (i as u8).wrapping_add(k as u8)
}

/// What the console saw of the video.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ReceivedVideo {
    pub received: u64,
    /// Received with every byte as sent.
    pub whole: u64,
    /// Received with wrong bytes or length.
    pub damaged: u64,
    /// Whole frames older than one already displayed (not displayed).
    pub late: u64,
    pub bytes: u64,
    /// Camera send → console receive, of the whole frames.
    pub delay_ns: Summary,
    /// Gaps between displayed frames over two frame periods.
    pub freezes: u64,
    pub freeze_total_ms: f64,
    pub freeze_longest_ms: f64,
    pub freeze_threshold_ms: f64,
    /// Frames the emulator said it released (from its end marker).
    pub released_by_emulator: Option<u64>,
    /// `video_received.csv`: one row per frame received.
    #[serde(default)]
    pub received_csv: Option<PathBuf>,
}

/// The file name of the console's per-frame record of the video.
pub const RECEIVED_CSV: &str = "video_received.csv";

/// Starts the console's video receiver: a thread of its own, on its own
/// node, taking frames off `video_out` until stopped (then until the
/// emulator's end marker, at most `wait_s` more), each recorded as a row
/// of `out/video_received.csv` as it comes.
pub fn receiver(run_id: &str, args: &VideoArgs, out: &Path, wait_s: f64) -> anyhow::Result<Option<Worker<ReceivedVideo>>> {
    if !args.on() {
        return Ok(None);
    }
    args.validate()?;
    let (run_id, hz) = (run_id.to_string(), args.video_hz);
    let wait_ns = (wait_s * 1e9) as u64;
    // Created here, so that a file that cannot be is an error at once.
    let log = crate::trace::CsvLog::create(out.join(RECEIVED_CSV), crate::video::RECEIVED_CSV_HEADER)?;
    // Subscribed before the console streams, so no frame is released into nothing.
    let (ready_tx, ready_rx) = std::sync::mpsc::channel();
    let w = spawn("netfi-video-rx", move |stop| {
        let node = crate::transport::open_node(&run_id, Role::Console)?;
        let port = node.video_subscriber(Channel::VideoOut).context("opening the emulator → console video port")?;
        let _ = ready_tx.send(());
        run_receiver(port, Received::new(hz, log), wait_ns, &stop)
    })?;
    if ready_rx.recv().is_err() {
        return w.finish().map(|_| None);
    }
    Ok(Some(w))
}

/// Whether a received frame's bytes are the camera's: its `len` of them,
/// and every 509th byte (a prime stride, so that every position in the
/// pattern's 256-byte cycle is checked) as [`pattern`] gives it.
#[inline]
fn intact(frame_index: u64, len: u32, bytes: &[u8]) -> bool {
    bytes.len() == len as usize && bytes.iter().enumerate().step_by(509).all(|(k, &v)| v == pattern(frame_index, k))
}

/// The console's account of the video: counts, delays, freezes, and the
/// per-frame record.
struct Received {
    delay: LatencyHistogram,
    freezes: Freezes,
    log: crate::trace::CsvLog,
    received: u64,
    whole: u64,
    damaged: u64,
    late: u64,
    bytes: u64,
    shown: Option<u64>,
    released_by_emulator: Option<u64>,
}

impl Received {
    fn new(hz: f64, log: crate::trace::CsvLog) -> Received {
        Received {
            delay: LatencyHistogram::new(),
            freezes: Freezes::new(hz),
            log,
            received: 0,
            whole: 0,
            damaged: 0,
            late: 0,
            bytes: 0,
            shown: None,
            released_by_emulator: None,
        }
    }

    /// A frame (not the end marker) received at `t`: counted, measured and
    /// recorded.
    #[inline]
    fn frame(&mut self, h: &VideoHeader, b: &[u8], t: u64) {
        self.received += 1;
        self.bytes += b.len() as u64;
        let mut row = crate::video::ReceivedRow {
            frame_index: h.frame_index,
            gop_index: h.gop_index,
            key: h.flags & VideoHeader::FLAG_KEY != 0,
            len: h.len,
            bytes: b.len() as u64,
            send_ns: h.send_ns,
            ingress_index: h.ingress_index,
            ingress_ns: h.ingress_ns,
            release_sched_ns: h.release_sched_ns,
            release_ns: h.release_ns,
            recv_ns: t,
            whole: intact(h.frame_index, h.len, b),
            ..Default::default()
        };
        if !row.whole {
            self.damaged += 1;
        } else {
            self.whole += 1;
            self.delay.record(row.delay_ns());
            if self.shown.is_some_and(|i| h.frame_index <= i) {
                self.late += 1;
            } else {
                self.shown = Some(h.frame_index);
                row.displayed = true;
                row.gap_ns = self.freezes.displayed(t);
                row.freeze = row.gap_ns.is_some_and(|g| self.freezes.is_freeze(g));
            }
        }
        self.log.push(|w| row.write(w));
        self.log.tick(t);
    }

    fn report(self) -> anyhow::Result<ReceivedVideo> {
        let f = self.freezes;
        let received_csv = self.log.finish()?;
        Ok(ReceivedVideo {
            received: self.received,
            whole: self.whole,
            damaged: self.damaged,
            late: self.late,
            bytes: self.bytes,
            delay_ns: self.delay.summary(),
            freezes: f.count,
            freeze_total_ms: f.total_ns as f64 / 1e6,
            freeze_longest_ms: f.longest_ns as f64 / 1e6,
            freeze_threshold_ms: f.threshold_ns() as f64 / 1e6,
            released_by_emulator: self.released_by_emulator,
            received_csv: Some(received_csv),
        })
    }
}

fn run_receiver(mut port: VideoSubscriber, mut rx: Received, wait_ns: u64, stop: &AtomicBool) -> anyhow::Result<ReceivedVideo> {
    let mut deadline: Option<u64> = None;
    let mut idle = 0u32;
    loop {
        match port.try_recv() {
            Ok(Some(s)) => {
                let t = now_ns();
                let h = *s.header();
                if h.is_end() {
                    rx.released_by_emulator = Some(h.frame_index);
                    break;
                }
                rx.frame(&h, s.bytes(), t);
            }
            Ok(None) => {
                idle = idle.wrapping_add(1);
                if idle % 1024 == 0 {
                    rx.log.tick(now_ns());
                }
                if stop.load(Ordering::Relaxed) {
                    let now = now_ns();
                    let d = *deadline.get_or_insert(now + wait_ns);
                    if now > d || port.peers_connected() == 0 {
                        break;
                    }
                }
                std::thread::sleep(std::time::Duration::from_micros(50));
            }
            Err(_) => std::thread::sleep(std::time::Duration::from_millis(1)),
        }
    }
    rx.report()
}

/// The video stream of a run robot → emulator → console: what the camera
/// sent, what the video scenario did, and what the console saw.
///
/// `frames` counts the frames the emulator took in less those it released
/// while no console listened: whole (arrived with every byte), damaged
/// (part lost: dropped part-way by a loss stage, or arrived with wrong
/// bytes) and lost. `balanced`: the emulator's account holds and the
/// console received what the emulator released to it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct VideoSection {
    pub scenario: String,
    pub seed: u64,
    pub camera: Option<CameraReport>,
    pub frames: crate::video::FrameTally,
    pub dropped: BTreeMap<String, u64>,
    pub held_at_end: u64,
    /// Whole frames older than one already displayed.
    pub late: Option<u64>,
    /// Camera send → console receive of the whole frames.
    pub delay_ns: Option<Summary>,
    /// The delay the video scenario injected (a link stage's queueing and
    /// serialization included).
    pub injected_delay_ns: Summary,
    pub freezes: Option<u64>,
    pub freeze_total_ms: Option<f64>,
    pub freeze_longest_ms: Option<f64>,
    pub freeze_threshold_ms: Option<f64>,
    pub bytes_entered: u64,
    pub bytes_delivered: u64,
    /// The video scenario's stages (a link stage's utilisation, queue and delay).
    pub stages: serde_json::Value,
    pub balanced: bool,
}

impl VideoSection {
    /// Joins the emulator's video path, the console's receiver and the
    /// camera's report; `None` without video.
    pub fn join(e: Option<&PathReport<VideoExtra>>, c: Option<&ReceivedVideo>, camera: Option<&CameraReport>) -> Option<VideoSection> {
        let e = e?;
        let a = &e.account;
        let sent = a.entered.saturating_sub(e.delivered_unsubscribed);
        let (whole, damaged_rx) = c.map_or((0, 0), |c| (c.whole, c.damaged));
        let balanced = e.balanced && c.is_some_and(|c| c.received + e.delivered_unsubscribed == a.delivered);
        Some(VideoSection {
            scenario: e.scenario.clone(),
            seed: e.seed,
            camera: camera.cloned(),
            frames: crate::video::FrameTally::new(sent, whole, damaged_rx, e.extra.dropped_damaged),
            dropped: a.dropped.clone(),
            held_at_end: a.held_at_end,
            late: c.map(|c| c.late),
            delay_ns: c.map(|c| c.delay_ns).filter(|d| d.count > 0),
            injected_delay_ns: e.measures.injected_delay_ns,
            freezes: c.map(|c| c.freezes),
            freeze_total_ms: c.map(|c| c.freeze_total_ms),
            freeze_longest_ms: c.map(|c| c.freeze_longest_ms),
            freeze_threshold_ms: c.map(|c| c.freeze_threshold_ms),
            bytes_entered: e.extra.bytes_entered,
            bytes_delivered: e.extra.bytes_delivered,
            stages: serde_json::to_value(&e.measures.stages).unwrap_or_default(),
            balanced,
        })
    }

    /// The section as lines of the run's text report.
    pub fn to_text(&self) -> String {
        let dropped: Vec<String> = self.dropped.iter().map(|(k, v)| format!("{v} by {k}")).collect();
        let mut s = format!("video      scenario {} (seed {})", self.scenario, self.seed);
        if let Some(c) = &self.camera {
            s += &format!(
                ": camera {:.0} Hz, {:.2} Mbit/s, GOP {} (key {} B, delta {} B), {} frames sent",
                c.frame_hz,
                c.bit_rate_bit_s / 1e6,
                c.gop_frames,
                c.key_bytes,
                c.delta_bytes,
                c.frames_sent
            );
        }
        s += "\n";
        let f = &self.frames;
        s += &format!(
            "  frames     {} through the emulator: {} whole, {} damaged, {} lost; dropped {}; held at end {}; accounting {}\n",
            f.sent,
            f.whole,
            f.damaged,
            f.lost,
            if dropped.is_empty() { "none".into() } else { dropped.join(", ") },
            self.held_at_end,
            if self.balanced { "balanced" } else { "NOT balanced" }
        );
        s += &format!("  delay      {}\n", line_ms(self.delay_ns.as_ref()));
        if let (Some(n), Some(t), Some(l), Some(th)) = (self.freezes, self.freeze_total_ms, self.freeze_longest_ms, self.freeze_threshold_ms) {
            s += &format!("  freezes    {n} (gaps over {th:.1} ms): total {t:.1} ms, longest {l:.1} ms\n");
        }
        s
    }
}

fn line_ms(d: Option<&Summary>) -> String {
    match d {
        Some(d) => format!(
            "p50 {:.2} ms  p90 {:.2} ms  p99 {:.2} ms  max {:.2} ms  ({} whole frames)",
            d.p50 as f64 / 1e6,
            d.p90 as f64 / 1e6,
            d.p99 as f64 / 1e6,
            d.max as f64 / 1e6,
            d.count
        ),
        None => "-".into(),
    }
}
