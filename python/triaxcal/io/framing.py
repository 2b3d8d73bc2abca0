"""The bytes on the wire, both ways: CRC-16 checksums, COBS, and the frame encoders of the four
protocols (:mod:`triaxcal.io.protocol` describes them; its decoders read what these write).
Pure code: bytes in, bytes out.
"""

from __future__ import annotations

import math
import re
import struct
from collections.abc import Iterable, Sequence
from typing import Any, Union

from ..errors import CalibrationError

__all__ = [
    "cobs_decode",
    "cobs_encode",
    "crc16_ccitt",
    "crc16_modbus",
    "encode_binary",
    "encode_framed",
    "encode_raw",
    "encode_text",
]

_I16_MIN, _I16_MAX = -32768, 32767

Number = Union[int, float]


# --------------------------------------------------------------------------------- checksums

def _crc16_ccitt_table() -> list[int]:
    table = []
    for i in range(256):
        crc = i << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) if crc & 0x8000 else (crc << 1)
        table.append(crc & 0xFFFF)
    return table


def _crc16_modbus_table() -> list[int]:
    table = []
    for i in range(256):
        crc = i
        for _ in range(8):
            crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
        table.append(crc)
    return table


_CCITT = _crc16_ccitt_table()
_MODBUS = _crc16_modbus_table()


def crc16_ccitt(b: bytes) -> int:
    """CRC-16/CCITT-FALSE: poly 0x1021, init 0xFFFF, no reflection, no final xor.

    Parameters
    ----------
    b : bytes
        Data to check.

    Returns
    -------
    int
        The CRC, 0..65535 (the framed protocol sends it little-endian).

    Examples
    --------
    >>> hex(crc16_ccitt(b"123456789"))
    '0x29b1'
    """
    crc = 0xFFFF
    for byte in b:
        crc = ((crc << 8) & 0xFFFF) ^ _CCITT[((crc >> 8) ^ byte) & 0xFF]
    return crc


def crc16_modbus(b: bytes) -> int:
    """CRC-16/MODBUS: poly 0xA001 reflected, init 0xFFFF (the MotionCal packet's checksum).

    Examples
    --------
    >>> hex(crc16_modbus(b"123456789"))
    '0x4b37'
    """
    crc = 0xFFFF
    for byte in b:
        crc = (crc >> 8) ^ _MODBUS[(crc ^ byte) & 0xFF]
    return crc


# --------------------------------------------------------------------------------------- COBS

def cobs_encode(b: bytes) -> bytes:
    """Consistent Overhead Byte Stuffing: the result has no 0x00 byte (delimiter not added).

    Examples
    --------
    >>> cobs_encode(b"\\x11\\x00\\x22").hex()
    '02110222'
    """
    out = bytearray()
    block = bytearray()
    for byte in bytes(b):
        if byte == 0:
            out.append(len(block) + 1)
            out += block
            block.clear()
        else:
            block.append(byte)
            if len(block) == 254:
                out.append(255)
                out += block
                block.clear()
    out.append(len(block) + 1)
    out += block
    return bytes(out)


def cobs_decode(b: bytes) -> bytes:
    """Inverse of :func:`cobs_encode` (pass one frame without its 0x00 delimiter).

    Raises
    ------
    CalibrationError
        If ``b`` is not valid COBS (a 0x00 byte inside, or a code byte pointing past the end).

    Examples
    --------
    >>> cobs_decode(bytes.fromhex("02110222"))
    b'\\x11\\x00"'
    """
    data = bytes(b)
    out = bytearray()
    i, n = 0, len(data)
    if n == 0:
        raise CalibrationError("empty COBS frame: a frame has at least one code byte")
    while i < n:
        code = data[i]
        if code == 0:
            raise CalibrationError(f"0x00 inside a COBS frame at byte {i}: split frames on 0x00")
        end = i + code
        if end > n:
            raise CalibrationError(
                f"COBS code byte {code} at {i} points past the end of the {n}-byte frame "
                "(truncated or corrupted frame)"
            )
        block = data[i + 1 : end]
        if 0 in block:
            raise CalibrationError("0x00 inside a COBS frame: split frames on 0x00 first")
        out += block
        i = end
        if code < 255 and i < n:
            out.append(0)
    return bytes(out)


# ---------------------------------------------------------------------------------- encoders

def _int16s(values: Iterable[Any], name: str = "values") -> list[int]:
    vals = list(values)
    if not vals:
        raise CalibrationError(f"{name} is empty: a record needs at least one channel")
    out = []
    for v in vals:
        if isinstance(v, bool) or not isinstance(v, (int,)) and not hasattr(v, "__index__"):
            raise CalibrationError(
                f"{name} must be integers (int16 counts), got {v!r}; round readings first"
            )
        iv = int(v)
        if not _I16_MIN <= iv <= _I16_MAX:
            raise CalibrationError(
                f"{name} must fit int16 (-32768..32767 counts), got {iv}; clip or rescale first"
            )
        out.append(iv)
    return out


def encode_binary(values: Sequence[int]) -> bytes:
    """One legacy binary frame: K int16 little-endian, then ``\\n``.

    Examples
    --------
    >>> encode_binary([10, -246]).hex()
    '0a000aff0a'
    """
    vals = _int16s(values)
    return struct.pack(f"<{len(vals)}h", *vals) + b"\n"


def encode_framed(values: Sequence[int], seq: int) -> bytes:
    """One framed record: COBS(seq + K int16 LE + CRC-16/CCITT-FALSE LE) + 0x00.

    ``seq`` is taken modulo 256 (the counter wraps).

    Examples
    --------
    >>> encode_framed([1, -2], seq=7).hex()
    '03070105feff522e00'
    >>> from triaxcal.io.protocol import FramedDecoder
    >>> FramedDecoder(2).feed(encode_framed([1, -2], seq=7))
    [(1, -2)]
    """
    vals = _int16s(values)
    payload = bytes([int(seq) & 0xFF]) + struct.pack(f"<{len(vals)}h", *vals)
    return cobs_encode(payload + struct.pack("<H", crc16_ccitt(payload))) + b"\x00"


def _fmt_number(v: Any) -> str:
    if isinstance(v, bool):
        raise CalibrationError(f"values must be numbers, got {v!r}")
    if isinstance(v, int) or hasattr(v, "__index__"):
        return str(int(v))
    f = float(v)
    if not math.isfinite(f):
        raise CalibrationError(f"values must be finite, got {v!r}")
    return repr(f)


def encode_text(values: Sequence[Number], label: str | None = None) -> bytes:
    """One text line: numbers joined by commas, optional ``label: `` prefix, ``\\n``.

    Examples
    --------
    >>> encode_text([1, -2, 3.5], label="acc")
    b'acc: 1,-2,3.5\\n'
    """
    vals = list(values)
    if not vals:
        raise CalibrationError("values is empty: a line needs at least one number")
    body = ",".join(_fmt_number(v) for v in vals)
    if label is not None:
        if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", label):
            raise CalibrationError(
                f"label {label!r} must be a word (letters, digits, underscores; no ':' or spaces)"
            )
        body = f"{label}: {body}"
    return body.encode("ascii") + b"\n"


def encode_raw(values: Sequence[int]) -> bytes:
    """One MotionCal ``Raw:`` line of 9 int16 counts, ended by ``\\r\\n`` as Arduino's println.

    Examples
    --------
    >>> encode_raw([0, 0, 8192, 0, 0, 0, 200, 0, -400])
    b'Raw:0,0,8192,0,0,0,200,0,-400\\r\\n'
    """
    vals = _int16s(values)
    if len(vals) != 9:
        raise CalibrationError(
            f"a Raw: line has 9 values (ax ay az gx gy gz mx my mz), got {len(vals)}"
        )
    return ("Raw:" + ",".join(str(v) for v in vals)).encode("ascii") + b"\r\n"
