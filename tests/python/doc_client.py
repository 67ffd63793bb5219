"""A console and a robot written from docs/interface.md alone, on iceoryx2's
official Python bindings and ctypes: nothing of netfi's own Python module.
Every name, number and step below is the document's.

    doc_client.py robot RUN OUT.json READY [CLOSE]
        receives until the emulator's end marker (then, given CLOSE, waits
        for that file to appear before it closes)
    doc_client.py console RUN FRAMES OUT.json
        sends FRAMES frames at 1 kHz and the end marker

Each writes what it did as JSON; both close their node and, when last,
remove the run's management segment."""

import ctypes
import gc
import json
import os
import stat
import struct
import sys
import time

import iceoryx2 as iox

# "A run" → "The iceoryx2 configuration": the per-user layout.
UID = os.geteuid()


def private(path: str) -> bool:
    try:
        st = os.lstat(path)
    except OSError:
        return False
    return stat.S_ISDIR(st.st_mode) and st.st_uid == UID and not st.st_mode & 0o077


def root() -> str:
    named = os.environ.get("NETFI_IPC_ROOT", "")
    if named and private(named):
        return named.rstrip("/") + "/"
    xdg = os.environ.get("XDG_RUNTIME_DIR", "")
    if xdg and private(xdg):
        return os.path.join(xdg, "netfi-iceoryx2") + "/"
    return f"/tmp/netfi-iceoryx2-{UID}/"


ROOT = root()


def prefix(run: str) -> str:
    return f"netfi_u{UID}_{run}_"


def config(run: str):
    if not os.path.isdir(ROOT):
        os.mkdir(ROOT, 0o700)
    st = os.lstat(ROOT)
    if not stat.S_ISDIR(st.st_mode) or st.st_uid != UID or st.st_mode & 0o077:
        sys.exit(f"{ROOT} is not a private directory of this user")
    c = iox.config.default()
    g = c.global_cfg
    g.prefix = iox.FileName.new(prefix(run))
    g.root_path = iox.Path.new(ROOT)
    g.node.cleanup_dead_nodes_on_creation = False
    g.node.cleanup_dead_nodes_on_destruction = False
    g.service.cleanup_dead_nodes_on_open = False
    ps = c.defaults.publish_subscribe
    ps.max_publishers = 1
    ps.max_subscribers = 2
    ps.max_nodes = 8
    ps.subscriber_max_buffer_size = 16384
    ps.subscriber_max_borrowed_samples = 1
    ps.publisher_max_loaned_samples = 1
    ps.publisher_history_size = 0
    ps.enable_safe_overflow = False
    ps.backpressure_strategy = iox.BackpressureStrategy.DiscardData
    return c


# "The payload: netfi::FrameSample.v1": 192 bytes, aligned to 8.
class Sample(ctypes.Structure):
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
        ("wire", ctypes.c_uint8 * 124),
        ("_pad", ctypes.c_uint8 * 4),
    ]

    @staticmethod
    def type_name() -> str:
        return "netfi::FrameSample.v1"


assert ctypes.sizeof(Sample) == 192 and ctypes.alignment(Sample) == 8
assert Sample.wire.offset == 64 and Sample.len.offset == 56

# "The ITP frame in wire": 124 bytes, packed, little-endian.
ITP = struct.Struct("<III2i2i2i2d2d2d2d2i2iii")
assert ITP.size == 124


def itp(sequence: int) -> bytes:
    delx, dely, delz = [sequence % 7, -1], [2, sequence % 5], [0, 1]
    buttons, grasp, surgeon_mode = [0, 0], [10, -10], 1
    checksum = surgeon_mode + delx[0] + dely[0] + delz[0] + delx[1] + dely[1] + delz[1] + buttons[0] + buttons[1]
    checksum += struct.unpack("<i", struct.pack("<I", sequence))[0]
    checksum = struct.unpack("<i", struct.pack("<I", checksum & 0xFFFFFFFF))[0]
    q = [0.0, 0.0]
    # pactyp and version: 0.
    return ITP.pack(sequence, 0, 0, *delx, *dely, *delz, *q, *q, *q, 1.0, 1.0, *buttons, *grasp, surgeon_mode, checksum)


def checksum_ok(wire: bytes) -> bool:
    f = ITP.unpack(wire)
    sequence, delx, dely, delz = f[0], f[3:5], f[5:7], f[7:9]
    buttons, surgeon_mode, checksum = f[17:19], f[21], f[22]
    total = surgeon_mode + delx[0] + dely[0] + delz[0] + delx[1] + dely[1] + delz[1] + buttons[0] + buttons[1]
    total += struct.unpack("<i", struct.pack("<I", sequence))[0]
    return struct.unpack("<i", struct.pack("<I", total & 0xFFFFFFFF))[0] == checksum


def open_node(run: str, role: str):
    c = config(run)
    node = (
        iox.NodeBuilder.new()
        .name(iox.NodeName.new(f"netfi/{run}/{role}"))
        .config(c)
        .signal_handling_mode(iox.SignalHandlingMode.HandleTerminationRequests)
        .create(iox.ServiceType.Ipc)
    )
    # "/dev/shm": the run's files made private to this user.
    for name in os.listdir("/dev/shm"):
        path = os.path.join("/dev/shm", name)
        if name.startswith(prefix(run)) and os.lstat(path).st_uid == UID:
            os.chmod(path, 0o600)
    return c, node


def service(node, run: str, channel: str):
    return (
        node.service_builder(iox.ServiceName.new(f"netfi/{run}/{channel}"))
        .publish_subscribe(Sample)
        .max_publishers(1)
        .max_subscribers(2)
        .max_nodes(8)
        .subscriber_max_buffer_size(16384)
        .subscriber_max_borrowed_samples(1)
        .history_size(0)
        .enable_safe_overflow(False)
        .open_or_create()
    )


def stopped(node) -> bool:
    try:
        node.wait(iox.Duration.from_nanos(0))
    except iox.NodeWaitFailure:
        return True
    return False


def close(c, run: str) -> bool:
    """Once this process's node is gone: removes the management segment when
    every node of the run listed is dead. Whether it did."""
    gc.collect()
    if any(not isinstance(s, iox.NodeState.Dead) for s in iox.Node.list(iox.ServiceType.Ipc, c)):
        return False
    removed = False
    for name in os.listdir("/dev/shm"):
        path = os.path.join("/dev/shm", name)
        if name.startswith(prefix(run)) and name.endswith(".global_mgmt") and os.lstat(path).st_uid == UID:
            os.unlink(path)
            removed = True
    return removed


def robot(run: str, out: str, ready: str, close_after: str = "") -> None:
    c, node = open_node(run, "simulator")
    svc = service(node, run, "emulator")
    sub = svc.subscriber_builder().buffer_size(16384).create()
    mgmt = [n for n in os.listdir("/dev/shm") if n.startswith(prefix(run)) and n.endswith(".global_mgmt")]
    modes = [oct(os.stat(os.path.join("/dev/shm", n)).st_mode & 0o777) for n in mgmt]
    open(ready, "w").close()
    received = bad = 0
    sequences = []
    marker = None
    deadline = time.monotonic() + 120
    while marker is None and time.monotonic() < deadline and not stopped(node):
        sample = sub.receive()
        if sample is None:
            time.sleep(0.0002)
            continue
        s = Sample()
        ctypes.memmove(ctypes.byref(s), sample.payload_ptr, ctypes.sizeof(s))
        sample.delete()
        sample = None
        if s.flags & 1:
            marker = s.console_index
        elif s.len == 124 and checksum_ok(bytes(s.wire)):
            received += 1
            sequences.append(ITP.unpack(bytes(s.wire))[0])
        else:
            bad += 1
    while close_after and not os.path.exists(close_after) and time.monotonic() < deadline and not stopped(node):
        time.sleep(0.01)
    sub.delete()
    del sub, svc, node
    removed = close(c, run)
    json.dump({"received": received, "bad": bad, "marker": marker, "sequences": sequences, "mgmt_modes": modes, "removed_segment": removed}, open(out, "w"))


def console(run: str, frames: int, out: str) -> None:
    c, node = open_node(run, "console")
    svc = service(node, run, "console")
    pub = svc.publisher_builder().max_loaned_samples(1).backpressure_strategy(iox.BackpressureStrategy.DiscardData).create()
    # "Waiting for the emulator".
    deadline = time.monotonic() + 10
    while svc.dynamic_config.number_of_subscribers < 1:
        if time.monotonic() > deadline or stopped(node):
            sys.exit(f"no emulator subscribed to netfi/{run}/console")
        time.sleep(0.001)
    unsubscribed = 0
    period_ns = 1_000_000
    t0 = time.monotonic_ns()
    for i in range(frames + 1):
        while time.monotonic_ns() < t0 + i * period_ns:
            pass
        s = Sample()
        s.console_index = i
        if i < frames:
            s.wire[:] = itp(i)
            s.len = 124
        else:
            s.flags = 1  # the end marker: console_index = frames sent
        s.send_ns = time.monotonic_ns()
        loaned = pub.loan_uninit().write_payload(s)
        if loaned.send() == 0:
            unsubscribed += 1
        loaned = None
    pub.delete()
    del pub, svc, node
    removed = close(c, run)
    json.dump({"sent": frames, "unsubscribed": unsubscribed, "removed_segment": removed}, open(out, "w"))


if __name__ == "__main__":
    role, run = sys.argv[1], sys.argv[2]
    if role == "robot":
        robot(run, sys.argv[3], sys.argv[4], sys.argv[5] if len(sys.argv) > 5 else "")
    else:
        console(run, int(sys.argv[3]), sys.argv[4])
    assert not any(m.startswith("netfi_iox") for m in sys.modules), "netfi's own module was imported"
