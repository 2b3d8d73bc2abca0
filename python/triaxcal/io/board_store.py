"""The calibration a board keeps itself: its stored record, and the frames that report it.

The firmware (``firmware/src/board_cal.h``, the C library's ``tc_store.h``) fits the
accelerometer on the board at the end of the still-pose mode and stores the result in
non-volatile memory as a 72-byte record (integers and IEEE-754 float32 little-endian):

====  ============  ===============================================================
byte  field         meaning
====  ============  ===============================================================
0     ``TC``        magic
2     version u8    1
3     sensor u8     1: accelerometer
4     model u8      6: offset + 3 gains ("axis"), 9: offset + symmetric matrix ("full"),
                    0: other (written by the host)
5     origin u8     1: fitted on the board, 2: written by the host
6     n u16         poses fitted (0: unknown)
8     warnings u16  the fit's warnings (:data:`WARNINGS`)
10    radius f32    magnitude of calibrated readings, in calibrated units
14    offset 3 f32  raw counts
26    matrix 9 f32  row-major; ``calibrated = matrix @ (raw - offset)``: the matrix
                    **multiplies**, calibrated units per raw count
62    rms f32       RMS of ``|calibrated| - radius`` over the poses, calibrated units
66    spread f32    smallest eigenvalue of ``mean(d d^T)`` of the calibrated directions
                    (1/3 when even, below 0.1 a band)
70    crc u16       CRC-16/CCITT-FALSE of bytes 0..69 (:func:`binascii.crc_hqx`, init
                    0xFFFF)
====  ============  ===============================================================

The board's calibrated unit is counts at the sensor's nominal scale: an MPU-6050 at +-2 g
has radius 16384, so ``calibrated / 16384`` is in g.

Frames (the framed protocol's envelope ``COBS(seq, type, fields, CRC-16 LE) + 0x00``, an odd
number of bytes between ``seq`` and the CRC like every frame of the still-pose mode):

``K`` (0x4B) the stored record
    ``status`` u8 (:data:`STATUS`), ``flags`` u8 (bit 0: the streams are calibrated; bits 4-5
    why it was sent, :data:`REASONS`), the 72 record bytes.
``Q`` (0x51) the board's fit
    ``version`` u8 (1), ``code`` i8 (the C library's refusal, :data:`FIT_CODES`; 0 fitted and
    stored), ``descent_code`` i8, ``warnings`` u16, ``n`` u16 poses, ``iterations`` u8,
    ``descent_iterations`` u16, the descent's centre 3 x f32, ``rms`` f32, ``spread`` f32,
    ``faces`` 6 x u8, ``stack_free`` u16 (bytes of RAM the stack never reached).

Commands: ``K`` report, ``c`` fit now, ``A`` / ``a`` calibrated / raw streams, and the write
packet :func:`write_packet` (``w``, ``1``, a record) that stores a host's calibration.

:class:`BoardStoreDecoder` is pure (bytes in, reports out), never raises on any bytes and
keeps a bounded buffer; :func:`decode_record` raises :class:`~triaxcal.CalibrationError`
saying what is wrong with a record (absent, damaged, newer, unusable).
"""

from __future__ import annotations

import binascii
import math
import struct
from dataclasses import dataclass
from typing import Any

from ..errors import CalibrationError
from .protocol import FramedDecoder, cobs_decode, cobs_encode

__all__ = [
    "COMMAND_APPLY",
    "COMMAND_FIT",
    "COMMAND_RAW",
    "COMMAND_REPORT",
    "FIT_CODES",
    "RECORD_BYTES",
    "REASONS",
    "STATUS",
    "WARNINGS",
    "BoardQuality",
    "BoardRecord",
    "BoardStoreDecoder",
    "RecordReport",
    "crc16",
    "decode_record",
    "encode_quality_frame",
    "encode_record_frame",
    "write_packet",
]

RECORD_BYTES = 72
RECORD_VERSION = 1
FRAME_RECORD, FRAME_QUALITY = 0x4B, 0x51  # 'K', 'Q'
COMMAND_REPORT, COMMAND_FIT, COMMAND_APPLY, COMMAND_RAW = b"K", b"c", b"A", b"a"
_WRITE_START = b"w1"
_HEAD = struct.Struct("<2sBBBBHH")  # magic .. warnings: 10 bytes
_BODY = struct.Struct("<f3f9fff")  # radius, offset, matrix, rms, spread: 60 bytes
_QUALITY = struct.Struct("<BbbHHBH3fff6BH")  # 38 bytes after the type byte

#: ``K`` frame status (the C library's ``enum tc_store_status``).
STATUS = {
    0: "a good record",
    1: "no record: the storage was never written (erased)",
    2: "a damaged record: its magic or CRC does not match",
    3: "a record of a newer version than this firmware reads",
    4: "a record whose values cannot be used (not finite, radius <= 0, or a singular matrix)",
}
#: Why a ``K`` frame was sent (its flags, bits 4-5).
REASONS = {0x00: "report", 0x10: "fitted", 0x20: "written", 0x30: "write refused"}
#: Warning bits of a fit (``TC_WARN_*``), as the host's fit words them.
WARNINGS = {
    0x01: "as many poses as unknowns: no residual is left to judge the fit by",
    0x02: "the fit did not converge",
    0x04: "the offset is poorly determined (standard error above 1 % of the radius)",
    0x08: "the fit is ill-conditioned (condition number above 1e8)",
    0x10: "the residuals are above 20 % of the radius",
    0x20: "part of the sphere is empty: a face of the cube holds under 1 % of the poses",
    0x40: "the poses cover only a band of the sphere (spread below 0.1)",
}
#: The C library's refusal codes (``enum tc_code``), and the firmware's storage failure.
FIT_CODES = {
    0: "fitted and stored",
    1: "an option is out of range",
    2: "a pose is not finite",
    3: "too few poses for the model",
    4: "all poses are identical",
    5: "the poses lie on a line",
    6: "the poses lie on a plane",
    7: "the poses do not determine the model",
    8: "the gains differ by more than a factor of 3 between axes",
    9: "no convergence",
    10: "the model is not built into this firmware",
    -1: "the storage did not keep the record",
}
_MODELS = {6: "axis", 9: "full", 0: None}


def crc16(data: bytes) -> int:
    """CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF), the firmware's ``crc16_ccitt``.

    Examples
    --------
    >>> hex(crc16(b"123456789"))
    '0x29b1'
    """
    return binascii.crc_hqx(bytes(data), 0xFFFF)


def _finite(*values: float) -> bool:
    return all(math.isfinite(v) for v in values)


def _f32(value: Any, name: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise CalibrationError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(v):
        raise CalibrationError(f"{name} must be finite, got {v}")
    try:
        return float(struct.unpack("<f", struct.pack("<f", v))[0])
    except OverflowError:
        raise CalibrationError(f"{name} = {v:g} does not fit a float32 (largest 3.4e38)") from None


@dataclass(frozen=True)
class BoardRecord:
    """A calibration as a board stores it (the module docstring has the layout).

    Values are rounded to float32 on construction, so that a record read back from the board
    compares equal to the one written.

    Attributes
    ----------
    offset : tuple of 3 float
        Raw counts.
    matrix : tuple of 3 tuples of 3 float
        ``calibrated = matrix @ (raw - offset)``; calibrated units per raw count.
    radius : float
        Magnitude of calibrated readings in calibrated units (16384: counts at +-2 g).
    model : str or None
        ``"axis"``, ``"full"`` or None.
    origin : str
        ``"board"`` (fitted there) or ``"host"`` (written by ``triaxcal board write``).
    n : int
        Poses fitted (0: unknown).
    warnings : int
        Warning bits (:data:`WARNINGS`).
    rms : float
        RMS of ``|calibrated| - radius``, calibrated units.
    spread : float
        Coverage: smallest eigenvalue of ``mean(d d^T)`` (1/3 even; 0 unknown).

    Examples
    --------
    >>> r = BoardRecord(offset=(180.0, -240.0, 350.0), matrix=((0.985, 0, 0), (0, 1.016, 0),
    ...                 (0, 0, 0.996)), radius=16384.0, model="axis", origin="board", n=60)
    >>> decode_record(r.to_bytes()) == r
    True
    >>> len(r.to_bytes())
    72
    """

    offset: tuple[float, float, float]
    matrix: tuple[tuple[float, float, float], ...]
    radius: float
    model: str | None = None
    origin: str = "host"
    n: int = 0
    warnings: int = 0
    rms: float = 0.0
    spread: float = 0.0

    def __post_init__(self) -> None:
        off = tuple(self.offset)
        rows = tuple(tuple(r) for r in self.matrix)
        if len(off) != 3 or len(rows) != 3 or any(len(r) != 3 for r in rows):
            raise CalibrationError("a board record holds an offset of 3 and a 3 x 3 matrix")
        object.__setattr__(self, "offset", tuple(_f32(v, "offset") for v in off))
        object.__setattr__(self, "matrix", tuple(tuple(_f32(v, "matrix") for v in r)
                                                 for r in rows))
        for name in ("radius", "rms", "spread"):
            object.__setattr__(self, name, _f32(getattr(self, name), name))
        if not self.radius > 0:
            raise CalibrationError(f"radius must be > 0 (calibrated units), got {self.radius}")
        m = self.matrix
        det = (m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
               - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
               + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]))
        if not (math.isfinite(det) and det != 0):
            raise CalibrationError("the matrix is singular: it is not a calibration")
        if self.model not in ("axis", "full", None):
            raise CalibrationError(f"model must be 'axis', 'full' or None, got {self.model!r}")
        if self.origin not in ("board", "host"):
            raise CalibrationError(f"origin must be 'board' or 'host', got {self.origin!r}")
        for name, hi in (("n", 65535), ("warnings", 65535)):
            v = getattr(self, name)
            if isinstance(v, bool) or not hasattr(v, "__index__") or not 0 <= int(v) <= hi:
                raise CalibrationError(f"{name} must be a whole number 0..{hi}, got {v!r}")
            object.__setattr__(self, name, int(v))

    def to_bytes(self) -> bytes:
        """The 72 bytes, with magic, version and CRC."""
        model = {v: k for k, v in _MODELS.items()}[self.model]
        head = _HEAD.pack(b"TC", RECORD_VERSION, 1, model,
                          1 if self.origin == "board" else 2, self.n, self.warnings)
        body = _BODY.pack(self.radius, *self.offset, *(v for r in self.matrix for v in r),
                          self.rms, self.spread)
        data = head + body
        return data + struct.pack("<H", crc16(data))

    @property
    def warning_texts(self) -> list[str]:
        """The warnings in words."""
        return [text for bit, text in WARNINGS.items() if self.warnings & bit]


def decode_record(data: bytes) -> BoardRecord:
    """Check and read a stored record.

    Raises
    ------
    CalibrationError
        Saying which: no record (erased storage), a damaged one (magic or CRC), a newer
        version, a record that is not 72 bytes, or values that cannot be used.
    """
    b = bytes(data)
    if len(b) != RECORD_BYTES:
        raise CalibrationError(f"a board record is {RECORD_BYTES} bytes, got {len(b)}")
    if b in (b"\xff" * RECORD_BYTES, b"\x00" * RECORD_BYTES):
        raise CalibrationError(
            "the board holds no calibration (its storage was never written): calibrate on the "
            "board (capture --board-poses, mode S, fits after the 84th pose) or store one "
            "with `triaxcal board write CAL.json --port PORT`")
    magic, version, sensor, model, origin, n, warnings = _HEAD.unpack_from(b)
    if magic != b"TC" or crc16(b[:-2]) != struct.unpack_from("<H", b, 70)[0]:
        raise CalibrationError(
            "the board's stored calibration is damaged (its CRC does not match): do not use "
            "it; calibrate again, or store a host calibration with `triaxcal board write`")
    if version != RECORD_VERSION:
        raise CalibrationError(
            f"the board's stored calibration has version {version}; this triaxcal reads "
            f"version {RECORD_VERSION}: upgrade triaxcal")
    if sensor != 1:
        raise CalibrationError(f"the board's record is for sensor {sensor}; only the "
                               "accelerometer (1) is known")
    v = _BODY.unpack_from(b, _HEAD.size)
    radius, offset, flat, rms, spread = v[0], v[1:4], v[4:13], v[13], v[14]
    if not _finite(radius, rms, spread, *offset, *flat):
        raise CalibrationError("the board's stored calibration holds values that are not "
                               "finite: calibrate again")
    try:
        return BoardRecord(offset=offset, matrix=(flat[0:3], flat[3:6], flat[6:9]),
                           radius=radius, model=_MODELS.get(model), origin="board"
                           if origin == 1 else "host", n=n, warnings=warnings, rms=rms,
                           spread=spread)
    except CalibrationError as exc:
        raise CalibrationError(f"the board's stored calibration cannot be used: {exc}") from None


def write_packet(record: BoardRecord) -> bytes:
    """The 74-byte packet that stores ``record`` on the board (``w``, ``1``, the record; the
    record's own CRC protects it).

    Examples
    --------
    >>> r = BoardRecord(offset=(0, 0, 0), matrix=((1, 0, 0), (0, 1, 0), (0, 0, 1)),
    ...                 radius=16384)
    >>> p = write_packet(r)
    >>> p[:2], len(p)
    (b'w1', 74)
    """
    return _WRITE_START + record.to_bytes()


@dataclass(frozen=True)
class RecordReport:
    """A ``K`` frame: what the board's storage holds.

    ``status`` is :data:`STATUS`'s key (0: good), ``reason`` why the frame came
    (:data:`REASONS`), ``applied`` whether the streams are calibrated, ``raw`` the 72 bytes.
    """

    status: int
    reason: str
    applied: bool
    raw: bytes

    def record(self) -> BoardRecord:
        """The record, checked on the host too; :class:`CalibrationError` when there is none
        or it is damaged (saying which)."""
        if self.reason == "write refused":
            raise CalibrationError("the board refused the record: "
                                   + STATUS.get(self.status, f"status {self.status}"))
        if self.status != 0:
            # the host checks the bytes itself: its message says what is wrong
            decode_record(self.raw)
            raise CalibrationError("the board reports "
                                   + STATUS.get(self.status, f"status {self.status}"))
        return decode_record(self.raw)


@dataclass(frozen=True)
class BoardQuality:
    """A ``Q`` frame: what the board's fit gave.

    ``code`` is the C library's (:data:`FIT_CODES`; 0: fitted and stored), ``center`` the
    sphere-centre search (raw counts), ``rms`` in calibrated counts, ``faces`` the poses
    nearest +X -X +Y -Y +Z -Z, ``stack_free`` the bytes of RAM its stack never reached.
    """

    code: int
    descent_code: int
    warnings: int
    n: int
    iterations: int
    descent_iterations: int
    center: tuple[float, float, float]
    rms: float
    spread: float
    faces: tuple[int, ...]
    stack_free: int

    @property
    def why(self) -> str:
        """The fit's code in words."""
        return FIT_CODES.get(self.code, f"code {self.code}")


def _frame(payload: bytes, seq: int) -> bytes:
    body = bytes([int(seq) & 0xFF]) + payload
    return cobs_encode(body + struct.pack("<H", crc16(body))) + b"\x00"


def encode_record_frame(raw: bytes, *, status: int = 0, flags: int = 0, seq: int = 0) -> bytes:
    """A ``K`` frame as the board sends it (for tests and simulators).

    Examples
    --------
    >>> r = BoardRecord(offset=(1, 2, 3), matrix=((1, 0, 0), (0, 1, 0), (0, 0, 1)),
    ...                 radius=16384)
    >>> rep, = BoardStoreDecoder().feed(encode_record_frame(r.to_bytes(), flags=0x11))
    >>> rep.reason, rep.applied, rep.record().offset
    ('fitted', True, (1.0, 2.0, 3.0))
    """
    raw = bytes(raw)
    if len(raw) != RECORD_BYTES:
        raise CalibrationError(f"a record is {RECORD_BYTES} bytes, got {len(raw)}")
    return _frame(bytes([FRAME_RECORD, status & 0xFF, flags & 0xFF]) + raw, seq)


def encode_quality_frame(q: BoardQuality, *, seq: int = 0) -> bytes:
    """A ``Q`` frame as the board sends it (for tests and simulators)."""
    payload = bytes([FRAME_QUALITY]) + _QUALITY.pack(
        1, q.code, q.descent_code, q.warnings, q.n, q.iterations, q.descent_iterations,
        *q.center, q.rms, q.spread, *q.faces, q.stack_free)
    return _frame(payload, seq)


class BoardStoreDecoder(FramedDecoder):
    """Decode ``K`` and ``Q`` frames among whatever else the board sends.

    :meth:`feed` returns :class:`RecordReport` and :class:`BoardQuality` objects. Frames of
    the other kinds (samples of the ``F`` stream, poses, status and settings of the still-pose
    mode) are passed over and counted in ``other_frames``; anything that fails COBS, length or
    CRC is dropped and counted in ``stats.dropped_frames``, as in
    :class:`~triaxcal.io.protocol.FramedDecoder`.

    Examples
    --------
    >>> d = BoardStoreDecoder()
    >>> d.feed(b"garbage\\x00" + encode_record_frame(b"\\xff" * 72, status=1))[0].status
    1
    >>> d.stats.dropped_frames
    1
    """

    def __init__(self) -> None:
        super().__init__(None)
        self.other_frames = 0

    def _decode(self, frame: bytes) -> Any:  # type: ignore[override]
        try:
            p = cobs_decode(frame)
        except CalibrationError:
            p = b""
        if len(p) < 4 or crc16(p[:-2]) != struct.unpack_from("<H", p, len(p) - 2)[0]:
            self.stats.dropped_bytes += len(frame) + 1
            self.stats.dropped_frames += 1
            return None
        seq, kind, body = p[0], p[1], p[2:-2]
        rec: Any = None
        if kind == FRAME_RECORD and len(body) == 2 + RECORD_BYTES:
            rec = RecordReport(status=body[0], reason=REASONS.get(body[1] & 0x30, "report"),
                               applied=bool(body[1] & 1), raw=bytes(body[2:]))
        elif kind == FRAME_QUALITY and len(body) == _QUALITY.size and body[0] == 1:
            v = _QUALITY.unpack(body)
            rec = BoardQuality(code=v[1], descent_code=v[2], warnings=v[3], n=v[4],
                               iterations=v[5], descent_iterations=v[6], center=v[7:10],
                               rms=v[10], spread=v[11], faces=v[12:18], stack_free=v[18])
        else:
            self.other_frames += 1
            return None
        if self.stats.last_seq is not None:
            self.stats.lost_frames += (seq - self.stats.last_seq - 1) % 256
        self.stats.last_seq = seq
        self.stats.frames += 1
        return rec
