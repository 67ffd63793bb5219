"""Reading netfi's ITP captures (docs/spec.md §7): one standard LZ4 frame whose
content is a sequence of records — u64 big-endian receive time in ns, u16
big-endian payload length, one "dropped" flag byte, then the payload."""

import struct
from typing import List, Tuple

from .itp import ItpFrame
from .payload import ITP_FRAME_LEN

_HEADER = struct.Struct(">QHB")


def load(path: str, verify: bool = True) -> List[Tuple[int, bytes]]:
    """The capture's frames as ``(offset_ns, wire)``: offsets from the first
    record, made non-decreasing (a wall-clock recording may step back)."""
    import lz4.frame  # the `lz4` package; only needed for captures

    with open(path, "rb") as f:
        data = lz4.frame.decompress(f.read())
    records = []
    pos, t0, last = 0, None, 0
    while pos < len(data):
        if pos + _HEADER.size > len(data):
            raise ValueError(f"{path}: record header cut at byte {pos}")
        t, n, _dropped = _HEADER.unpack_from(data, pos)
        pos += _HEADER.size
        if n != ITP_FRAME_LEN or pos + n > len(data):
            raise ValueError(f"{path}: record of {n} bytes at byte {pos - _HEADER.size}; ITP records are {ITP_FRAME_LEN}")
        wire = data[pos : pos + n]
        pos += n
        if verify:
            ItpFrame.decode(wire)
        t0 = t if t0 is None else t0
        last = max(last, t - t0)
        records.append((last, wire))
    return records
