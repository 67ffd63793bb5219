"""The video channels of interface version 1 (docs/interface.md, "Video").

A video frame is an iceoryx2 slice of bytes (``iox2.Slice[ctypes.c_uint8]``,
Rust ``[u8]``) with a user header beside it, ``netfi::VideoHeader.v1``:
:class:`VideoHeader` mirrors ``VideoHeader`` of ``src/sample.rs`` byte for
byte (``#[repr(C)]``, 64 bytes, aligned to 8); the module checks its layout
at import, and the Rust test ``tests/python`` checks it against the Rust
type. The camera publishes on ``video`` (the emulator subscribes); the
emulator releases on ``video_out`` (the console, and at most one other
viewer, subscribe).

Also here: the synthetic camera's group of pictures (:class:`Gop`) and the
byte pattern of its frames (:class:`Pattern`), as netfi's own camera makes
them, so that either side may be Python or Rust.
"""

import ctypes
from typing import Callable, Optional

import iceoryx2 as iox

from .layout import Payload, check_layout, layout_of
from .ports import MAX_SUBSCRIBERS_PER_CHANNEL, PublishingEnd, SubscribingEnd

#: The iceoryx2 type name of the user header.
VIDEO_HEADER_TYPE_NAME = "netfi::VideoHeader.v1"

#: ``flags`` bit: the end of the video stream, not a frame (no payload);
#: its ``frame_index`` is the number of frames sent (by the camera) or
#: released (by the emulator).
FLAG_VIDEO_END = 1
#: ``flags`` bit: a key frame (the first of its group of pictures).
FLAG_KEY = 2

#: Frames a subscriber's queue holds (``subscriber_max_buffer_size``).
VIDEO_BUFFER_FRAMES = 64
#: Samples the emulator may hold borrowed from ``video`` at once.
VIDEO_HELD_FRAMES = 64
#: The most bytes a publisher's sample is given at first (it grows for
#: larger frames: ``AllocationStrategy.PowerOfTwo``).
VIDEO_INITIAL_SLICE_BYTES = 256 * 1024
#: The default largest video payload of a run (``--video-max-bytes``).
DEFAULT_VIDEO_MAX_BYTES = 4 << 20
#: The payload's element type, as iceoryx2 names it on both sides.
VIDEO_PAYLOAD = iox.Slice[ctypes.c_uint8]

#: The stride at which a receiver checks a frame's bytes: every 509th byte
#: (509 is prime, so every place in the pattern's 256-byte cycle is seen).
CHECK_STRIDE = 509


class VideoHeader(Payload):
    """The header beside each video frame. Times are CLOCK_MONOTONIC ns
    (``time.monotonic_ns()``)."""

    _fields_ = [
        ("send_ns", ctypes.c_uint64),
        ("frame_index", ctypes.c_uint64),
        ("ingress_index", ctypes.c_uint64),
        ("ingress_ns", ctypes.c_uint64),
        ("release_sched_ns", ctypes.c_uint64),
        ("release_ns", ctypes.c_uint64),
        ("len", ctypes.c_uint32),
        ("flags", ctypes.c_uint32),
        ("gop_index", ctypes.c_uint32),
        ("_reserved", ctypes.c_uint32),
    ]

    TYPE_NAME = VIDEO_HEADER_TYPE_NAME
    END_FLAG = FLAG_VIDEO_END

    def is_key(self) -> bool:
        """Whether the frame is a key frame."""
        return bool(self.flags & FLAG_KEY)


#: Byte offset of every field, as docs/interface.md states them.
VIDEO_HEADER_OFFSETS = {
    "send_ns": 0,
    "frame_index": 8,
    "ingress_index": 16,
    "ingress_ns": 24,
    "release_sched_ns": 32,
    "release_ns": 40,
    "len": 48,
    "flags": 52,
    "gop_index": 56,
    "_reserved": 60,
}
VIDEO_HEADER_SIZE = 64
VIDEO_HEADER_ALIGNMENT = 8


def video_header_layout() -> dict:
    """The layout ctypes actually gives :class:`VideoHeader` (for checks)."""
    return layout_of(VideoHeader, VIDEO_HEADER_TYPE_NAME)


check_layout(VideoHeader, VIDEO_HEADER_TYPE_NAME, VIDEO_HEADER_SIZE, VIDEO_HEADER_ALIGNMENT, VIDEO_HEADER_OFFSETS)


def video_end_marker(count: int) -> VideoHeader:
    """The end marker after ``count`` frames."""
    return VideoHeader(frame_index=count, flags=FLAG_VIDEO_END)


def _round(x: float) -> int:
    """Rounds half away from zero, as Rust's ``f64::round`` (x ≥ 0)."""
    return int(x + 0.5)


class Gop:
    """The sizes of a group of pictures at a bit rate, as netfi's camera
    computes them (``src/video.rs``): one key frame of ``key_ratio`` times a
    delta frame's size, then ``frames - 1`` delta frames, scaled so that the
    mean bit rate is ``bit_rate_bit_s``."""

    def __init__(self, bit_rate_bit_s: float, frame_hz: float, frames: int, key_ratio: float):
        if not 0 < bit_rate_bit_s <= 1e11:
            raise ValueError(f"the video's bit rate must be above 0 and at most 100 Gbit/s, got {bit_rate_bit_s} bit/s")
        if not 0.1 <= frame_hz <= 10_000:
            raise ValueError(f"the video's frame rate must be from 0.1 to 10000 Hz, got {frame_hz}")
        if frames < 1:
            raise ValueError("a group of pictures has at least one frame")
        if not 1 <= key_ratio <= 1000:
            raise ValueError(f"the key frame ratio must be from 1 to 1000, got {key_ratio}")
        mean = bit_rate_bit_s / 8.0 / frame_hz
        delta = mean * frames / (frames - 1.0 + key_ratio)
        self.frames = frames
        self.delta_bytes = max(_round(delta), 1)
        self.key_bytes = max(_round(delta * key_ratio), 1)

    def size(self, index: int):
        """Frame ``index``'s size in bytes and whether it is a key frame."""
        if index % self.frames == 0:
            return self.key_bytes, True
        return self.delta_bytes, False

    def bit_rate(self, frame_hz: float) -> float:
        """The mean bit rate the sizes give, bit/s."""
        group = self.key_bytes + self.delta_bytes * (self.frames - 1)
        return group * 8.0 * frame_hz / self.frames


class Pattern:
    """The camera's bytes: byte ``k`` of frame ``i`` is ``(i + k) mod 256``
    (netfi's ``pattern``). Frames up to ``max_len`` bytes are views into one
    buffer made once, so neither sending nor checking a frame builds it."""

    def __init__(self, max_len: int):
        self.max_len = max_len
        self.buf = bytes(range(256)) * (max_len // 256 + 2)

    def frame(self, index: int, length: int) -> memoryview:
        """Frame ``index``'s ``length`` bytes (no copy)."""
        if length > self.max_len:
            raise ValueError(f"a frame of {length} bytes is over this pattern's {self.max_len}")
        off = index % 256
        return memoryview(self.buf)[off : off + length]

    def intact(self, index: int, length: int, data: memoryview) -> bool:
        """Whether ``data`` is frame ``index`` as sent: ``length`` bytes, and
        every :data:`CHECK_STRIDE`-th byte the pattern's (the check netfi's
        console makes)."""
        if len(data) != length or length > self.max_len:
            return False
        off = index % 256
        return data[::CHECK_STRIDE].tobytes() == self.buf[off : off + length : CHECK_STRIDE]


class VideoFrame:
    """A received frame, still in shared memory: ``header`` (a copy) and
    ``data`` (a view of the bytes in place). Call :meth:`release` (or use
    it as a context manager) before taking the next one: a viewer may hold
    one frame at a time."""

    def __init__(self, sample):
        self._sample = sample
        self.header = VideoHeader()
        ctypes.memmove(ctypes.byref(self.header), sample.user_header_ptr, VIDEO_HEADER_SIZE)
        payload = sample.payload()
        self.data = payload.as_memory_view() if payload.len() > 0 else memoryview(b"")

    def release(self) -> None:
        """Returns the sample to its publisher; ``data`` is invalid after."""
        if self._sample is not None:
            self.data.release()
            self._sample.delete()
            self._sample = None

    def __enter__(self) -> "VideoFrame":
        return self

    def __exit__(self, *exc) -> None:
        self.release()


class VideoPublisher(PublishingEnd):
    """The publishing end of a video channel (``video`` for a camera)."""

    def __init__(self, service, port, max_len: int):
        super().__init__(service, port)
        self.max_len = max_len

    def send(self, header: VideoHeader, data, stamp: Optional[Callable[[VideoHeader], None]] = None) -> int:
        """Loans a sample of ``len(data)`` bytes, copies ``header`` and
        ``data`` in, calls ``stamp(header)`` on the shared-memory header just
        before sending (e.g. to set ``send_ns``), and sends. Returns the
        number of subscribers that received it."""
        n = len(data)
        if n > self.max_len:
            raise ValueError(f"a video payload of {n} bytes is larger than this publisher's maximum of {self.max_len} bytes")
        sample = self.port.loan_slice_uninit(n)
        ctypes.memmove(sample.user_header_ptr, ctypes.byref(header), VIDEO_HEADER_SIZE)
        if n:
            ctypes.memmove(sample.payload().as_ptr(), data if isinstance(data, bytes) else bytes(data), n)
        sample = sample.assume_init()
        if stamp is not None:
            stamp(sample.user_header().contents)
        return sample.send()

    def send_end(self, count: int) -> int:
        """Sends the end marker after ``count`` frames."""
        return self.send(video_end_marker(count), b"")


class VideoSubscriber(SubscribingEnd):
    """A subscribing end of a video channel (``video_out`` for a viewer)."""

    def receive(self) -> Optional[VideoFrame]:
        """The oldest queued frame (or end marker), or None."""
        sample = self.port.receive()
        return None if sample is None else VideoFrame(sample)


def channel_limits(channel: str):
    """``(max_subscribers, subscriber_max_borrowed_samples)`` of a video
    channel: the emulator alone on ``video``, holding what its link holds;
    the console and one more viewer on ``video_out``, one frame each."""
    if channel == "video":
        return 1, VIDEO_HELD_FRAMES
    if channel == "video_out":
        return MAX_SUBSCRIBERS_PER_CHANNEL, 1
    raise ValueError(f"{channel!r} is not a video channel; expected video or video_out")
