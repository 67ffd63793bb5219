"""Python clients of netfi's iceoryx2 interface, version 1 (docs/interface.md).

- :mod:`netfi_iox.payload`: the shared-memory samples ``netfi::FrameSample.v1`` and ``netfi::FeedbackSample.v1``;
- :mod:`netfi_iox.itp`: the ITP frame codec and its checksum;
- :mod:`netfi_iox.run`: a run's configuration, names and node;
- :mod:`netfi_iox.ports`: the ends of its channels (publishers, subscribers, waiting for a peer);
- :mod:`netfi_iox.video`: the video channels' header ``netfi::VideoHeader.v1``, ports, and the
  synthetic camera's sizes and bytes;
- :mod:`netfi_iox.capture`: reading netfi's LZ4 ITP captures;
- :mod:`netfi_iox.layout`: the check at import that each ``ctypes`` mirror has the interface's layout;
- :mod:`netfi_iox.cli`: what the example programs share (quantiles, their JSON summary, their exit on errors).
"""

from . import capture
from .itp import SURGEON_DISENGAGED, SURGEON_ENGAGED, FrameError, ItpFrame, checksum
from .payload import (
    FEEDBACK_TYPE_NAME, FLAG_END, FLAG_RAW, INTERFACE_VERSION, ITP_FRAME_LEN, TYPE_NAME, FeedbackSample, FrameSample,
    end_marker, feedback_end_marker, feedback_layout, layout,
)
from .run import (
    CHANNELS, InterfaceMismatch, NoPeer, RunNode, iceoryx2_config, location, node_name, service_name,
)
from .video import (
    FLAG_KEY, FLAG_VIDEO_END, VIDEO_HEADER_TYPE_NAME, Gop, Pattern, VideoFrame, VideoHeader, VideoPublisher,
    VideoSubscriber, video_end_marker, video_header_layout,
)

__all__ = [
    "FEEDBACK_TYPE_NAME", "FeedbackSample", "feedback_end_marker", "feedback_layout",
    "CHANNELS", "FLAG_END", "FLAG_RAW", "INTERFACE_VERSION", "ITP_FRAME_LEN", "SURGEON_DISENGAGED",
    "SURGEON_ENGAGED", "TYPE_NAME", "FrameError", "FrameSample", "InterfaceMismatch", "ItpFrame", "NoPeer",
    "RunNode", "checksum", "end_marker", "iceoryx2_config", "layout", "location", "node_name", "service_name",
    "FLAG_KEY", "FLAG_VIDEO_END", "VIDEO_HEADER_TYPE_NAME", "Gop", "Pattern", "VideoFrame", "VideoHeader",
    "VideoPublisher", "VideoSubscriber", "video_end_marker", "video_header_layout",
]
