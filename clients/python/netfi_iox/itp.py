"""ITP master-to-slave frame codec (docs/spec.md §2): 124 bytes, packed,
little-endian, with the checksum netfi verifies."""

import struct
from dataclasses import dataclass, field
from typing import Tuple

from .payload import ITP_FRAME_LEN

# sequence, pactyp, version, delx[2], dely[2], delz[2], Qx[2], Qy[2], Qz[2],
# Qw[2], buttonstate[2], grasp[2], surgeon_mode, checksum
_FORMAT = struct.Struct("<III2i2i2i2d2d2d2d2i2iii")
assert _FORMAT.size == ITP_FRAME_LEN

#: ``surgeon_mode``: clutch engaged, the frame's increments apply.
SURGEON_ENGAGED = 1
#: ``surgeon_mode``: clutch released, the robot holds still.
SURGEON_DISENGAGED = 0

_I32 = 1 << 32


def _wrap_i32(v: int) -> int:
    v &= _I32 - 1
    return v - _I32 if v >= 1 << 31 else v


def checksum(sequence, delx, dely, delz, buttonstate, surgeon_mode) -> int:
    """Wrapping 32-bit sum of ``surgeon_mode``, both arms' position
    increments, both ``buttonstate``s and ``sequence`` (as i32). ``grasp``,
    the rotations, ``pactyp`` and ``version`` are not included."""
    return _wrap_i32(
        surgeon_mode
        + delx[0] + dely[0] + delz[0]
        + delx[1] + dely[1] + delz[1]
        + buttonstate[0] + buttonstate[1]
        + _wrap_i32(sequence)
    )


class FrameError(ValueError):
    """Bytes that are not a valid ITP frame."""


@dataclass
class ItpFrame:
    """One ITP frame; arrays hold arm 0 then arm 1."""

    sequence: int = 0
    pactyp: int = 0
    version: int = 0
    delx: Tuple[int, int] = (0, 0)
    dely: Tuple[int, int] = (0, 0)
    delz: Tuple[int, int] = (0, 0)
    qx: Tuple[float, float] = (0.0, 0.0)
    qy: Tuple[float, float] = (0.0, 0.0)
    qz: Tuple[float, float] = (0.0, 0.0)
    qw: Tuple[float, float] = (1.0, 1.0)
    buttonstate: Tuple[int, int] = (0, 0)
    grasp: Tuple[int, int] = (0, 0)
    surgeon_mode: int = SURGEON_ENGAGED
    checksum: int = field(default=0)

    def computed_checksum(self) -> int:
        """The checksum the fields call for."""
        return checksum(self.sequence, self.delx, self.dely, self.delz, self.buttonstate, self.surgeon_mode)

    def seal(self) -> "ItpFrame":
        """Sets ``checksum`` from the fields; returns self."""
        self.checksum = self.computed_checksum()
        return self

    def checksum_ok(self) -> bool:
        return self.checksum == self.computed_checksum()

    def encode(self) -> bytes:
        """The 124 wire bytes (the checksum as it stands: call :meth:`seal` first)."""
        return _FORMAT.pack(
            self.sequence & 0xFFFFFFFF, self.pactyp, self.version,
            *self.delx, *self.dely, *self.delz,
            *self.qx, *self.qy, *self.qz, *self.qw,
            *self.buttonstate, *self.grasp, self.surgeon_mode, self.checksum,
        )

    @classmethod
    def decode(cls, wire: bytes, verify: bool = True) -> "ItpFrame":
        """Parses 124 wire bytes; with ``verify``, refuses a wrong checksum."""
        if len(wire) != ITP_FRAME_LEN:
            raise FrameError(f"wrong ITP frame length: expected {ITP_FRAME_LEN} bytes, got {len(wire)}")
        v = _FORMAT.unpack(wire)
        f = cls(
            sequence=v[0], pactyp=v[1], version=v[2],
            delx=v[3:5], dely=v[5:7], delz=v[7:9],
            qx=v[9:11], qy=v[11:13], qz=v[13:15], qw=v[15:17],
            buttonstate=v[17:19], grasp=v[19:21], surgeon_mode=v[21], checksum=v[22],
        )
        if verify and not f.checksum_ok():
            raise FrameError(
                f"ITP checksum mismatch: computed {f.computed_checksum()} from the fields, frame carries {f.checksum}"
            )
        return f
