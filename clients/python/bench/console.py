#!/usr/bin/env python3
"""The benchmark's Python console (benches/python/): sends one frame every
half period, alternately through the netfi emulator (route 0) and straight
to the robot (route 1), so that each route runs at ``--rate-hz`` and both
see the same moments of the run; between sends it polls both routes for
the robot's feedback and records, per command, the round trip (sent → its
feedback received) with the emulator's stamps of both directions.

Over iceoryx2 the chain is run ``--run-id`` (``console`` → emulator →
``emulator``, feedback ``feedback`` → emulator → ``feedback_out``) and the
direct hop a second run, ``--direct-run-id``, with no emulator: the
console publishes on its ``emulator`` channel and takes the robot's
``feedback`` itself. Over UDP the chain goes to the emulator's ingress
(``--chain-to``; the robot's echo returns through the bridge's return
path) and the direct hop to the robot's own socket (``--direct-to``).

Writes its records (``--records``, int64 fields of common.CONSOLE_FIELDS)
and a JSON summary (``--summary``).
"""

import argparse
import math
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import common  # noqa: E402
from common import CHAIN, DIRECT, ROUTES, Records, now  # noqa: E402
from netfi_iox import FeedbackSample, FrameSample, RunNode, end_marker  # noqa: E402

#: Before a slot, with nothing in flight, the console sleeps until this long
#: before it, then polls (as the Rust benchmarks' driving thread does,
#: benches/common/drive.rs).
SLEEP_SLACK_NS = 100_000


class IoxRoutes:
    """The console's ports of both runs."""

    def __init__(self, run_id: str, direct_run_id: str):
        self.nodes = [RunNode(run_id, "console"), RunNode(direct_run_id, "console")]
        self.tx = [self.nodes[CHAIN].publisher("console"), self.nodes[DIRECT].publisher("emulator")]
        self.rx = [
            self.nodes[CHAIN].subscriber("feedback_out", FeedbackSample),
            self.nodes[DIRECT].subscriber("feedback", FeedbackSample),
        ]
        self.sample, self.fb = FrameSample(), FeedbackSample()
        self.ended = [False, False]

    def wait_ready(self, timeout_s: float) -> None:
        for route in ROUTES:
            self.tx[route].wait_for_subscriber(timeout_s, self.nodes[route])

    def send(self, route: int, slot: int, wire) -> bool:
        s = self.sample
        s.set_frame(bytes(wire))
        s.console_index = slot
        return self.tx[route].send(s, _stamp) > 0

    def poll(self, route: int, recs: Records) -> int:
        """Takes at most one answer of ``route``; 1 if one came."""
        f = self.fb
        if not self.rx[route].receive_into(f):
            return 0
        t = now()
        if f.is_end():
            self.ended[route] = True
            return 0
        recs.add(
            route, f.console_index, f.command_send_ns, t,
            f.command_ingress_ns, f.command_release_ns, f.command_injected_delay_ns,
            f.send_ns, f.ingress_ns, f.release_ns, f.injected_delay_ns, 0,
        )
        return 1

    def end(self, sent) -> None:
        for route in ROUTES:
            self.tx[route].send(end_marker(sent[route]))

    def all_ended(self) -> bool:
        return all(self.ended)

    def stopped(self) -> bool:
        return self.nodes[CHAIN].termination_requested()

    def close(self) -> None:
        for n in self.nodes:
            n.close()


def _stamp(s) -> None:
    s.send_ns = time.monotonic_ns()


class UdpRoutes:
    """Two loopback sockets: one to the emulator's ingress, one to the robot."""

    def __init__(self, chain_to: str, direct_to: str):
        self.to = [_addr(chain_to), _addr(direct_to)]
        self.socks = [common.udp_socket() for _ in ROUTES]
        self.buf = bytearray(2048)
        self.ended = [False, False]

    def wait_ready(self, timeout_s: float) -> None:
        pass

    def send(self, route: int, slot: int, wire) -> bool:
        common.stamp_udp(wire, now())
        try:
            self.socks[route].sendto(wire, self.to[route])
            return True
        except (BlockingIOError, OSError):
            return False

    def poll(self, route: int, recs: Records) -> int:
        """Takes at most one echo of ``route``; 1 if one came."""
        try:
            size = self.socks[route].recv_into(self.buf)
        except BlockingIOError:
            return 0
        t = now()
        if size < common.UDP_STAMP_OFFSET + 8:
            return 0
        slot, sent = common.read_udp(self.buf)
        recs.add(route, slot, sent, t, 0, 0, 0, 0, 0, 0, 0, 0)
        return 1

    def end(self, sent) -> None:
        # The direct route tells the robot the stream is over; the chain has
        # no end marker over UDP (the emulator ends by idleness).
        self.socks[DIRECT].sendto(b"E", self.to[DIRECT])

    def all_ended(self) -> bool:
        return False

    def stopped(self) -> bool:
        return False

    def close(self) -> None:
        for s in self.socks:
            s.close()


def _addr(text: str):
    host, port = text.rsplit(":", 1)
    return host, int(port)


class Drive:
    """One interval: slots at their times, both routes polled in between."""

    def __init__(self, routes, rate_hz: float, seconds: float, warmup_s: float):
        self.routes = routes
        self.half_ns = 1e9 / rate_hz / 2
        self.warm = 2 * math.ceil(rate_hz * warmup_s)
        self.slots = self.warm + 2 * round(rate_hz * seconds)
        self.sent, self.received, self.refused = [0, 0], [0, 0], 0
        self.recs = Records(common.CONSOLE_FIELDS)
        self.lateness_max = 0

    def poll(self) -> int:
        """Takes every waiting answer, one of each route at a time (in the
        order they were sent, as the routes alternate)."""
        got = 0
        while True:
            k0, k1 = self.routes.poll(CHAIN, self.recs), self.routes.poll(DIRECT, self.recs)
            self.received[CHAIN] += k0
            self.received[DIRECT] += k1
            got += k0 + k1
            if not (k0 or k1):
                return got

    def in_flight(self) -> bool:
        return self.sent[0] > self.received[0] or self.sent[1] > self.received[1]

    def wait_for(self, target: int) -> None:
        while True:
            t = now()
            if t >= target:
                return
            if self.poll():
                continue
            if not self.in_flight() and target - t > 2 * SLEEP_SLACK_NS:
                time.sleep((target - t - SLEEP_SLACK_NS) / 1e9)
            else:
                os.sched_yield()

    def run(self) -> int:
        t0 = now() + 2_000_000
        for slot in range(self.slots):
            if slot % 256 == 0 and self.routes.stopped():
                break
            wire = common.frame(slot)
            target = t0 + int(slot * self.half_ns)
            self.wait_for(target)
            route = slot % 2
            if self.routes.send(route, slot, wire):
                self.sent[route] += 1
            else:
                self.refused += 1
            self.lateness_max = max(self.lateness_max, now() - target)
        return t0

    def drain(self, timeout_s: float) -> None:
        deadline = now() + int(timeout_s * 1e9)
        while self.in_flight() and now() < deadline:
            if not self.poll():
                os.sched_yield()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    common.add_route_args(ap)
    ap.add_argument("--chain-to", help="UDP: the emulator's ingress, ADDR:PORT")
    ap.add_argument("--direct-to", help="UDP: the robot's direct socket, ADDR:PORT")
    ap.add_argument("--rate-hz", type=float, default=1000.0, help="frames per second on each route")
    ap.add_argument("--duration-s", type=float, required=True)
    ap.add_argument("--warmup-s", type=float, default=0.5)
    common.add_placement_args(ap)
    ap.add_argument("--records", required=True)
    ap.add_argument("--summary", required=True)
    a = ap.parse_args()
    common.place(a.core, a.nice)
    if a.transport == "iceoryx2":
        routes = IoxRoutes(a.run_id, a.direct_run_id)
    else:
        routes = UdpRoutes(a.chain_to, a.direct_to)
    try:
        routes.wait_ready(10.0)
        d = Drive(routes, a.rate_hz, a.duration_s, a.warmup_s)
        t0 = d.run()
        d.drain(1.0)
        routes.end(d.sent)
        deadline = now() + 5_000_000_000
        while a.transport == "iceoryx2" and not routes.all_ended() and now() < deadline:
            d.poll()
            time.sleep(0.0005)
    finally:
        routes.close()
    d.recs.write(a.records)
    common.write_summary(a.summary, {
        "transport": a.transport, "rate_hz": a.rate_hz, "t0_ns": t0, "half_period_ns": d.half_ns,
        "warm_slots": d.warm, "slots": d.slots, "sent": d.sent, "feedback_received": d.received,
        "refused": d.refused, "send_lateness_max_ns": d.lateness_max, "ended": routes.ended,
    })
    return 0


if __name__ == "__main__":
    sys.exit(main())
