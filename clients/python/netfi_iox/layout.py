"""The layout of a ``ctypes`` structure that mirrors a Rust ``#[repr(C)]``
type of the interface, the check at import that ctypes gives the layout
the interface states (docs/interface.md), and what every payload type has:
its iceoryx2 type name and its end flag."""

import ctypes


def layout_of(structure, type_name: str) -> dict:
    """The layout ctypes actually gives ``structure``: its iceoryx2 type
    name, size, alignment and the offset of every field."""
    return {
        "type_name": type_name,
        "size": ctypes.sizeof(structure),
        "alignment": ctypes.alignment(structure),
        "offsets": {name: getattr(structure, name).offset for name, _ in structure._fields_},
    }


def check_layout(structure, type_name: str, size: int, alignment: int, offsets: dict) -> None:
    """Refuses to import a module whose ``structure`` is not laid out as the
    interface states."""
    actual = layout_of(structure, type_name)
    expected = {"type_name": type_name, "size": size, "alignment": alignment, "offsets": offsets}
    if actual != expected:
        raise ImportError(f"{structure.__name__} layout differs from the interface: {actual} != {expected}")


class Payload(ctypes.Structure):
    """The base of the interface's payload types: a subclass names its
    iceoryx2 type (``TYPE_NAME``) and the ``flags`` bit that marks its end
    of stream (``END_FLAG``)."""

    TYPE_NAME = ""
    END_FLAG = 1

    @classmethod
    def type_name(cls) -> str:
        """The iceoryx2 type name (read by ``iceoryx2.get_type_name``)."""
        return cls.TYPE_NAME

    def is_end(self) -> bool:
        """Whether this sample marks the end of its stream."""
        return bool(self.flags & self.END_FLAG)
