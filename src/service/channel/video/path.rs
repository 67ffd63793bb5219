//! The video channel: the robot's camera → emulator → console, over
//! iceoryx2 (`netfi/<run>/video` → `netfi/<run>/video_out`), shaped by
//! `--video-scenario` (default `Normal`).
//!
//! **No copy on the way in.** The emulator keeps the sample it took off
//! `video` borrowed in a slot while the link holds the frame (the link
//! queues only the slot's number), and copies the frame's bytes once, into
//! a sample loaned on `video_out`, when it is released: one copy of each
//! delivered byte, none of a dropped one. The link's queue holds one frame
//! fewer than the channel lets the emulator borrow
//! ([`VIDEO_HELD_FRAMES`]), so a slot is always free for the next frame;
//! a frame beyond that is the drop `queue_full`. The link stages (`rate`,
//! `trace`) see each frame's own size; a frame larger than the run's
//! maximum (`--video-max-bytes`) is the drop `too_large`, and every drop is
//! counted as damaged (a loss stage took some of its packets) or lost
//! whole ([`crate::video`]).

use crate::injector::{DropCause, Invalid};
use crate::service::emulator::path::{Channel, Ending, Path, Reverse, Take, GRACE_NS};
use crate::service::channel::declare::ChannelOpen;
use crate::service::emulator::opening::{Opening, PathPlan};
use crate::service::link::{Arrival, Carried};
use crate::service::schema::Account;
use serde::{Deserialize, Serialize};
use crate::transport::ipc::video::{VideoPublisher, VideoSample, VideoSubscriber, VIDEO, VIDEO_HELD_FRAMES, VIDEO_OUT};
use super::VideoArgs;
use crate::transport::{IpcNode, PortError};
use crate::video::{drop_kind, DropKind};

/// What the video channel adds to its path's report: `entered = delivered
/// + dropped + held_at_end`, and every drop is damaged or lost.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct VideoExtra {
    pub max_bytes: usize,
    /// Frames the camera said it sent (from its end marker).
    pub sent_by_camera: Option<u64>,
    /// Dropped frames of several packets taken by a loss stage.
    pub dropped_damaged: u64,
    /// Dropped frames lost whole.
    pub dropped_lost: u64,
    pub bytes_entered: u64,
    pub bytes_delivered: u64,
}

/// What the emulator's video link holds: the slot of the borrowed sample,
/// and what the link and the release need of it.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct VideoItem {
    pub slot: u32,
    pub len: u32,
    pub ingress_index: u64,
    pub ingress_ns: u64,
}

impl Carried for VideoItem {
    #[inline]
    fn ingress_ns(&self) -> u64 {
        self.ingress_ns
    }
}

/// The video direction's ports and the samples it holds borrowed.
pub struct VideoPorts {
    source: VideoSubscriber,
    sink: VideoPublisher,
    slots: Vec<Option<VideoSample>>,
    free: Vec<u32>,
    max_bytes: usize,
    damaged: u64,
    lost: u64,
    bytes_entered: u64,
    bytes_delivered: u64,
    unsubscribed: u64,
}

impl Channel for VideoPorts {
    type Item = VideoItem;
    type Extra = VideoExtra;
    const NAME: &'static str = super::NAME;
    const TRACE_FILE: &'static str = "trace_video.csv";
    const ENDING: Ending = Ending::AfterForward { grace_ns: GRACE_NS };

    #[inline]
    fn take(&mut self, next_ingress_index: u64, clock: &mut impl FnMut() -> u64) -> Take<VideoItem> {
        let s = match self.source.try_recv() {
            Ok(Some(s)) => s,
            Ok(None) => return Take::Nothing,
            Err(e) => return Take::Failed(PortError { port: "video".into(), message: e.to_string() }),
        };
        let h = *s.header();
        if h.is_end() {
            return Take::End(h.frame_index);
        }
        let t = clock();
        let len = s.bytes().len();
        self.bytes_entered += len as u64;
        let arrival = Arrival { sequence: None, console_index: h.frame_index, send_ns: h.send_ns };
        if len > self.max_bytes || len != h.len as usize {
            self.lost += 1;
            return Take::Reject(t, if len > self.max_bytes { Invalid::TooLarge } else { Invalid::WrongSize }, arrival);
        }
        // A slot is always free: the link holds one frame fewer than there are slots.
        let slot = self.free.pop().expect("a free slot");
        self.slots[slot as usize] = Some(s);
        Take::Item(VideoItem { slot, len: len as u32, ingress_index: next_ingress_index, ingress_ns: t }, Some(len as u64), arrival)
    }

    #[inline]
    fn dropped(&mut self, item: &VideoItem, cause: DropCause) {
        self.slots[item.slot as usize] = None;
        self.free.push(item.slot);
        match drop_kind(u64::from(item.len), cause.reason(), crate::model::backlog::DEFAULT_MTU_BYTES) {
            DropKind::Damaged => self.damaged += 1,
            DropKind::Lost => self.lost += 1,
        }
    }

    /// Copies the frame once into a sample of `video_out`, stamped with its
    /// ingress and release times, and returns the borrowed one.
    #[inline]
    fn release(&mut self, item: &VideoItem, scheduled_ns: u64, stamp: impl FnOnce() -> u64) -> Result<u64, (u64, PortError)> {
        let sample = self.slots[item.slot as usize].take().expect("a held frame keeps its sample");
        self.free.push(item.slot);
        let mut h = *sample.header();
        h.ingress_index = item.ingress_index;
        h.ingress_ns = item.ingress_ns;
        h.release_sched_ns = scheduled_ns;
        let mut release_ns = 0;
        let sent = self.sink.send_copy(&h, sample.bytes(), |h| {
            release_ns = stamp();
            h.release_ns = release_ns;
        });
        drop(sample);
        self.bytes_delivered += u64::from(item.len);
        match sent {
            Ok(n) => {
                self.unsubscribed += u64::from(n == 0);
                Ok(release_ns)
            }
            Err(e) => Err((crate::clock::now_ns(), PortError { port: "video_out".into(), message: e.to_string() })),
        }
    }

    fn send_end(&mut self, released: u64) {
        let _ = self.sink.send_end(released);
    }

    fn senders(&mut self) -> Option<usize> {
        Some(self.source.peers_connected())
    }

    fn unsubscribed(&self) -> u64 {
        self.unsubscribed
    }

    fn finish(&mut self, account: &Account, sent: Option<u64>) -> (VideoExtra, bool) {
        // What the link still holds goes back to the camera's channel.
        self.slots.iter_mut().for_each(|s| drop(s.take()));
        let extra = VideoExtra {
            max_bytes: self.max_bytes,
            sent_by_camera: sent,
            dropped_damaged: self.damaged,
            dropped_lost: self.lost,
            bytes_entered: self.bytes_entered,
            bytes_delivered: self.bytes_delivered,
        };
        (extra, self.damaged + self.lost == account.dropped_total())
    }
}

/// Why the video path's ports could not be opened.
#[derive(Debug, thiserror::Error)]
#[error("opening the {direction} video port")]
pub struct VideoPortError {
    /// `robot → emulator` or `emulator → console`.
    pub direction: &'static str,
    #[source]
    pub cause: crate::transport::ipc::video::VideoOpenError,
}

/// The video path of a lane with iceoryx2 on both sides, as `plan`
/// settled it.
pub fn open(v: &VideoArgs, plan: &PathPlan, o: &Opening) -> Result<Box<dyn Reverse>, ChannelOpen<VideoPortError>> {
    let node = o.sessions.iceoryx2.as_ref().expect("the video path is asked for with iceoryx2 on both sides");
    Ok(Box::new(path(v, node, plan, o.out_dir)?))
}

/// The video path of `v` on `node`, as `plan` settled it (its queue holds
/// one frame fewer than the emulator may borrow), its trace in `out_dir`.
pub fn path(v: &VideoArgs, node: &IpcNode, plan: &PathPlan, out_dir: &std::path::Path) -> Result<Path<VideoPorts>, ChannelOpen<VideoPortError>> {
    let mut plan = plan.clone();
    plan.queue_capacity = VIDEO_HELD_FRAMES - 1;
    let port = |direction| move |cause| ChannelOpen::Own(VideoPortError { direction, cause });
    let source = node.video_subscriber(VIDEO).map_err(port("robot → emulator"))?;
    let sink = node.video_publisher(VIDEO_OUT, v.video_max_bytes).map_err(port("emulator → console"))?;
    let chan = VideoPorts {
        source,
        sink,
        slots: (0..VIDEO_HELD_FRAMES).map(|_| None).collect(),
        free: (0..VIDEO_HELD_FRAMES as u32).rev().collect(),
        max_bytes: v.video_max_bytes,
        damaged: 0,
        lost: 0,
        bytes_entered: 0,
        bytes_delivered: 0,
        unsubscribed: 0,
    };
    // An hour at 60 Hz sizes the trace.
    Ok(plan.open(chan, 3600 * 60, out_dir)?)
}
