"""The firmware's still-pose mode (mode byte ``S``): the board finds the poses, the host decodes.

In this mode the board runs the sphere-centre note's window detector itself
(``firmware/src/still.h``) and
sends, in the framed protocol's envelope, ``COBS(seq, type, fields, CRC-16/CCITT-FALSE LE)``
then ``0x00`` (``seq`` shared by every frame, +1 per frame), three kinds of frame, told apart by
the ``type`` byte (all integers little-endian):

``P`` pose (one per registered pose)
    ``index`` u16 (0 for the first pose since the mode started), ``n`` u16 (samples averaged),
    K x int32: the sum of each channel over those samples (``ax ay az gx gy gz temp`` counts
    for the AVR firmware). The mean is ``sum / n``, exact; nothing is rounded on the board.
``W`` window status (after a window, at most every 100 ms, and after each pose)
    ``flags`` u8 (1 moved, 2 hold-off, 4 waiting for a move, 8 gyro bias known), ``run`` u8
    (steady windows averaged so far), ``poses`` u16 (registered so far), the window's
    accelerometer mean, 3 x int16 counts, and its gyro mean minus the bias, 3 x int16 counts.
``C`` settings (on entering the mode and in answer to a settings packet)
    ``accepted`` u8 (0: the packet's values were out of range; these are the ones in use),
    ``version`` u8 (1), then the 10 bytes of :class:`BoardPoseSettings`.

Every one of these frames has an odd number of bytes between ``seq`` and the CRC, so none can
pass for a frame of K int16 counts (an even number): a decoder of either kind drops the other
kind's frames. The host changes the settings with a 14-byte packet (:meth:`BoardPoseSettings.
packet`): ``s``, ``1``, the 10 settings bytes, CRC-16/CCITT-FALSE LE of the first 12.

:class:`BoardPoseDecoder` is pure (bytes in, records out), never raises on any bytes and keeps a
bounded buffer, like the other decoders of :mod:`triaxcal.io.protocol`; each record is the
pose's K channel means (float, counts) followed by ``n``.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, fields
from typing import Any

from ..errors import CalibrationError
from .protocol import FramedDecoder, cobs_decode, cobs_encode, crc16_ccitt

__all__ = [
    "MODE_BYTE",
    "BoardPoseDecoder",
    "BoardPoseSettings",
    "BoardStatus",
    "encode_pose_frame",
    "encode_settings_frame",
    "encode_status_frame",
]

#: The mode byte that starts (or restarts) the still-pose mode.
MODE_BYTE = b"S"

FRAME_POSE, FRAME_STATUS, FRAME_SETTINGS = 0x50, 0x57, 0x43  # 'P', 'W', 'C'
# the board's own fit and stored calibration after the last pose (triaxcal.io.board_store)
_CALIBRATION_FRAMES = (0x51, 0x4B)  # 'Q', 'K'
_SETTINGS = struct.Struct("<BBBHHHB")  # the 10 settings bytes
_STATUS = struct.Struct("<BBH3h3h")  # 16 bytes after the type byte
_SETTINGS_VERSION = 1
_PACKET_START = b"s1"

#: Status flags (:attr:`BoardStatus.flags`).
FLAG_MOVED, FLAG_HOLDOFF, FLAG_WAITING, FLAG_BIAS = 1, 2, 4, 8

# (field, lowest, highest, what) of the settings, as the firmware checks them (still_valid)
_RANGES = {
    "period_ms": (1, 250, "milliseconds between samples"),
    "window": (1, 250, "samples per window"),
    "hold_windows": (1, 250, "steady windows averaged into a pose"),
    "holdoff_ms": (0, 60000, "milliseconds of hold-off after a beep"),
    "accel_threshold": (1, 32767, "accelerometer counts"),
    "gyro_threshold": (0, 32767, "gyro counts (0: the gyro takes no part)"),
    "beep_ms": (0, 250, "milliseconds of beep (0: silent)"),
}


@dataclass(frozen=True)
class BoardPoseSettings:
    """Settings of the board's still-pose detector (the firmware's ``struct still_settings``).

    All integers, in the board's units. The defaults are the firmware's: the original method's 0.07
    g
    (1147 counts at 16384 counts/g) and 2 s hold-off, 100 samples per second.

    Attributes
    ----------
    period_ms : int
        Milliseconds between samples, 1..250 (10: 100 Hz).
    window : int
        Samples per averaging window, 1..250.
    hold_windows : int
        Steady windows averaged into a pose before it is registered (and the buzzer beeps),
        1..250; the first steady window after a move is not averaged.
    holdoff_ms : int
        No pose is averaged for this long after a beep, 0..60000 (the original method's 2000).
    accel_threshold : int
        Largest change of an accelerometer axis's window mean from the previous window's, in
        counts, 1..32767.
    gyro_threshold : int
        Largest distance of a gyro axis's window mean from its bias, in counts, 0..32767
        (0: the gyro takes no part; 393 = 3 deg/s at 131 counts per deg/s).
    beep_ms : int
        Length of the beep on PB0, 0..250 ms (0: silent).

    Examples
    --------
    >>> s = BoardPoseSettings(holdoff_ms=500)
    >>> BoardPoseSettings.from_bytes(s.to_bytes()) == s
    True
    >>> s.packet()[:2], len(s.packet())
    (b's1', 14)
    """

    period_ms: int = 10
    window: int = 25
    hold_windows: int = 4
    holdoff_ms: int = 2000
    accel_threshold: int = 1147
    gyro_threshold: int = 393
    beep_ms: int = 100

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            lo, hi, what = _RANGES[f.name]
            if isinstance(v, bool) or not hasattr(v, "__index__"):
                raise CalibrationError(f"board pose setting {f.name} must be a whole number "
                                       f"({what}), got {v!r}")
            if not lo <= int(v) <= hi:
                raise CalibrationError(f"board pose setting {f.name} must be {lo}..{hi} "
                                       f"({what}), got {int(v)}")
            object.__setattr__(self, f.name, int(v))

    def to_bytes(self) -> bytes:
        """The 10 bytes of the wire form."""
        return _SETTINGS.pack(*(getattr(self, f.name) for f in fields(self)))

    @classmethod
    def from_bytes(cls, b: bytes) -> BoardPoseSettings:
        """Inverse of :meth:`to_bytes` (raises :class:`CalibrationError` on bad values)."""
        if len(b) != _SETTINGS.size:
            raise CalibrationError(f"board pose settings are {_SETTINGS.size} bytes, got {len(b)}")
        return cls(*_SETTINGS.unpack(bytes(b)))

    def packet(self) -> bytes:
        """The 14-byte settings packet the host sends (``s``, ``1``, settings, CRC LE)."""
        body = _PACKET_START + self.to_bytes()
        return body + struct.pack("<H", crc16_ccitt(body))

    @property
    def holdoff_samples(self) -> int:
        """The hold-off as the board counts it: ``holdoff_ms // period_ms`` samples."""
        return self.holdoff_ms // self.period_ms

    def to_dict(self) -> dict[str, int]:
        """Plain JSON values."""
        return {f.name: getattr(self, f.name) for f in fields(self)}


@dataclass(frozen=True)
class BoardStatus:
    """The board's last window status (a ``W`` frame).

    ``accel`` is the window's accelerometer mean and ``rate`` its gyro mean minus the gyro
    bias, both in counts; ``poses`` the poses registered since the mode started; ``run`` the
    steady windows averaged into the pose in progress.
    """

    flags: int
    run: int
    poses: int
    accel: tuple[int, int, int]
    rate: tuple[int, int, int]

    @property
    def moved(self) -> bool:
        return bool(self.flags & FLAG_MOVED)

    @property
    def holdoff(self) -> bool:
        return bool(self.flags & FLAG_HOLDOFF)

    @property
    def waiting(self) -> bool:
        """A pose was registered and the board has not moved since."""
        return bool(self.flags & FLAG_WAITING)

    @property
    def bias_known(self) -> bool:
        return bool(self.flags & FLAG_BIAS)


def _frame(payload: bytes, seq: int) -> bytes:
    body = bytes([int(seq) & 0xFF]) + payload
    return cobs_encode(body + struct.pack("<H", crc16_ccitt(body))) + b"\x00"


def _whole(v: Any, name: str, lo: int, hi: int) -> int:
    if isinstance(v, bool) or not hasattr(v, "__index__") or not lo <= int(v) <= hi:
        raise CalibrationError(f"{name} must be a whole number {lo}..{hi}, got {v!r}")
    return int(v)


def encode_pose_frame(sums: Any, n: int, *, index: int, seq: int) -> bytes:
    """One ``P`` frame: the sums of K channels over ``n`` samples (as the board sends them).

    Examples
    --------
    >>> d = BoardPoseDecoder(2)
    >>> d.feed(encode_pose_frame([100, -50], 4, index=0, seq=0))
    [(25.0, -12.5, 4)]
    """
    n = _whole(n, "n (samples averaged)", 1, 65535)
    vals = [_whole(s, "sums", -(2**31), 2**31 - 1) for s in sums]
    if not vals:
        raise CalibrationError("sums is empty: a pose has at least one channel")
    payload = struct.pack(f"<BHH{len(vals)}i", FRAME_POSE,
                          _whole(index, "index", 0, 65535), n, *vals)
    return _frame(payload, seq)


def encode_status_frame(status: BoardStatus, *, seq: int) -> bytes:
    """One ``W`` frame."""
    payload = bytes([FRAME_STATUS]) + _STATUS.pack(
        status.flags, status.run, status.poses, *status.accel, *status.rate)
    return _frame(payload, seq)


def encode_settings_frame(settings: BoardPoseSettings, *, accepted: bool = True,
                          seq: int) -> bytes:
    """One ``C`` frame (the board's answer to a settings packet)."""
    payload = bytes([FRAME_SETTINGS, 1 if accepted else 0, _SETTINGS_VERSION])
    return _frame(payload + settings.to_bytes(), seq)


def _encoded_len(payload_len: int) -> int:
    raw = 1 + payload_len + 2
    return raw + 1 + (raw - 1) // 254


class BoardPoseDecoder(FramedDecoder):
    """Decode the still-pose mode's frames: one record per pose, ``(*means, n)``.

    Parameters
    ----------
    channels : int, optional
        K, the channels of a pose (7 for the AVR firmware). ``None``: taken from the first
        good pose frame.

    Attributes
    ----------
    status : BoardStatus or None
        The last window status the board sent.
    settings : BoardPoseSettings or None
        The settings the board said it uses (its last ``C`` frame); ``settings_accepted`` is
        False when that frame refused a settings packet.
    heartbeats : int
        Status and settings frames received: the board is alive though no pose came.
    poses_lost : int
        Poses missing according to their index (a damaged frame is dropped whole).
    restarts : int
        Times the index went back (the mode was started again).

    Notes
    -----
    Frames are split on 0x00, COBS-decoded and checked for type, length and CRC (the framed
    protocol's checks: :class:`~triaxcal.io.protocol.FramedDecoder`); a pose frame whose sums
    could not come from ``n`` int16 samples (``|sum| > 32768 n``) or with ``n = 0`` is dropped
    and counted like a damaged one. Frames of K int16 counts (the ``F`` stream) are dropped.

    Examples
    --------
    >>> d = BoardPoseDecoder(3)
    >>> data = encode_settings_frame(BoardPoseSettings(), seq=0)
    >>> data += encode_pose_frame([160, 0, 1640], 10, index=0, seq=1)
    >>> d.feed(data), d.settings.window, d.heartbeats
    ([(16.0, 0.0, 164.0, 10)], 25, 1)
    """

    def __init__(self, channels: int | None = None) -> None:
        super().__init__(channels)
        self.status: BoardStatus | None = None
        self.settings: BoardPoseSettings | None = None
        self.settings_accepted: bool | None = None
        self.heartbeats = 0
        self.poses_lost = 0
        self.restarts = 0
        self.last_index: int | None = None

    def _sizes(self) -> list[int]:
        sizes = [_encoded_len(1 + _STATUS.size), _encoded_len(3 + _SETTINGS.size)]
        if self.channels is not None:
            sizes.append(_encoded_len(5 + 4 * self.channels))
        return sorted(set(sizes), reverse=True)

    def _decode(self, frame: bytes) -> tuple[Any, ...] | None:
        ok, rec = self._parse(frame)
        if not ok:
            # garbage with no 0x00 in it glued itself in front of a good frame: every frame
            # kind has a fixed length, so try the tails
            for size in self._sizes():
                if len(frame) > size:
                    ok, rec = self._parse(frame[-size:])
                    if ok:
                        self.stats.dropped_bytes += len(frame) - size
                        break
        if not ok:
            self.stats.dropped_bytes += len(frame) + 1
            self.stats.dropped_frames += 1
        return rec  # a pose record, or None for a status or settings frame

    def _parse(self, frame: bytes) -> tuple[bool, tuple[Any, ...] | None]:
        """(good frame, its pose record or None for a status or settings frame)."""
        bad: tuple[bool, None] = (False, None)
        try:
            payload = cobs_decode(frame)
        except CalibrationError:
            return bad
        if len(payload) < 4 or (len(payload) - 3) % 2 == 0:
            return bad  # too short, or a frame of int16 counts
        crc = payload[-2] | (payload[-1] << 8)
        if crc16_ccitt(payload[:-2]) != crc:
            return bad
        seq, kind, body = payload[0], payload[1], payload[2:-2]
        rec: tuple[Any, ...] | None = None
        if kind == FRAME_POSE:
            if len(body) < 8 or (len(body) - 4) % 4:
                return bad
            k = (len(body) - 4) // 4
            if self.channels is not None and k != self.channels:
                return bad
            index, n = struct.unpack_from("<HH", body)
            sums = struct.unpack_from(f"<{k}i", body, 4)
            if n == 0 or any(abs(s) > 32768 * n for s in sums):
                return bad  # not sums of n int16 samples
            if self.channels is None:
                self.channels = k
            if self.last_index is not None:
                if index > self.last_index:
                    self.poses_lost += index - self.last_index - 1
                else:
                    self.restarts += 1
            elif index > 0:
                self.poses_lost += index
            self.last_index = index
            self.stats.frames += 1
            rec = (*(s / n for s in sums), n)
        elif kind == FRAME_STATUS:
            if len(body) != _STATUS.size:
                return bad
            v = _STATUS.unpack(body)
            self.status = BoardStatus(flags=v[0], run=v[1], poses=v[2],
                                      accel=(v[3], v[4], v[5]), rate=(v[6], v[7], v[8]))
            self.heartbeats += 1
        elif kind == FRAME_SETTINGS:
            if len(body) != 2 + _SETTINGS.size or body[1] != _SETTINGS_VERSION:
                return bad
            try:
                self.settings = BoardPoseSettings.from_bytes(body[2:])
            except CalibrationError:
                return bad
            self.settings_accepted = bool(body[0])
            self.heartbeats += 1
        elif kind in _CALIBRATION_FRAMES:
            self.heartbeats += 1  # intact, for board_store's decoder: no pose, not dropped
        else:
            return bad
        if self.stats.last_seq is not None:
            self.stats.lost_frames += (seq - self.stats.last_seq - 1) % 256
        self.stats.last_seq = seq
        return True, rec

    def reset(self) -> None:
        """Discard a partial frame (counters kept; the next pose index starts a new run)."""
        super().reset()
        self.last_index = None
