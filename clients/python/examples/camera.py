#!/usr/bin/env python3
"""A synthetic Python camera for a netfi run over iceoryx2 (interface v1).

Publishes one video frame every period on the run's ``video`` channel, as
netfi's own camera does (``netfi run --video-mbps``): ``--hz`` frames a
second (default 60), sizes from a group of ``--gop`` pictures (one key frame
``--key-ratio`` times a delta frame, then delta frames) scaled to ``--mbps``
Mbit/s, byte ``k`` of frame ``i`` equal to ``(i + k) mod 256`` (what a
receiver checks). Each frame is a ``[u8]`` slice with a
``netfi::VideoHeader.v1`` header: ``frame_index``, ``len``, ``flags`` (key),
``gop_index``, and ``send_ns`` stamped just before publishing. Waits for
the emulator to subscribe, ends after ``--frames`` (or ``--duration-s``, or
SIGINT/SIGTERM) with the end marker (``flags`` = 1, ``frame_index`` = frames
sent), and prints a JSON summary (also ``--out FILE``).

    netfi emulator --run-id R --scenario Normal --video-mbps 8 --out out/R
    python3 clients/python/examples/camera.py --run-id R --mbps 8 --duration-s 10
"""

import argparse
import os
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

import netfi_iox  # noqa: E402
from netfi_iox import FLAG_KEY, Gop, Pattern, RunNode, VideoHeader  # noqa: E402
from netfi_iox.video import DEFAULT_VIDEO_MAX_BYTES  # noqa: E402
from netfi_iox.cli import emit, quantiles, run_main  # noqa: E402


def wait_until(target_ns: int) -> None:
    """Sleeps until ``target_ns`` (CLOCK_MONOTONIC), in slices of at most 2 ms."""
    while True:
        left = target_ns - time.monotonic_ns()
        if left <= 0:
            return
        time.sleep(min(left, 2_000_000) / 1e9)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--run-id", required=True)
    ap.add_argument("--mbps", type=float, required=True, help="mean bit rate of the video, Mbit/s")
    ap.add_argument("--hz", type=float, default=60.0, help="frame rate (default 60)")
    ap.add_argument("--gop", type=int, default=30, help="frames per group of pictures (default 30)")
    ap.add_argument("--key-ratio", type=float, default=8.0, help="a key frame's size over a delta frame's (default 8)")
    ap.add_argument("--max-bytes", type=int, default=DEFAULT_VIDEO_MAX_BYTES,
                    help="the publisher's initial sizing, bytes (a larger frame is still sent: the emulator drops it as too_large)")
    g = ap.add_mutually_exclusive_group()
    g.add_argument("--frames", type=int, help="frames to send")
    g.add_argument("--duration-s", type=float, help="seconds to stream (default: until SIGINT/SIGTERM)")
    ap.add_argument("--wait-for-peer-s", type=float, default=10.0, help="seconds to wait for the emulator")
    ap.add_argument("--out", help="also write the JSON summary here")
    a = ap.parse_args()
    try:
        gop = Gop(a.mbps * 1e6, a.hz, a.gop, a.key_ratio)
    except ValueError as e:
        ap.error(str(e))
    count = a.frames if a.frames is not None else (round(a.duration_s * a.hz) if a.duration_s is not None else None)
    # As netfi's camera: the frames are what the sizes say; the run's maximum is the emulator's check.
    max_len = max(a.max_bytes, gop.key_bytes)
    pattern = Pattern(max_len)
    period_ns = 1e9 / a.hz
    sent = bytes_sent = send_errors = unsubscribed = 0
    lateness = []
    ended_by = "done"
    with RunNode(a.run_id, "simulator") as node:
        port = node.video_publisher(max_len, "video")
        port.wait_for_subscriber(a.wait_for_peer_s, node)

        def stamp(h):
            h.send_ns = time.monotonic_ns()

        header = VideoHeader()
        t0 = time.monotonic_ns()
        i = 0
        while count is None or i < count:
            if node.termination_requested():
                ended_by = "signal"
                break
            target = t0 + round(i * period_ns)
            wait_until(target)
            length, key = gop.size(i)
            header.frame_index = i
            header.len = length
            header.flags = FLAG_KEY if key else 0
            header.gop_index = i % gop.frames
            try:
                if port.send(header, pattern.frame(i, length), stamp) == 0:
                    unsubscribed += 1
            except Exception:
                send_errors += 1
            lateness.append(time.monotonic_ns() - target)
            sent += 1
            bytes_sent += length
            i += 1
        port.send_end(sent)
    summary = {
        "interface": netfi_iox.VIDEO_HEADER_TYPE_NAME,
        "run_id": a.run_id,
        "frame_hz": a.hz,
        "gop_frames": gop.frames,
        "key_bytes": gop.key_bytes,
        "delta_bytes": gop.delta_bytes,
        "bit_rate_bit_s": gop.bit_rate(a.hz),
        "frames_sent": sent,
        "bytes_sent": bytes_sent,
        "send_errors": send_errors,
        "sent_unsubscribed": unsubscribed,
        "send_lateness_us": quantiles(lateness),
        "ended_by": ended_by,
    }
    emit(summary, a.out)
    return 0


if __name__ == "__main__":
    run_main("camera", main, (netfi_iox.InterfaceMismatch, netfi_iox.NoPeer, ValueError))
