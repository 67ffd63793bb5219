"""What the benchmark's Python console and robot share: placement, per-frame
records, the benchmark's ITP frames and their stamps, and the summary.

The benchmark (``cargo bench --bench python``, benches/python/) starts the
two programs; they are not meant to be run by hand. Frames go two routes,
alternately: route 0 through the netfi emulator (the chain), route 1
straight from the console to the robot (the direct hop).
"""

import json
import os
import socket
import struct
import sys
import time
from array import array

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

from netfi_iox import ItpFrame  # noqa: E402

CHAIN, DIRECT = 0, 1
ROUTES = (CHAIN, DIRECT)

#: Fields of one robot record (all int64): route, slot, console send time,
#: robot receive time, and the emulator's stamps of the command (iceoryx2;
#: zero over UDP and on the direct route).
ROBOT_FIELDS = ("route", "slot", "send_ns", "recv_ns", "ingress_ns", "release_ns", "injected_delay_ns", "reserved")
#: Fields of one console record: the command's route, slot and send time,
#: the time its feedback was received, then the emulator's stamps of the
#: command (forward) and of the feedback (return) and the robot's send time
#: of the feedback (iceoryx2; zero over UDP and on the direct route).
CONSOLE_FIELDS = (
    "route", "slot", "send_ns", "recv_ns",
    "cmd_ingress_ns", "cmd_release_ns", "cmd_injected_delay_ns",
    "fb_send_ns", "fb_ingress_ns", "fb_release_ns", "fb_injected_delay_ns", "reserved",
)

#: Over UDP the console's send time travels in the frame: the 8 bytes of
#: ``Qw[0]`` (offset 84), which the ITP checksum does not cover. The slot is
#: the ITP ``sequence`` (offset 0).
UDP_STAMP_OFFSET = 84
_U64 = struct.Struct("<Q")
_U32 = struct.Struct("<I")


def place(core, nice) -> None:
    """Pins this process to ``core`` and sets its nice value (None: leaves
    each as it is; a negative nice value needs CAP_SYS_NICE)."""
    if core is not None:
        os.sched_setaffinity(0, {core})
    if nice is not None:
        os.setpriority(os.PRIO_PROCESS, 0, nice)


def add_route_args(ap) -> None:
    """The transport, and the runs of the chained and direct routes."""
    ap.add_argument("--transport", choices=("iceoryx2", "udp"), required=True)
    ap.add_argument("--run-id")
    ap.add_argument("--direct-run-id")


def add_placement_args(ap) -> None:
    ap.add_argument("--core", type=int, help="pin to this core")
    ap.add_argument("--nice", type=int, help="run at this nice value")


def udp_socket() -> socket.socket:
    """A non-blocking UDP socket on a free loopback port."""
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    s.setblocking(False)
    return s


def frame(slot: int) -> bytearray:
    """The benchmark's frame of ``slot``: a sealed ITP frame whose sequence
    is the slot (an engaged clutch, no motion)."""
    return bytearray(ItpFrame(sequence=slot & 0xFFFFFFFF).seal().encode())


def stamp_udp(buf: bytearray, ns: int) -> None:
    _U64.pack_into(buf, UDP_STAMP_OFFSET, ns)


def read_udp(buf) -> tuple:
    """(slot, send_ns) of a benchmark frame received over UDP."""
    return _U32.unpack_from(buf, 0)[0], _U64.unpack_from(buf, UDP_STAMP_OFFSET)[0]


class Records:
    """Fixed-width int64 records, written raw (little-endian) for the
    benchmark to read."""

    def __init__(self, fields):
        self.width = len(fields)
        self.data = array("q")

    def add(self, *values) -> None:
        self.data.extend(values)

    def __len__(self) -> int:
        return len(self.data) // self.width

    def write(self, path: str) -> None:
        if sys.byteorder != "little":
            self.data.byteswap()
        with open(path, "wb") as f:
            self.data.tofile(f)


def write_summary(path: str, summary: dict) -> None:
    text = json.dumps(summary, indent=2)
    with open(path, "w") as f:
        f.write(text + "\n")


def now() -> int:
    return time.monotonic_ns()
