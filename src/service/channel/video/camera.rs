//! The synthetic camera: a thread of the simulator publishing one frame of
//! the group's size every period.

use super::{spawn, VideoArgs, VideoError, Worker};
use crate::clock::now_ns;
use crate::transport::ipc::video::VideoHeader;
use crate::transport::ipc::video::VIDEO;
use crate::transport::Role;
use serde::{Deserialize, Serialize};
use std::sync::atomic::{AtomicBool, Ordering};

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


/// Starts the camera (in the simulator): a thread of its own, on its own
/// node, publishing on `video` once the emulator subscribes, until stopped.
pub fn camera(run_id: &str, args: &VideoArgs) -> Result<Option<Worker<CameraReport>>, VideoError> {
    if !args.on() {
        return Ok(None);
    }
    args.validate()?;
    let (run_id, args) = (run_id.to_string(), args.clone());
    spawn("netfi-camera", move |stop| run_camera(&run_id, &args, &stop)).map(Some)
}

fn run_camera(run_id: &str, args: &VideoArgs, stop: &AtomicBool) -> Result<CameraReport, VideoError> {
    let gop = args.gop()?;
    let node = crate::transport::open_node(run_id, Role::Simulator)?;
    // The camera writes what its sizes say; the run's maximum is the emulator's check.
    let max = args.video_max_bytes.max(gop.key_bytes as usize);
    let mut port = node.video_publisher(VIDEO, max).map_err(|source| VideoError::Port { direction: "robot → emulator", source })?;
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
pub(super) fn pattern(i: u64, k: usize) -> u8 {
    (i as u8).wrapping_add(k as u8)
}

