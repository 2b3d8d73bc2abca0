"""A PX4 ULog (``.ulg``) writer, for simulated flights that PX4's tools read like a real log.

The format (PX4 ``docs/en/dev_log/ulog_file_format.md``; read by ``pyulog`` and PX4's
``logger`` module writes it): a 16-byte header ``ULog`` ``0x01 0x12 0x35``, the version byte 1
and the start time (uint64, us), then messages ``uint16 size, uint8 type, payload[size]``:

=====  ====================================================================================
type   payload
=====  ====================================================================================
``B``  flag bits: 8 compatible and 8 incompatible flag bytes, 3 appended offsets (uint64);
       the first message, all zero here
``F``  a topic's format: ``name:type field;type field;...`` (``float[4] q``; the first field
       ``uint64_t timestamp``)
``I``  information: ``uint8 key length``, key ``"type name"`` (``char[3] sys_name``), value
``P``  a parameter, as ``I``: key ``"float NAME"`` or ``"int32_t NAME"``, value 4 bytes
``A``  subscription: ``uint8 multi_id``, ``uint16 msg_id``, topic name
``D``  data: ``uint16 msg_id``, the fields packed little-endian as the format says
=====  ====================================================================================

Definitions (``B``, ``F``, ``I``, ``P``) come before the data section, which the first ``A``
opens. Fields are written without padding (``pyulog`` and PX4's ``ulog_cpp`` read the packed
layout the format describes).
"""

from __future__ import annotations

import struct
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ..errors import CalibrationError

__all__ = ["ULOG_TYPES", "ulog_bytes"]

_MAGIC = b"ULog\x01\x12\x35"
#: ULog field types -> (struct code, numpy dtype).
ULOG_TYPES = {
    "uint64_t": ("Q", "<u8"), "int64_t": ("q", "<i8"), "uint32_t": ("I", "<u4"),
    "int32_t": ("i", "<i4"), "uint16_t": ("H", "<u2"), "int16_t": ("h", "<i2"),
    "uint8_t": ("B", "u1"), "int8_t": ("b", "i1"), "float": ("f", "<f4"),
    "double": ("d", "<f8"), "bool": ("?", "?"),
}


def _message(kind: str, payload: bytes) -> bytes:
    if len(payload) > 0xFFFF:
        raise CalibrationError(f"a ULog message holds at most 65535 bytes, got {len(payload)}")
    return struct.pack("<HB", len(payload), ord(kind)) + payload


def _keyed(kind: str, key: str, value: bytes) -> bytes:
    k = key.encode("ascii")
    return _message(kind, bytes([len(k)]) + k + value)


def _fields(spec: Sequence[tuple[str, str]]) -> list[tuple[str, str, int]]:
    """``(type, name)`` pairs, ``"float[4]"`` allowed, -> ``(type, name, count)``."""
    out = []
    for typ, name in spec:
        count = 1
        if typ.endswith("]"):
            typ, n = typ[:-1].split("[")
            count = int(n)
        if typ not in ULOG_TYPES:
            raise CalibrationError(f"unknown ULog field type {typ!r}")
        out.append((typ, name, count))
    if not out or out[0][:2] != ("uint64_t", "timestamp"):
        raise CalibrationError("a ULog topic's first field is uint64_t timestamp")
    return out


def ulog_bytes(
    topics: Mapping[str, tuple[Sequence[tuple[str, str]], Mapping[str, Any]]],
    *,
    start_us: int,
    info: Mapping[str, Any] | None = None,
    params: Mapping[str, float | int] | None = None,
) -> bytes:
    """A ULog file holding ``topics`` (instance 0 each).

    Parameters
    ----------
    topics : mapping
        ``name -> (fields, columns)``: ``fields`` the ``(type, name)`` pairs of the format
        (``("float[4]", "q")`` for an array; first ``("uint64_t", "timestamp")``), ``columns``
        one array per field (``(N,)``, or ``(N, k)`` for an array of ``k``).
    start_us : int
        The header's start time (us).
    info : mapping, optional
        Information messages: ``str`` values are written as ``char[n]``, ``int`` as
        ``uint32_t`` (``ver_sw_release``).
    params : mapping, optional
        Parameters: ``int`` values as ``int32_t``, ``float`` as ``float``.

    Returns
    -------
    bytes

    Examples
    --------
    >>> t = np.array([1000, 2000], dtype=np.uint64)
    >>> data = ulog_bytes({"demo": ([("uint64_t", "timestamp"), ("float", "x")],
    ...                             {"timestamp": t, "x": np.array([1.5, 2.5])})},
    ...                   start_us=0, params={"SYS_HAS_MAG": 1})
    >>> data[:7], len(data)
    (b'ULog\\x01\\x125', 165)
    """
    out = bytearray(_MAGIC + b"\x01" + struct.pack("<Q", int(start_us)))
    out += _message("B", bytes(16) + bytes(24))
    layouts = {}
    for name, (spec, cols) in topics.items():
        fields = _fields(spec)
        fmt = name + ":" + "".join(
            f"{t}{'' if c == 1 else f'[{c}]'} {n};" for t, n, c in fields)
        out += _message("F", fmt.encode("ascii"))
        dtype = np.dtype([(n, ULOG_TYPES[t][1], (c,)) if c > 1 else (n, ULOG_TYPES[t][1])
                          for t, n, c in fields])
        n_rows = len(np.asarray(cols["timestamp"]))
        rec = np.zeros(n_rows, dtype=dtype)
        for _, n, c in fields:
            v = np.asarray(cols[n])
            if v.shape != ((n_rows,) if c == 1 else (n_rows, c)):
                raise CalibrationError(f"ULog topic {name}: field {n} has shape {v.shape}, "
                                       f"expected {(n_rows,) if c == 1 else (n_rows, c)}")
            rec[n] = v
        layouts[name] = rec
    for key, value in (info or {}).items():
        if isinstance(value, str):
            b = value.encode("utf-8")
            out += _keyed("I", f"char[{len(b)}] {key}", b)
        elif isinstance(value, (int, np.integer)):
            out += _keyed("I", f"uint32_t {key}", struct.pack("<I", int(value)))
        else:
            raise CalibrationError(f"ULog information {key}: a text or a whole number")
    for key, value in (params or {}).items():
        if isinstance(value, (int, np.integer)) and not isinstance(value, bool):
            out += _keyed("P", f"int32_t {key}", struct.pack("<i", int(value)))
        else:
            out += _keyed("P", f"float {key}", struct.pack("<f", float(value)))
    rows = []
    for msg_id, (name, rec) in enumerate(layouts.items()):
        out += _message("A", struct.pack("<BH", 0, msg_id) + name.encode("ascii"))
        head = struct.pack("<HBH", rec.dtype.itemsize + 2, ord("D"), msg_id)
        rows += [(int(ts), head + r.tobytes()) for ts, r in zip(rec["timestamp"], rec)]
    rows.sort(key=lambda x: x[0])  # in time order, as the logger writes them
    out += b"".join(r for _, r in rows)
    return bytes(out)
