"""Opens run RUN's console channel with payloads of another interface
version; prints the refusal of each on one line. Exits 1 if one is accepted."""

import ctypes
import sys

import netfi_iox


class FrameSampleV0(netfi_iox.FrameSample):
    """The v1 layout under the name of another version."""

    @staticmethod
    def type_name() -> str:
        return "netfi::FrameSample.v0"


class Wider(ctypes.Structure):
    """The v1 name on a payload of another size."""

    _fields_ = [("words", ctypes.c_uint64 * 25)]

    @staticmethod
    def type_name() -> str:
        return netfi_iox.TYPE_NAME


with netfi_iox.RunNode(sys.argv[1], "tool") as node:
    for payload in (FrameSampleV0, Wider):
        try:
            node.publisher("console", payload)
        except netfi_iox.InterfaceMismatch as e:
            print(str(e).replace("\n", " "))
        else:
            print(f"{netfi_iox.run.service_name(sys.argv[1], 'console')} accepted {payload.type_name()}")
            sys.exit(1)
