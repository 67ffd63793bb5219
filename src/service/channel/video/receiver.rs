//! The console's video receiver: a thread taking frames off `video_out`,
//! each checked, measured and recorded as a row of `video_received.csv`.

use super::camera::pattern;
use super::{spawn, VideoArgs, VideoError, Worker};
use crate::clock::now_ns;
use crate::metrics::{LatencyHistogram, Summary};
use crate::transport::ipc::video::VideoHeader;
use crate::transport::ipc::video::VideoSubscriber;
use crate::transport::ipc::video::VIDEO_OUT;
use crate::transport::Role;
use crate::video::Freezes;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

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
pub fn receiver(run_id: &str, args: &VideoArgs, out: &Path, wait_s: f64) -> Result<Option<Worker<ReceivedVideo>>, VideoError> {
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
        let port = node.video_subscriber(VIDEO_OUT).map_err(|source| VideoError::Port { direction: "emulator → console", source })?;
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

    fn report(self) -> Result<ReceivedVideo, VideoError> {
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

fn run_receiver(mut port: VideoSubscriber, mut rx: Received, wait_ns: u64, stop: &AtomicBool) -> Result<ReceivedVideo, VideoError> {
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

