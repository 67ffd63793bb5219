#!/usr/bin/env python3
"""A Python console for a netfi run over iceoryx2 (interface v1).

Streams ITP frames to the emulator (channel ``console``) and, unless
``--no-direct``, the same frames to the robot directly (channel ``direct``,
the baseline hop): synthetic bimanual motion at ``--rate-hz``, or a capture
replayed with its original timing (or at ``--rate-hz``). Waits for the
emulator to subscribe, stamps each sample with its send time, ends with the
end-of-stream marker, and prints a JSON summary (also ``--out FILE``).
Meanwhile it takes the robot's feedback as the emulator passes it back
(channel ``feedback_out``) and measures the round trip of each command
(sent → the robot's feedback naming it received); after its last frame it
waits for the end of the feedback (``--feedback-wait-s``).

    python3 clients/python/examples/console.py --run-id R --rate-hz 1000 --duration-s 5
"""

import argparse
import math
import os
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

import netfi_iox  # noqa: E402
from netfi_iox import FeedbackSample, FrameSample, ItpFrame, RunNode, end_marker  # noqa: E402
from netfi_iox.cli import emit, quantiles, run_main  # noqa: E402


def synthetic(rate_hz: float, n: int):
    """Smooth bimanual motion: each arm traces a slow ellipse (increments in
    ITP position units), the clutch released for 0.2 s every 3 s, the grasp
    opening and closing. Yields ``(offset_ns, wire)``."""
    period_ns = 1e9 / rate_hz
    pos = [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]
    sent = [[0, 0, 0], [0, 0, 0]]
    for i in range(n):
        t = i / rate_hz
        engaged = (t % 3.0) < 2.8
        inc = [[0, 0, 0], [0, 0, 0]]
        for arm in (0, 1):
            phase = t * 2 * math.pi * (0.25 + 0.1 * arm)
            target = [3000 * (math.cos(phase) - 1), 2000 * math.sin(phase), 500 * math.sin(2 * phase)]
            for ax in range(3):
                pos[arm][ax] = target[ax]
                want = round(pos[arm][ax]) - sent[arm][ax]
                inc[arm][ax] = want
                sent[arm][ax] += want
        f = ItpFrame(
            sequence=i,
            delx=(inc[0][0], inc[1][0]),
            dely=(inc[0][1], inc[1][1]),
            delz=(inc[0][2], inc[1][2]),
            grasp=(int(500 + 500 * math.sin(t)), int(500 - 500 * math.sin(t))),
            surgeon_mode=1 if engaged else 0,
        ).seal()
        yield round(i * period_ns), f.encode()


def replay(records, rate_hz, n):
    for i, (offset_ns, wire) in enumerate(records[:n]):
        yield (round(i * 1e9 / rate_hz) if rate_hz else offset_ns), wire


def wait_until(target_ns: int, poll=None) -> None:
    """Sleeps until shortly before ``target_ns``, then polls the clock;
    calls ``poll()`` at least every 100 µs meanwhile, when given."""
    while True:
        if poll is not None:
            poll()
        left = target_ns - time.monotonic_ns()
        if left <= 0:
            return
        if left > 300_000:
            time.sleep(min(left - 200_000, 100_000 if poll is not None else left) / 1e9)


class Feedback:
    """The console's end of the feedback loop: counts the robot's feedback
    and the round trip of each command it names."""

    def __init__(self, port):
        self.port = port
        self.sample = FeedbackSample()
        self.received = 0
        self.unknown_command = 0
        self.sent_by_emulator = None
        self.rtt = []
        self.sent = 0

    def poll(self) -> None:
        while self.port.receive_into(self.sample):
            t = time.monotonic_ns()
            f = self.sample
            if f.is_end():
                self.sent_by_emulator = f.robot_index
                continue
            self.received += 1
            if f.console_index >= self.sent:
                self.unknown_command += 1
                continue
            self.rtt.append(t - f.command_send_ns)

    def wait_end(self, timeout_s: float, node) -> str:
        deadline = time.monotonic() + timeout_s
        while True:
            self.poll()
            if self.sent_by_emulator is not None:
                return "end_marker"
            if self.port.peers_connected() == 0:
                self.poll()
                return "end_marker" if self.sent_by_emulator is not None else "no_emulator"
            if time.monotonic() > deadline:
                return "timeout"
            if node.termination_requested():
                return "signal"
            time.sleep(0.0001)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--run-id", required=True)
    ap.add_argument("--rate-hz", type=float, help="frame rate (default 1000; a capture keeps its own timing unless given)")
    g = ap.add_mutually_exclusive_group()
    g.add_argument("--frames", type=int, help="frames to send")
    g.add_argument("--duration-s", type=float, help="seconds to stream (default 5; a capture: all of it)")
    ap.add_argument("--capture", help="replay this LZ4 ITP capture instead of synthetic motion")
    ap.add_argument("--no-direct", action="store_true", help="do not send the direct (baseline) copies")
    ap.add_argument("--wait-for-peer-s", type=float, default=10.0, help="seconds to wait for the emulator")
    ap.add_argument("--out", help="also write the JSON summary here")
    ap.add_argument("--feedback-wait-s", type=float, default=5.0, help="seconds to wait for the end of the feedback")
    a = ap.parse_args()
    if a.rate_hz is not None and not (a.rate_hz > 0 and math.isfinite(a.rate_hz)):
        ap.error("--rate-hz must be a positive number")

    if a.capture:
        records = netfi_iox.capture.load(a.capture)
        count = len(records)
        if a.frames is not None:
            count = min(count, a.frames)
        elif a.duration_s is not None:
            count = min(count, round(a.duration_s * (a.rate_hz or 517.0)))
        script = replay(records, a.rate_hz, count)
        source = f"capture:{a.capture}"
    else:
        rate = a.rate_hz or 1000.0
        count = a.frames if a.frames is not None else round((a.duration_s or 5.0) * rate)
        script = synthetic(rate, count)
        source = "synthetic"

    with RunNode(a.run_id, "console") as node:
        port = node.publisher("console")
        direct = None if a.no_direct else node.publisher("direct")
        fb = Feedback(node.subscriber("feedback_out", FeedbackSample))
        port.wait_for_subscriber(a.wait_for_peer_s, node)
        sent = send_errors = unsubscribed = direct_sent = 0
        ended_by = "done"
        sample = FrameSample()

        def stamp(s):
            s.send_ns = time.monotonic_ns()

        t_start = time.monotonic_ns() + 1_000_000
        lateness = []
        for i, (offset_ns, wire) in enumerate(script):
            if i % 64 == 0 and node.termination_requested():
                ended_by = "signal"
                break
            target = t_start + offset_ns
            wait_until(target, fb.poll)
            sample.set_frame(wire)
            sample.console_index = i
            try:
                if port.send(sample, stamp) == 0:
                    unsubscribed += 1
            except Exception:
                send_errors += 1
            lateness.append(time.monotonic_ns() - target)
            sent += 1
            fb.sent = sent
            fb.poll()
            if fb.sent_by_emulator is not None:
                # The emulator ended the feedback early (its robot died):
                # stop, so the stream ends with a marker it will take.
                ended_by = "emulator_ended"
                break
            if direct is not None:
                try:
                    direct.send(sample, stamp)
                    direct_sent += 1
                except Exception:
                    pass
        t_end = time.monotonic_ns()
        port.send(end_marker(sent))
        if direct is not None:
            direct.send(end_marker(sent))
        feedback_ended_by = fb.wait_end(a.feedback_wait_s, node)

    lateness.sort()
    duration_s = max(t_end - t_start, 0) / 1e9
    summary = {
        "interface": netfi_iox.TYPE_NAME,
        "run_id": a.run_id,
        "source": source,
        "frames_sent": sent,
        "direct_sent": direct_sent,
        "send_errors": send_errors,
        "sent_unsubscribed": unsubscribed,
        "rate_hz": sent / duration_s if duration_s > 0 else 0.0,
        "duration_s": duration_s,
        "send_lateness_us": {
            "p50": lateness[len(lateness) // 2] / 1e3 if lateness else None,
            "p99": lateness[min(len(lateness) - 1, len(lateness) * 99 // 100)] / 1e3 if lateness else None,
        },
        "ended_by": ended_by,
        "feedback": {
            "received": fb.received,
            "sent_by_emulator": fb.sent_by_emulator,
            "unknown_command": fb.unknown_command,
            "ended_by": feedback_ended_by,
            "round_trip_us": quantiles(fb.rtt),
        },
    }
    emit(summary, a.out)
    return 0


if __name__ == "__main__":
    run_main("console", main, (netfi_iox.InterfaceMismatch, netfi_iox.NoPeer, ValueError))
