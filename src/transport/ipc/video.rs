//! The video channels: variable-size payloads, a `[u8]` slice of one video
//! frame with a [`VideoHeader`] beside it (docs/interface.md, "Video").
//!
//! | setting | `video` (robot → emulator) | `video_out` (emulator → console) |
//! |---|---|---|
//! | subscribers | 1 | [`MAX_SUBSCRIBERS_PER_CHANNEL`] |
//! | subscriber queue | [`VIDEO_BUFFER_FRAMES`] | [`VIDEO_BUFFER_FRAMES`] |
//! | borrowed samples per subscriber | [`VIDEO_HELD_FRAMES`] | 1 |
//!
//! The emulator keeps the samples it takes off `video` borrowed while its
//! link holds them (no copy on the way in), so the channel lets it borrow
//! [`VIDEO_HELD_FRAMES`]; each is copied once, into a sample loaned on
//! `video_out`, when it is released. A publisher's memory starts at
//! `initial_max_slice_len` bytes a sample (at most [`VIDEO_INITIAL_SLICE_BYTES`])
//! and grows by powers of two when a larger frame is loaned (a new
//! segment; rare: only the first frame of each larger size); the run's
//! maximum payload is checked by the ports themselves
//! ([`VideoSendError::TooLarge`]).

use iceoryx2::node::Node;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::port::update_connections::UpdateConnections as _;
use iceoryx2::port::{BackpressureAction, BackpressureInfo, SendError};
use iceoryx2::prelude::{AllocationStrategy, BackpressureStrategy, PortFactory as _, ServiceName};
use iceoryx2::sample::Sample;
use iceoryx2::service::port_factory::publish_subscribe::PortFactory;

use super::{FrameRecvError, Port, Role, FrameSendError, Ipc, IpcConfig, RunId, MAX_NODES_PER_CHANNEL, MAX_SUBSCRIBERS_PER_CHANNEL};
use iceoryx2::prelude::ZeroCopySend;

/// The user header of a video frame on the video channels (`video`,
/// `video_out`): the payload is the frame's bytes, a `[u8]` slice of `len`
/// bytes; this header travels beside it (docs/interface.md, "Video").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ZeroCopySend)]
#[type_name("netfi::VideoHeader.v1")]
#[repr(C)]
pub struct VideoHeader {
    /// Camera send time, stamped just before publishing.
    pub send_ns: u64,
    /// The camera's frame counter (0, 1, 2, …); in the end marker, the
    /// number of frames sent.
    pub frame_index: u64,
    /// Assigned by the emulator when the frame enters it (0, 1, 2, …).
    pub ingress_index: u64,
    /// Time the emulator took the frame off `video`.
    pub ingress_ns: u64,
    /// Scheduled release time (ingress + injected delay).
    pub release_sched_ns: u64,
    /// Actual release time, stamped just before publishing on `video_out`.
    pub release_ns: u64,
    /// Payload bytes (the slice's length).
    pub len: u32,
    /// [`VideoHeader::FLAG_END`], [`VideoHeader::FLAG_KEY`].
    pub flags: u32,
    /// The frame's place in its group of pictures (0: the key frame).
    pub gop_index: u32,
    /// Zero.
    pub _reserved: u32,
}

const _: () = assert!(core::mem::size_of::<VideoHeader>() == 64);
const _: () = assert!(core::mem::align_of::<VideoHeader>() == 8);

impl VideoHeader {
    /// The iceoryx2 type name of the header; must match between processes.
    pub const TYPE_NAME: &'static str = "netfi::VideoHeader.v1";
    /// The end of the video stream: not a frame, no payload.
    pub const FLAG_END: u32 = 1;
    /// A key frame (the first of its group of pictures).
    pub const FLAG_KEY: u32 = 2;

    /// An end marker after `sent` frames.
    pub fn end_marker(sent: u64) -> VideoHeader {
        VideoHeader { frame_index: sent, flags: VideoHeader::FLAG_END, ..VideoHeader::default() }
    }

    /// Whether this is the end marker.
    pub fn is_end(&self) -> bool {
        self.flags & VideoHeader::FLAG_END != 0
    }
}

/// Frames a video subscriber's queue holds (about 1 s at 60 Hz).
pub const VIDEO_BUFFER_FRAMES: usize = 64;
/// Frames the emulator may hold borrowed from `video` at once: the video
/// link's queue capacity (a frame beyond it is the drop `queue_full`).
pub const VIDEO_HELD_FRAMES: usize = 64;
/// The most bytes a sample is given at first (the memory grows for larger
/// frames).
pub const VIDEO_INITIAL_SLICE_BYTES: usize = 256 * 1024;
/// The default largest video payload of a run: 4 MiB.
pub const DEFAULT_VIDEO_MAX_BYTES: usize = 4 << 20;

type VideoService = PortFactory<Ipc, [u8], VideoHeader>;

/// Robot → emulator: video frames, `[u8]` with a [`VideoHeader`].
pub const VIDEO: Port = Port::new("video", Role::Simulator, Role::Emulator);
/// Emulator → console: the video frames that survived the video scenario.
pub const VIDEO_OUT: Port = Port::new("video_out", Role::Emulator, Role::Console);

fn open_video_service(node: &Node<Ipc>, config: &IpcConfig, channel: Port) -> Result<VideoService, VideoOpenError> {
    let name = ServiceName::new(&config.service_name(channel)).expect("a validated run id always forms a valid service name");
    // The emulator holds the frames it takes off `video` borrowed while
    // its link delays them.
    let (subscribers, borrowed) = if channel == VIDEO { (1, VIDEO_HELD_FRAMES) } else { (MAX_SUBSCRIBERS_PER_CHANNEL, 1) };
    node.service_builder(&name)
        .publish_subscribe::<[u8]>()
        .user_header::<VideoHeader>()
        .max_publishers(1)
        .max_subscribers(subscribers)
        .max_nodes(MAX_NODES_PER_CHANNEL)
        .subscriber_max_buffer_size(VIDEO_BUFFER_FRAMES)
        .subscriber_max_borrowed_samples(borrowed)
        .history_size(0)
        .enable_safe_overflow(false)
        .open_or_create()
        .map_err(|e| VideoOpenError { service: config.service_name(channel), what: e.to_string() })
}

/// Why a video port could not be opened.
#[derive(Debug, thiserror::Error)]
#[error("cannot open video service `{service}` (iceoryx2: {what}); every process of a run must speak netfi::VideoHeader.v1 over [u8]")]
pub struct VideoOpenError {
    /// The service name.
    pub service: String,
    /// The iceoryx2 failure.
    pub what: String,
}

/// Why a video frame was not sent.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum VideoSendError {
    /// The payload is larger than the run's maximum (the drop `too_large`).
    #[error("a video payload of {len} bytes is larger than the run's maximum of {max} bytes")]
    TooLarge {
        /// The payload's bytes.
        len: usize,
        /// The run's maximum.
        max: usize,
    },
    /// The channel refused it (loan, full queue, delivery).
    #[error(transparent)]
    Send(#[from] FrameSendError),
}

/// The publishing end of a video channel. Not `Send`.
pub struct VideoPublisher {
    port: Publisher<Ipc, [u8], VideoHeader>,
    service: VideoService,
    run: RunId,
    channel: Port,
    max_len: usize,
}

impl std::fmt::Debug for VideoPublisher {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("VideoPublisher").field("run", &self.run).field("channel", &self.channel).field("max_len", &self.max_len).finish()
    }
}

impl VideoPublisher {
    pub(super) fn open(node: &Node<Ipc>, config: &IpcConfig, channel: Port, max_len: usize) -> Result<Self, VideoOpenError> {
        let service = open_video_service(node, config, channel)?;
        let port = service
            .publisher_builder()
            .initial_max_slice_len(max_len.clamp(1, VIDEO_INITIAL_SLICE_BYTES))
            .allocation_strategy(AllocationStrategy::PowerOfTwo)
            .max_loaned_samples(1)
            .backpressure_strategy(BackpressureStrategy::DiscardData)
            .set_backpressure_handler(|_: &BackpressureInfo| BackpressureAction::DiscardDataAndFail)
            .create()
            .map_err(|e| VideoOpenError { service: config.service_name(channel), what: e.to_string() })?;
        Ok(Self { port, service, run: config.run_id().clone(), channel, max_len })
    }

    /// The largest payload this publisher sends.
    pub fn max_len(&self) -> usize {
        self.max_len
    }

    /// Sends a frame of `len` bytes that `fill` writes (every byte), with
    /// `header`; `stamp` runs just before the send. Returns the receivers.
    pub fn send_fill(
        &mut self,
        header: &VideoHeader,
        len: usize,
        fill: impl FnMut(usize) -> u8,
        stamp: impl FnOnce(&mut VideoHeader),
    ) -> Result<usize, VideoSendError> {
        self.check(len)?;
        let mut sample = self.port.loan_slice_uninit(len).map_err(|source| self.loan_error(source))?;
        *sample.user_header_mut() = *header;
        let mut sample = sample.write_from_fn(fill);
        stamp(sample.user_header_mut());
        self.finish(sample.send())
    }

    /// Sends a copy of `bytes` with `header` (the one copy of the emulator's
    /// release); `stamp` runs just before the send.
    pub fn send_copy(&mut self, header: &VideoHeader, bytes: &[u8], stamp: impl FnOnce(&mut VideoHeader)) -> Result<usize, VideoSendError> {
        self.check(bytes.len())?;
        let mut sample = self.port.loan_slice_uninit(bytes.len()).map_err(|source| self.loan_error(source))?;
        *sample.user_header_mut() = *header;
        let mut sample = sample.write_from_slice(bytes);
        stamp(sample.user_header_mut());
        self.finish(sample.send())
    }

    /// Sends an end marker (no payload) after `sent` frames.
    pub fn send_end(&mut self, sent: u64) -> Result<usize, VideoSendError> {
        self.send_fill(&VideoHeader::end_marker(sent), 0, |_| 0, |_| {})
    }

    /// Subscribers registered on the channel.
    pub fn peers_connected(&self) -> usize {
        self.service.dynamic_config().number_of_subscribers()
    }

    fn check(&self, len: usize) -> Result<(), VideoSendError> {
        if len > self.max_len {
            return Err(VideoSendError::TooLarge { len, max: self.max_len });
        }
        Ok(())
    }

    fn loan_error(&self, source: iceoryx2::port::LoanError) -> VideoSendError {
        VideoSendError::Send(FrameSendError::Loan { run: self.run.clone(), channel: self.channel, source })
    }

    fn finish(&self, sent: Result<usize, SendError>) -> Result<usize, VideoSendError> {
        let subscribers = self.peers_connected();
        match sent {
            Ok(n) if n >= subscribers => Ok(n),
            Ok(_) | Err(SendError::UnableToDeliver) => Err(VideoSendError::Send(FrameSendError::QueueFull {
                run: self.run.clone(),
                channel: self.channel,
                consumer: self.channel.consumer().as_str(),
                capacity: VIDEO_BUFFER_FRAMES,
            })),
            Err(source) => Err(VideoSendError::Send(FrameSendError::Delivery { run: self.run.clone(), channel: self.channel, source })),
        }
    }
}

/// A video frame received, still in shared memory: the subscriber's
/// borrowed sample, returned when this is dropped.
pub struct VideoSample(Sample<Ipc, [u8], VideoHeader>);

impl std::fmt::Debug for VideoSample {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("VideoSample").field("header", self.header()).field("len", &self.bytes().len()).finish()
    }
}

impl VideoSample {
    /// The header the sender wrote.
    pub fn header(&self) -> &VideoHeader {
        self.0.user_header()
    }

    /// The frame's bytes, in place.
    pub fn bytes(&self) -> &[u8] {
        self.0.payload()
    }
}

/// The subscribing end of a video channel. Not `Send`.
pub struct VideoSubscriber {
    port: Subscriber<Ipc, [u8], VideoHeader>,
    service: VideoService,
    run: RunId,
    channel: Port,
}

impl std::fmt::Debug for VideoSubscriber {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("VideoSubscriber").field("run", &self.run).field("channel", &self.channel).finish()
    }
}

impl VideoSubscriber {
    pub(super) fn open(node: &Node<Ipc>, config: &IpcConfig, channel: Port) -> Result<Self, VideoOpenError> {
        let service = open_video_service(node, config, channel)?;
        let err = |e: String| VideoOpenError { service: config.service_name(channel), what: e };
        let port = service.subscriber_builder().buffer_size(VIDEO_BUFFER_FRAMES).create().map_err(|e| err(e.to_string()))?;
        port.update_connections().map_err(|e| err(e.to_string()))?;
        Ok(Self { port, service, run: config.run_id().clone(), channel })
    }

    /// Takes the oldest queued frame, left in shared memory until the
    /// returned sample is dropped; `None` when none waits. Never blocks. At
    /// most as many samples may be held at once as the channel lets a
    /// subscriber borrow.
    pub fn try_recv(&mut self) -> Result<Option<VideoSample>, FrameRecvError> {
        match self.port.receive() {
            Ok(s) => Ok(s.map(VideoSample)),
            Err(source) => Err(FrameRecvError::Receive { run: self.run.clone(), channel: self.channel, source }),
        }
    }

    /// Publishers registered on the channel (0 or 1).
    pub fn peers_connected(&self) -> usize {
        self.service.dynamic_config().number_of_publishers()
    }
}

impl super::IpcNode {
    /// Opens the publishing end of a video channel (`video`, `video_out`)
    /// for payloads of at most `max_len` bytes.
    pub fn video_publisher(&self, channel: Port, max_len: usize) -> Result<VideoPublisher, VideoOpenError> {
        let p = VideoPublisher::open(&self.node, &self.config, channel, max_len);
        super::node::make_private(self.config.prefix());
        p
    }

    /// Opens the subscribing end of a video channel.
    pub fn video_subscriber(&self, channel: Port) -> Result<VideoSubscriber, VideoOpenError> {
        let s = VideoSubscriber::open(&self.node, &self.config, channel);
        super::node::make_private(self.config.prefix());
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn video_header_type_name_and_offsets_are_pinned() {
        // SAFETY: type_name only returns the attribute's string.
        assert_eq!(unsafe { VideoHeader::type_name() }, VideoHeader::TYPE_NAME);
        let h = VideoHeader::default();
        let base = &h as *const _ as usize;
        assert_eq!(&h.ingress_index as *const _ as usize - base, 16);
        assert_eq!(&h.len as *const _ as usize - base, 48);
        assert_eq!(&h.gop_index as *const _ as usize - base, 56);
    }
}
