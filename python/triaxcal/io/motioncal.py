"""The PJRC MotionCal calibration packet on the wire, and the board's echo of it.

68 bytes: ``117, 84``, 16 float32 LE (accel offsets[3] m/s^2, gyro offsets[3] rad/s, mag hard
iron[3] uT, field uT, soft iron ``xx, yy, zz, xy, xz, yz``), CRC-16/MODBUS LE of the first 66
bytes. A board that accepts it answers ``Cal1:a0,a1,a2,g0,g1,g2,m0,m1,m2,field`` and
``Cal2:`` with the 3x3 soft-iron matrix row-major, 4 decimals, as the PJRC/Adafruit
calibration sketches do.
"""

from __future__ import annotations

import math
import re
import struct
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._checks import options
from .._checks.arrays import as_matrix3
from ..errors import CalibrationError
from .protocol import crc16_modbus

__all__ = [
    "MOTIONCAL_HEADER",
    "MOTIONCAL_SIZE",
    "MotionCalPacket",
    "decode_motioncal",
    "echo_matches",
    "encode_motioncal",
    "format_cal_lines",
    "parse_motioncal_echo",
]

MOTIONCAL_HEADER = bytes((117, 84))
MOTIONCAL_SIZE = 68

@dataclass(frozen=True)
class MotionCalPacket:
    """The values of a MotionCal calibration packet (float32 precision).

    ``accel_offset`` (m/s^2), ``gyro_offset`` (rad/s), ``mag_offset`` (hard iron, uT), ``field``
    (uT) and ``soft_iron`` (3x3 symmetric, dimensionless; it multiplies ``mag - mag_offset``),
    as Adafruit_Sensor_Calibration applies them.
    """

    accel_offset: tuple[float, float, float]
    gyro_offset: tuple[float, float, float]
    mag_offset: tuple[float, float, float]
    field: float
    soft_iron: tuple[tuple[float, float, float], ...]

    def values(self) -> list[float]:
        """The 16 packet floats in wire order (soft iron as xx, yy, zz, xy, xz, yz)."""
        s = self.soft_iron
        return [
            *self.accel_offset,
            *self.gyro_offset,
            *self.mag_offset,
            self.field,
            s[0][0], s[1][1], s[2][2], s[0][1], s[0][2], s[1][2],
        ]


def encode_motioncal(
    *,
    accel_offset: Any = (0.0, 0.0, 0.0),
    gyro_offset: Any = (0.0, 0.0, 0.0),
    mag_offset: Any = (0.0, 0.0, 0.0),
    field: float = 50.0,
    soft_iron: Any = None,
) -> bytes:
    """The 68-byte packet from values already in MotionCal's units (see MotionCalPacket)."""
    si = np.eye(3) if soft_iron is None else as_matrix3(soft_iron, "soft_iron")
    if not np.allclose(si, si.T, rtol=1e-6, atol=1e-9):
        raise CalibrationError(
            "the MotionCal packet holds a symmetric soft-iron matrix (6 terms); this one is not "
            "symmetric: fit with model='full' or use the C header instead"
        )
    vals = [
        *options.vector3(accel_offset, "accel_offset"),
        *options.vector3(gyro_offset, "gyro_offset"),
        *options.vector3(mag_offset, "mag_offset"),
        options.number(field, "field", hint="uT"),
        si[0, 0], si[1, 1], si[2, 2], si[0, 1], si[0, 2], si[1, 2],
    ]
    if len(vals) != 16:
        raise CalibrationError("offsets must have 3 values each")
    if not all(math.isfinite(v) and abs(v) < 3.4e38 for v in vals):
        raise CalibrationError(f"packet values must be finite float32 numbers, got {vals}")
    body = MOTIONCAL_HEADER + struct.pack("<16f", *vals)
    return body + struct.pack("<H", crc16_modbus(body))


def decode_motioncal(data: bytes) -> MotionCalPacket:
    """Parse and check a 68-byte MotionCal packet (header bytes 117, 84 and the CRC)."""
    if not isinstance(data, (bytes, bytearray, memoryview)):
        raise CalibrationError(f"data must be the packet's bytes, got {type(data).__name__}")
    data = bytes(data)
    if len(data) != MOTIONCAL_SIZE:
        raise CalibrationError(f"a MotionCal packet has {MOTIONCAL_SIZE} bytes, got {len(data)}")
    if data[:2] != MOTIONCAL_HEADER:
        raise CalibrationError(
            f"not a MotionCal packet: starts with {data[:2].hex()}, expected 7554 (117, 84)"
        )
    want = struct.unpack("<H", data[66:68])[0]
    got = crc16_modbus(data[:66])
    if want != got:
        raise CalibrationError(
            f"MotionCal packet CRC mismatch: stored 0x{want:04X}, computed 0x{got:04X} "
            "(corrupted in transit?)"
        )
    v = struct.unpack("<16f", data[2:66])
    xx, yy, zz, xy, xz, yz = v[10:16]
    return MotionCalPacket(
        accel_offset=(v[0], v[1], v[2]),
        gyro_offset=(v[3], v[4], v[5]),
        mag_offset=(v[6], v[7], v[8]),
        field=v[9],
        soft_iron=((xx, xy, xz), (xy, yy, yz), (xz, yz, zz)),
    )


def format_cal_lines(p: MotionCalPacket) -> bytes:
    """The ``Cal1:``/``Cal2:`` echo of a packet, 4 decimals, ``\\r\\n`` line ends.

    >>> pkt = decode_motioncal(encode_motioncal(field=48.0))
    >>> format_cal_lines(pkt).split(b"\\r\\n")[0]
    b'Cal1:0.0000,0.0000,0.0000,0.0000,0.0000,0.0000,0.0000,0.0000,0.0000,48.0000'
    """
    one = [*p.accel_offset, *p.gyro_offset, *p.mag_offset, p.field]
    two = [v for row in p.soft_iron for v in row]
    text = "Cal1:" + ",".join(f"{v:.4f}" for v in one) + "\r\n"
    text += "Cal2:" + ",".join(f"{v:.4f}" for v in two) + "\r\n"
    return text.encode("ascii")


_ECHO = re.compile(rb"(Cal[12]):([-+0-9.eE, \tnaif]*)\r?\n")


def parse_motioncal_echo(data: bytes) -> tuple[list[float], list[float]] | None:
    """Find the ``Cal1:`` (10 values) and ``Cal2:`` (9 values) lines a board echoes.

    Other bytes around them (binary frames of a streaming board) are ignored. Returns ``None``
    until both lines are complete.
    """
    found: dict[bytes, list[float]] = {}
    for m in _ECHO.finditer(bytes(data)):
        try:
            vals = [float(x) for x in m.group(2).replace(b" ", b"").split(b",") if x.strip()]
        except ValueError:
            continue
        want = 10 if m.group(1) == b"Cal1" else 9
        if len(vals) == want:
            found[m.group(1)] = vals
    if b"Cal1" in found and b"Cal2" in found:
        return found[b"Cal1"], found[b"Cal2"]
    return None


def echo_matches(packet: bytes, cal1: list[float], cal2: list[float]) -> list[str]:
    """Differences between a packet and the board's echo (4-decimal text); empty if equal."""
    p = decode_motioncal(packet)
    want1 = [*p.accel_offset, *p.gyro_offset, *p.mag_offset, p.field]
    want2 = [v for row in p.soft_iron for v in row]
    bad = []
    for name, want, got in (("Cal1", want1, cal1), ("Cal2", want2, cal2)):
        for i, (w, g) in enumerate(zip(want, got)):
            if abs(w - g) > 0.5e-4 + 1e-6 * abs(w) + 1e-9:
                bad.append(f"{name}[{i}]: sent {w:.6g}, board has {g:.6g}")
    return bad

