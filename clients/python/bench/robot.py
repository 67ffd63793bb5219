#!/usr/bin/env python3
"""The benchmark's Python robot (benches/python/): takes the frames of both
routes (through the emulator, and straight from the console), records each
one's arrival, and answers it at once on the same route: over iceoryx2 with
a ``netfi::FeedbackSample.v1`` that echoes the command's stamps (as
clients/python/examples/robot.py does), over UDP by echoing the datagram to
its sender (the emulator's egress socket, whose return path relays it to the
console, or the console itself).

Over iceoryx2 it ends when both routes' end markers have come; over UDP
when the console's end datagram has come on the direct socket and the chain
has been quiet for 300 ms. Writes its records (``--records``, int64 fields
of common.ROBOT_FIELDS) and a JSON summary (``--summary``); ``--ready``
is written once its ports are open (over UDP: the two ports, as JSON).
"""

import argparse
import json
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import common  # noqa: E402
from common import CHAIN, DIRECT, ROUTES, Records, now  # noqa: E402
from netfi_iox import FeedbackSample, FrameSample, RunNode, feedback_end_marker  # noqa: E402

#: Over UDP, the chain counts as drained after this long without a datagram.
UDP_QUIET_NS = 300_000_000


class IoxRobot:
    """The robot's ports of both runs (the chain's and the direct one's)."""

    def __init__(self, run_id: str, direct_run_id: str):
        self.nodes = [RunNode(run_id, "simulator"), RunNode(direct_run_id, "simulator")]
        self.rx = [n.subscriber("emulator") for n in self.nodes]
        self.tx = [n.publisher("feedback", FeedbackSample) for n in self.nodes]
        self.sample, self.fb = FrameSample(), FeedbackSample()
        self.answered = [0, 0]
        self.ended = [False, False]
        self.turns = 0

    def ready(self) -> dict:
        return {}

    def serve(self, route: int, recs: Records) -> int:
        """Takes at most one frame of ``route`` and answers it; 1 if one came."""
        s, fb = self.sample, self.fb
        if not self.rx[route].receive_into(s):
            return 0
        t = now()
        if s.is_end():
            self.tx[route].send(feedback_end_marker(self.answered[route]))
            self.ended[route] = True
            return 0
        recs.add(route, s.console_index, s.send_ns, t, s.ingress_ns, s.release_ns, s.injected_delay_ns, 0)
        fb.robot_index = self.answered[route]
        fb.console_index = s.console_index
        fb.command_send_ns = s.send_ns
        fb.command_ingress_ns = s.ingress_ns
        fb.command_release_ns = s.release_ns
        fb.command_injected_delay_ns = s.injected_delay_ns
        fb.commands = self.answered[route] + 1
        self.tx[route].send(fb, _stamp)
        self.answered[route] += 1
        return 1

    def done(self, last_ns: int) -> bool:
        self.turns += 1
        if all(self.ended):
            return True
        # A zero wait on the node is a system call: look for SIGINT/SIGTERM
        # now and then, not on every turn.
        return self.turns % 4096 == 0 and self.nodes[CHAIN].termination_requested()

    def close(self) -> None:
        for n in self.nodes:
            n.close()


def _stamp(f) -> None:
    f.send_ns = now()


class UdpRobot:
    """Two loopback sockets: the emulator's egress sends to the first, the
    console's direct route to the second."""

    def __init__(self):
        self.socks = [common.udp_socket() for _ in ROUTES]
        self.buf = bytearray(2048)
        self.view = memoryview(self.buf)
        self.answered = [0, 0]
        self.ended = [False, False]

    def ready(self) -> dict:
        return {"chain": self.socks[CHAIN].getsockname()[1], "direct": self.socks[DIRECT].getsockname()[1]}

    def serve(self, route: int, recs: Records) -> int:
        """Takes at most one datagram of ``route`` and echoes it; 1 if one came."""
        try:
            size, addr = self.socks[route].recvfrom_into(self.buf)
        except BlockingIOError:
            return 0
        t = now()
        if size < common.UDP_STAMP_OFFSET + 8:
            self.ended[route] = True
            return 0
        slot, sent = common.read_udp(self.buf)
        recs.add(route, slot, sent, t, 0, 0, 0, 0)
        try:
            self.socks[route].sendto(self.view[:size], addr)
            self.answered[route] += 1
        except (BlockingIOError, OSError):
            pass
        return 1

    def done(self, last_ns: int) -> bool:
        return self.ended[DIRECT] and now() - last_ns > UDP_QUIET_NS

    def close(self) -> None:
        for s in self.socks:
            s.close()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    common.add_route_args(ap)
    common.add_placement_args(ap)
    ap.add_argument("--ready", required=True)
    ap.add_argument("--timeout-s", type=float, default=120.0)
    ap.add_argument("--records", required=True)
    ap.add_argument("--summary", required=True)
    a = ap.parse_args()
    common.place(a.core, a.nice)
    robot = IoxRobot(a.run_id, a.direct_run_id) if a.transport == "iceoryx2" else UdpRobot()
    recs = Records(common.ROBOT_FIELDS)
    received = [0, 0]
    timed_out = False
    try:
        with open(a.ready, "w") as f:
            json.dump(robot.ready(), f)
        t_start = last = now()
        while not robot.done(last):
            # One frame of each route at a time: frames that piled up while
            # the robot was off its core are taken in the order they were
            # sent (the routes alternate), so neither route waits for the
            # other's backlog.
            got = 0
            while True:
                k0, k1 = robot.serve(CHAIN, recs), robot.serve(DIRECT, recs)
                received[CHAIN] += k0
                received[DIRECT] += k1
                got += k0 + k1
                if not (k0 or k1):
                    break
            if got:
                last = now()
            else:
                os.sched_yield()
            if now() - t_start > a.timeout_s * 1e9:
                timed_out = True
                break
    finally:
        robot.close()
    recs.write(a.records)
    common.write_summary(a.summary, {
        "received": received, "answered": robot.answered, "ended": robot.ended, "timed_out": timed_out,
    })
    return 3 if timed_out else 0


if __name__ == "__main__":
    sys.exit(main())
