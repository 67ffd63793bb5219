#!/usr/bin/env python3
"""A Python video viewer for a netfi run over iceoryx2 (interface v1).

Takes the video frames the emulator releases (channel ``video_out``,
``[u8]`` slices with a ``netfi::VideoHeader.v1`` header) and measures them
as netfi's console does: each frame's delay (camera send → receive), whether
it arrived whole (its ``len`` bytes, every 509th byte the camera's pattern)
or damaged, and the freezes: gaps between displayed frames (whole, newer
than the last displayed) longer than two frame periods (``--hz``, the
camera's rate). Ends on the emulator's end marker (or SIGINT/SIGTERM, or
``--timeout-s``), then prints a JSON summary (also ``--out FILE``);
``--csv FILE`` also writes one row per frame received, in the columns of
netfi's ``video_received.csv`` (docs/spec.md §6).

    python3 clients/python/examples/viewer.py --run-id R --hz 60 --out viewer.json
"""

import argparse
import os
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

import netfi_iox  # noqa: E402
from netfi_iox import Pattern, RunNode  # noqa: E402
from netfi_iox.cli import emit, quantiles, run_main  # noqa: E402

#: The columns of netfi's ``video_received.csv``.
CSV_HEADER = (
    "frame_index,gop_index,key,len,bytes,send_ns,ingress_index,ingress_ns,release_sched_ns,release_ns,"
    "recv_ns,delay_ns,fate,displayed,gap_ns,freeze"
)


class Viewer:
    """What the viewer has seen so far."""

    def __init__(self, hz: float, csv):
        self.threshold_ns = int(2e9 / hz)
        self.pattern = Pattern(1 << 20)
        self.csv = csv
        self.received = self.whole = self.damaged = self.late = self.bytes = self.key_frames = 0
        self.delays = []
        self.freezes = self.freeze_total_ns = self.freeze_longest_ns = 0
        self.shown = None
        self.last_shown_ns = None
        self.last_index = None
        self.indices_increasing = True
        self.released_by_emulator = None

    def frame(self, h, data, t: int) -> None:
        """A frame (not the end marker) received at ``t``."""
        self.received += 1
        self.bytes += len(data)
        self.key_frames += h.is_key()
        if self.last_index is not None and h.frame_index <= self.last_index:
            self.indices_increasing = False
        self.last_index = h.frame_index
        if h.len > self.pattern.max_len:
            self.pattern = Pattern(2 * h.len)
        whole = self.pattern.intact(h.frame_index, h.len, data)
        displayed, gap, freeze = False, None, False
        if not whole:
            self.damaged += 1
        else:
            self.whole += 1
            self.delays.append(t - h.send_ns)
            if self.shown is not None and h.frame_index <= self.shown:
                self.late += 1
            else:
                displayed, self.shown = True, h.frame_index
                if self.last_shown_ns is not None:
                    gap = t - self.last_shown_ns
                    freeze = gap > self.threshold_ns
                    if freeze:
                        self.freezes += 1
                        self.freeze_total_ns += gap
                        self.freeze_longest_ns = max(self.freeze_longest_ns, gap)
                self.last_shown_ns = t
        if self.csv is not None:
            self.csv.write(
                f"{h.frame_index},{h.gop_index},{int(h.is_key())},{h.len},{len(data)},{h.send_ns},{h.ingress_index},"
                f"{h.ingress_ns},{h.release_sched_ns},{h.release_ns},{t},{max(t - h.send_ns, 0)},"
                f"{'whole' if whole else 'damaged'},{int(displayed)},{'' if gap is None else gap},{int(freeze)}\n"
            )

    def summary(self) -> dict:
        return {
            "received": self.received,
            "whole": self.whole,
            "damaged": self.damaged,
            "late": self.late,
            "bytes": self.bytes,
            "key_frames": self.key_frames,
            "last_frame_index": self.last_index,
            "indices_increasing": self.indices_increasing,
            "delay_ms": quantiles(self.delays, unit_ns=1e6, points=(0.5, 0.9, 0.99), mean=True),
            "freezes": self.freezes,
            "freeze_total_ms": self.freeze_total_ns / 1e6,
            "freeze_longest_ms": self.freeze_longest_ns / 1e6,
            "freeze_threshold_ms": self.threshold_ns / 1e6,
            "released_by_emulator": self.released_by_emulator,
            "balanced": self.released_by_emulator == self.received,
        }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--run-id", required=True)
    ap.add_argument("--hz", type=float, default=60.0, help="the camera's frame rate, for the freeze threshold (default 60)")
    ap.add_argument("--ready", help="create this file once subscribed (for scripts that start the emulator next)")
    ap.add_argument("--timeout-s", type=float, help="give up when no end marker came after this many seconds")
    ap.add_argument("--out", help="also write the JSON summary here")
    ap.add_argument("--csv", help="also write one row per frame received here")
    a = ap.parse_args()
    if not a.hz > 0:
        ap.error("--hz must be positive")
    csv = open(a.csv, "w", buffering=1 << 16) if a.csv else None
    if csv is not None:
        csv.write(CSV_HEADER + "\n")
    v = Viewer(a.hz, csv)
    ended_by = None
    with RunNode(a.run_id, "console") as node:
        port = node.video_subscriber("video_out")
        if a.ready:
            open(a.ready, "w").close()
        t_start = last = time.monotonic_ns()
        stop_at = None
        while ended_by is None:
            f = port.receive()
            now = time.monotonic_ns()
            if f is not None:
                with f:
                    last = now
                    if f.header.is_end():
                        v.released_by_emulator = f.header.frame_index
                        ended_by = "end_marker"
                    else:
                        v.frame(f.header, f.data, now)
                continue
            if stop_at is None and node.termination_requested():
                stop_at = now
            if stop_at is not None and (now - last > 200_000_000 or port.peers_connected() == 0):
                ended_by = "signal"
            elif a.timeout_s is not None and now - t_start > a.timeout_s * 1e9:
                ended_by = "timeout"
            time.sleep(0.0002)
        t_end = time.monotonic_ns()
    if csv is not None:
        csv.close()
    summary = {"interface": netfi_iox.VIDEO_HEADER_TYPE_NAME, "run_id": a.run_id, **v.summary(), "ended_by": ended_by, "duration_s": (t_end - t_start) / 1e9}
    emit(summary, a.out)
    return 0 if ended_by != "timeout" else 3


if __name__ == "__main__":
    run_main("viewer", main, (netfi_iox.InterfaceMismatch, ValueError))
