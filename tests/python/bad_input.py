"""Publishes bad input on run RUN's console channel, then a flood of good
frames as fast as it can, then the end marker; prints what it sent as JSON."""

import json
import os
import sys

import netfi_iox
from netfi_iox import FrameSample, ItpFrame, RunNode, end_marker

with RunNode(sys.argv[1], "console") as node:
    port = node.publisher("console")
    port.wait_for_subscriber(30, node)
    good = ItpFrame(sequence=1, surgeon_mode=1).seal().encode()
    sent = 0
    refused = 0

    def send(s):
        global sent, refused
        s.console_index = sent
        sent += 1
        if port.send(s) == 0:
            refused += 1

    for n in (0, 50, 500):  # zero, short, oversize
        s = FrameSample()
        s.set_frame(good)
        s.len = n
        send(s)
    for flags in (0xFF00, netfi_iox.FLAG_RAW):  # garbage bits; raw on iceoryx2
        s = FrameSample()
        s.set_frame(good)
        s.flags = flags
        send(s)
    s = FrameSample()  # garbage bytes of the right length: a bad checksum
    s.set_frame(os.urandom(124))
    send(s)
    flood = int(sys.argv[2])
    for i in range(flood):
        s = FrameSample()
        s.set_frame(ItpFrame(sequence=i, surgeon_mode=1).seal().encode())
        send(s)
    port.send(end_marker(sent))
    print(json.dumps({"sent": sent, "refused": refused}))
