"""The shared-memory sample of interface version 1: ``netfi::FrameSample.v1``.

Mirrors ``src/sample.rs`` byte for byte (``#[repr(C)]``, 192 bytes, aligned
to 8). The offsets below are the interface (docs/interface.md); the module
checks at import that ctypes lays the structure out the same way, and the
Rust test ``tests/python`` checks them against the Rust type.
"""

import ctypes

from .layout import Payload, check_layout, layout_of

#: The iceoryx2 type name of the payload. A layout or meaning change bumps
#: the ``.vN`` suffix; iceoryx2 refuses to connect ports whose names differ.
TYPE_NAME = "netfi::FrameSample.v1"

#: Interface version (the suffix of :data:`TYPE_NAME`).
INTERFACE_VERSION = 1

#: Length of an ITP master-to-slave frame on the wire.
ITP_FRAME_LEN = 124

#: ``flags`` bit: the sample marks the end of a stream, it is not a frame.
#: Its ``console_index`` carries the number of frames sent before it.
FLAG_END = 1

#: ``flags`` bit: the sample carries an opaque datagram (the UDP bridge's raw
#: mode); no ITP validation applies. Never set by an iceoryx2 console.
FLAG_RAW = 2


class FrameSample(Payload):
    """One frame in shared memory: the 124 wire bytes plus metadata.

    All times are CLOCK_MONOTONIC nanoseconds (``time.monotonic_ns()`` in
    Python reads the same clock on Linux).
    """

    _fields_ = [
        ("send_ns", ctypes.c_uint64),
        ("console_index", ctypes.c_uint64),
        ("ingress_index", ctypes.c_uint64),
        ("ingress_ns", ctypes.c_uint64),
        ("injected_delay_ns", ctypes.c_uint64),
        ("release_sched_ns", ctypes.c_uint64),
        ("release_ns", ctypes.c_uint64),
        ("len", ctypes.c_uint32),
        ("flags", ctypes.c_uint32),
        ("wire", ctypes.c_uint8 * ITP_FRAME_LEN),
        ("_pad", ctypes.c_uint8 * 4),
    ]

    TYPE_NAME = TYPE_NAME
    END_FLAG = FLAG_END

    def payload(self) -> bytes:
        """The valid wire bytes (``len`` of them, at most 124)."""
        return bytes(self.wire)[: min(self.len, ITP_FRAME_LEN)]

    def set_frame(self, wire: bytes) -> None:
        """Puts one ITP frame's wire bytes in and sets ``len``."""
        if len(wire) != ITP_FRAME_LEN:
            raise ValueError(f"an ITP frame is {ITP_FRAME_LEN} bytes, got {len(wire)}")
        ctypes.memmove(self.wire, wire, ITP_FRAME_LEN)
        self.len = ITP_FRAME_LEN


#: Byte offset of every field, as docs/interface.md states them.
OFFSETS = {
    "send_ns": 0,
    "console_index": 8,
    "ingress_index": 16,
    "ingress_ns": 24,
    "injected_delay_ns": 32,
    "release_sched_ns": 40,
    "release_ns": 48,
    "len": 56,
    "flags": 60,
    "wire": 64,
    "_pad": 188,
}

#: Size and alignment of the sample in bytes.
SIZE = 192
ALIGNMENT = 8


def layout() -> dict:
    """The layout ctypes actually gives :class:`FrameSample` (for checks)."""
    return layout_of(FrameSample, TYPE_NAME)


check_layout(FrameSample, TYPE_NAME, SIZE, ALIGNMENT, OFFSETS)


def end_marker(frames_sent: int) -> FrameSample:
    """An end-of-stream marker after ``frames_sent`` frames."""
    return FrameSample(console_index=frames_sent, flags=FLAG_END)


#: The iceoryx2 type name of the robot's feedback (channels ``feedback`` and
#: ``feedback_out``).
FEEDBACK_TYPE_NAME = "netfi::FeedbackSample.v1"


class FeedbackSample(Payload):
    """The robot's feedback, one per command it received: which command it
    answers, the robot's integrated pose then, and the emulator's stamps of
    both directions (docs/interface.md). Mirrors ``FeedbackSample`` of
    ``src/sample.rs`` (216 bytes, aligned to 8)."""

    _fields_ = [
        ("send_ns", ctypes.c_uint64),
        ("robot_index", ctypes.c_uint64),
        ("console_index", ctypes.c_uint64),
        ("command_send_ns", ctypes.c_uint64),
        ("command_ingress_ns", ctypes.c_uint64),
        ("command_release_ns", ctypes.c_uint64),
        ("command_injected_delay_ns", ctypes.c_uint64),
        ("ingress_index", ctypes.c_uint64),
        ("ingress_ns", ctypes.c_uint64),
        ("injected_delay_ns", ctypes.c_uint64),
        ("release_sched_ns", ctypes.c_uint64),
        ("release_ns", ctypes.c_uint64),
        ("sequence", ctypes.c_uint32),
        ("flags", ctypes.c_uint32),
        ("position", (ctypes.c_int64 * 3) * 2),
        ("rotation", (ctypes.c_double * 3) * 2),
        ("grasp", ctypes.c_int32 * 2),
        ("commands", ctypes.c_uint64),
    ]

    TYPE_NAME = FEEDBACK_TYPE_NAME
    END_FLAG = FLAG_END


#: Byte offset of every field of :class:`FeedbackSample`.
FEEDBACK_OFFSETS = {
    "send_ns": 0,
    "robot_index": 8,
    "console_index": 16,
    "command_send_ns": 24,
    "command_ingress_ns": 32,
    "command_release_ns": 40,
    "command_injected_delay_ns": 48,
    "ingress_index": 56,
    "ingress_ns": 64,
    "injected_delay_ns": 72,
    "release_sched_ns": 80,
    "release_ns": 88,
    "sequence": 96,
    "flags": 100,
    "position": 104,
    "rotation": 152,
    "grasp": 200,
    "commands": 208,
}

FEEDBACK_SIZE = 216


def feedback_layout() -> dict:
    """The layout ctypes actually gives :class:`FeedbackSample`."""
    return layout_of(FeedbackSample, FEEDBACK_TYPE_NAME)


check_layout(FeedbackSample, FEEDBACK_TYPE_NAME, FEEDBACK_SIZE, ALIGNMENT, FEEDBACK_OFFSETS)


def feedback_end_marker(sent: int) -> FeedbackSample:
    """The end of a feedback stream after ``sent`` feedback samples."""
    return FeedbackSample(robot_index=sent, flags=FLAG_END)
