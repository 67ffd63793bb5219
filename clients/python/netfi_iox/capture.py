"""Reading netfi's ITP captures (docs/spec.md §7): a sequence of one or more
complete standard LZ4 frames (what ``lz4 -d`` decodes as one stream), whose
content is a sequence of records — u64 big-endian receive time in ns, u16
big-endian payload length, one "dropped" flag byte, then the payload.

As netfi's own reader, this one refuses what is not a sequence of complete
frames: bytes after a frame that begin no other (garbage appended or between
frames), a frame cut short, a bad checksum (the LZ4 library checks the block
and content checksums it finds). Skippable frames are skipped when whole."""

import struct
from typing import List, Tuple

from .itp import ItpFrame
from .payload import ITP_FRAME_LEN

_HEADER = struct.Struct(">QHB")
_LZ4_MAGIC = b"\x04\x22\x4d\x18"
_SKIPPABLE_MAGIC = 0x184D2A50


def decompress(data: bytes, path: str = "capture") -> bytes:
    """The content of every LZ4 frame in ``data``, in order, as one stream;
    ``ValueError`` naming the frame and byte when ``data`` is not a sequence
    of complete frames."""
    import lz4.frame  # the `lz4` package; only needed for captures

    out, pos, frames = [], 0, 0
    while pos < len(data):
        head = data[pos : pos + 4]
        if len(head) == 4 and int.from_bytes(head, "little") & ~0xF == _SKIPPABLE_MAGIC:
            size = int.from_bytes(data[pos + 4 : pos + 8], "little") if pos + 8 <= len(data) else None
            if size is None or pos + 8 + size > len(data):
                raise ValueError(f"{path}: the skippable frame at byte {pos} is cut short")
            pos += 8 + size
            continue
        if head != _LZ4_MAGIC:
            what = "not an LZ4 frame" if frames == 0 else f"{len(data) - pos} byte(s) after the end of LZ4 frame {frames} that are not an LZ4 frame"
            raise ValueError(f"{path}: byte {pos}: {what}; a capture is a sequence of complete LZ4 frames")
        decoder = lz4.frame.LZ4FrameDecompressor()
        try:
            out.append(decoder.decompress(data[pos:]))
        except RuntimeError as e:
            raise ValueError(f"{path}: LZ4 frame {frames + 1} at byte {pos} is damaged: {e}") from e
        if not decoder.eof:
            raise ValueError(f"{path}: LZ4 frame {frames + 1} at byte {pos} ends without its end mark: the file was cut short")
        pos = len(data) - len(decoder.unused_data or b"")
        frames += 1
    if frames == 0:
        raise ValueError(f"{path}: no LZ4 frame: the file is empty")
    return b"".join(out)


def load(path: str, verify: bool = True) -> List[Tuple[int, bytes]]:
    """The capture's frames as ``(offset_ns, wire)``: offsets from the first
    record, made non-decreasing (a wall-clock recording may step back)."""
    with open(path, "rb") as f:
        data = decompress(f.read(), path)
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
    if not records:
        raise ValueError(f"{path}: contains no records")
    return records
