"""The layout of a ``ctypes`` structure that mirrors a Rust ``#[repr(C)]``
type of the interface, and the check at import that ctypes gives the
layout the interface states (docs/interface.md)."""

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
