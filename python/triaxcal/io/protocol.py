"""Wire protocols between a sensor board and the host: pure code, bytes in, records out.

Nothing here touches a port or a clock. A reader (``triaxcal.io.serial``) or a simulator
feeds whatever bytes arrived to a decoder and gets back complete records; the decoder keeps
partial frames between calls, so feeding a stream in any chunk sizes gives the same records
as feeding it at once (see :meth:`BinaryDecoder.flush` for the end of a stream).

Four protocols (``PROTOCOLS``), all carrying K signed 16-bit counts per record:

``binary`` (legacy)
    K little-endian int16 (low byte first), then one ``\\n`` (0x0A) byte: ``2K + 1`` bytes.
    No checksum. Data bytes can equal 0x0A (the value 10 is ``0A 00``), so frames are cut by
    length and the terminators are checked, never found by scanning for ``\\n``.
``framed`` (recommended)
    payload = ``seq`` (uint8, +1 per frame, wraps) + K int16 LE; the CRC-16/CCITT-FALSE of the
    payload (LE) is appended, the whole is COBS-encoded and ended by one 0x00 byte. Corrupted
    frames are detected and dropped; sequence gaps count lost frames.
``text``
    K numbers separated by commas, spaces or tabs, an optional ``label:`` prefix, ``\\n`` or
    ``\\r\\n``.
``raw``
    PJRC MotionCal's ``Raw:ax,ay,az,gx,gy,gz,mx,my,mz`` lines, fixed scales ``RAW_SCALES``.

Malformed input is skipped and counted in the decoder's :class:`DecoderStats`; decoders never
raise on any bytes, and no decoder buffers more than a bounded number of bytes.

The MotionCal calibration packet a host sends to a board is :mod:`triaxcal.io.motioncal`; the
firmware's still-pose mode (``S``: one framed record per pose found on the board) is
:mod:`triaxcal.io.board_poses`. The checksums, COBS and the encoders that write each protocol
(what a board or the simulator sends) are :mod:`triaxcal.io.framing`, re-exported here.
"""

from __future__ import annotations

import math
import re
import struct
from collections import deque
from dataclasses import dataclass
from typing import Any, Union

from .._checks.options import MAGNITUDE
from ..errors import CalibrationError
from .framing import (
    _I16_MAX,
    _I16_MIN,
    Number,
    cobs_decode,
    cobs_encode,
    crc16_ccitt,
    crc16_modbus,
    encode_binary,
    encode_framed,
    encode_raw,
    encode_text,
)

__all__ = [
    "CHANNELS_7",
    "CHANNELS_10",
    "MAX_LINE_BYTES",
    "PROTOCOLS",
    "RAW_SCALES",
    "REQUEST_BYTE",
    "BinaryDecoder",
    "DecoderStats",
    "FramedDecoder",
    "RawDecoder",
    "TextDecoder",
    "cobs_decode",
    "cobs_encode",
    "crc16_ccitt",
    "crc16_modbus",
    "encode_binary",
    "encode_framed",
    "encode_raw",
    "encode_text",
    "make_decoder",
]

PROTOCOLS = ("binary", "framed", "text", "raw")

#: Channel names in device order: 10 channels (with magnetometer; the simulator) and 7 (the
#: AVR firmware's MPU-6050, no magnetometer). All int16 counts.
CHANNELS_10 = ("ax", "ay", "az", "gx", "gy", "gz", "mx", "my", "mz", "temp")
CHANNELS_7 = ("ax", "ay", "az", "gx", "gy", "gz", "temp")

#: Request byte of the polled legacy protocol (``!``); the firmware answers it in any mode.
REQUEST_BYTE = b"!"

#: Fixed scales of the ``Raw:`` format (PJRC MotionCal): counts per g, per deg/s, per uT.
#: Readings in physical units are ``counts / scale`` (the scale divides).
RAW_SCALES = {"accel": 8192.0, "gyro": 16.0, "mag": 10.0}

#: Longest text line kept; longer lines (or garbage with no newline) are skipped and counted.
MAX_LINE_BYTES = 1024

#: Most channels a frame may carry (bounds the bytes buffered by the binary decoders).
MAX_CHANNELS = 64

_TERM = 0x0A


@dataclass
class DecoderStats:
    """Counters kept by every decoder (cumulative; :meth:`reset` does not clear them).

    Attributes
    ----------
    bytes_in : int
        Bytes fed so far.
    frames : int
        Records returned (frames or lines).
    dropped_bytes : int
        Bytes thrown away: garbage, bytes skipped while resynchronising, bad frames' bytes.
    dropped_frames : int
        Frames rejected. Framed: bad COBS, length or CRC. Binary streaming: resynchronisation
        events (runs of dropped bytes). Binary polled: replies too short, too long or without
        the terminator.
    lines_skipped : int
        Text lines skipped (malformed, wrong field count, not numbers, too long; for ``raw``,
        every line that is not a ``Raw:`` line with 9 integers).
    lost_frames : int
        Frames missing according to the sequence numbers of the framed protocol (includes the
        frames dropped for bad CRC; 255 or more consecutive losses cannot be seen).
    last_seq : int or None
        Sequence number of the last good framed frame.
    """

    bytes_in: int = 0
    frames: int = 0
    dropped_bytes: int = 0
    dropped_frames: int = 0
    lines_skipped: int = 0
    lost_frames: int = 0
    last_seq: int | None = None


# ---------------------------------------------------------------------------------- decoders

def _check_channels(channels: Any, protocol: str, *, required: bool) -> int | None:
    if channels is None:
        if required:
            raise CalibrationError(
                f"the {protocol} protocol needs the channel count: pass channels=K "
                "(K int16 values per frame, e.g. 7 for the AVR firmware)"
            )
        return None
    if isinstance(channels, bool) or not hasattr(channels, "__index__"):
        raise CalibrationError(f"channels must be an integer, got {channels!r}")
    k = int(channels)
    if not 1 <= k <= MAX_CHANNELS:
        raise CalibrationError(f"channels must be 1..{MAX_CHANNELS}, got {k}")
    return k


class BinaryDecoder:
    """Decode the legacy binary protocol: K int16 LE + ``\\n`` per frame.

    Parameters
    ----------
    channels : int
        K, the int16 values per frame (the frame is ``2K + 1`` bytes).
    polled : bool
        ``True`` when the host asks for every frame with a request byte (``!``). Then call
        :meth:`reset` (and clear the port's input buffer) before each request and feed the
        reply: a reply of exactly ``2K + 1`` bytes ending in 0x0A gives one record; a reply that
        is too short (see :meth:`reset`), too long (extra bytes in the same :meth:`feed` call,
        or after the frame) or lacks the terminator is dropped and counted, never decoded.

    Notes
    -----
    Streaming mode (``polled=False``) cuts frames by length, never at a ``\n`` found by
    scanning. While in step, a frame is accepted when its own terminator and those of the
    next two frames are in place, so records come out two frames late; call :meth:`flush` at
    the end of a stream for the last ones. When a check fails the decoder hunts. A frame start
    needs a terminator just before it (a stream that begins with a whole frame is taken as it
    is) and the next three terminators in place. Several starts can qualify: a byte that is
    0x0A in every frame (a still axis reading 10 or 2560..2815 counts) makes a second, false
    phase. Among the starts within four frames the decoder takes the one whose record is
    closest to the last three good records plus the least rough run of frames from it (a
    false phase puts a noisy low byte into a high byte: noise x 256), then the one closest to
    the old phase; it refuses, for up to eight frames, a start far from everything recent.

    Costs and limits, measured by the property tests and a 120 000-case run of the same
    generators (sensor-like data, one corruption each): a dropped, inserted or flipped byte or a
    burst of garbage costs the damaged frames and at most three more (in every case); 7 cases in
    120 000 gave a wrong row. Without a checksum some damage cannot be seen at all: a flipped
    data byte gives a wrong row; losing exactly ``2K + 1`` bytes joins the remains of two frames
    into one perfect frame; if the last channel's high byte is 0x0A in every frame, a frame that
    lost its first byte reads as a perfect frame from the previous terminator on; with a false
    phase present, a run of lost or inserted bytes whose length moves the stream exactly onto it
    cannot be told from a clean stream whose values jumped, and gives wrong rows until that byte
    changes, as can damage within the first or last three frames of a stream. Use the framed
    protocol where that matters.

    Examples
    --------
    >>> d = BinaryDecoder(3)
    >>> d.feed(encode_binary([10, 2570, -246]) * 2) + d.flush()
    [(10, 2570, -246), (10, 2570, -246)]
    """

    _HUNT_FRAMES = 3  # terminators that must line up before a new phase is accepted

    def __init__(self, channels: int, *, polled: bool = False) -> None:
        k = _check_channels(channels, "binary", required=True)
        assert k is not None
        self.channels = k
        self.polled = bool(polled)
        self.frame_len = 2 * k + 1
        self._unpack = struct.Struct(f"<{k}h").unpack_from
        self.stats = DecoderStats()
        self._buf = bytearray()
        self._pos = 0  # stream offset of _buf[0]
        self._prev: int | None = None  # byte just before _buf[0]; None at stream start
        self._synced = False
        self._ref: int | None = None  # phase (offset mod L) where sync was lost
        self._hunt_dropped = False
        self._recent: deque[tuple[int, ...]] = deque(maxlen=3)  # last accepted records
        self._step: float | None = None  # typical change between consecutive records
        self._hunted = 0  # bytes dropped since the last accepted frame
        self._reply_over = False  # polled: the reply was decided; later bytes are extra

    @property
    def buffered(self) -> int:
        """Bytes held back waiting for the rest of a frame or line (bounded)."""
        return len(self._buf)

    def reset(self) -> None:
        """Discard partial state (counters are kept).

        Polled mode: call before each request. An unfinished reply (too short, e.g. after a
        timeout) counts as one dropped frame. Streaming mode: start as at a new stream.
        """
        if self._buf:
            self.stats.dropped_bytes += len(self._buf)
            if self.polled and not self._reply_over:
                self.stats.dropped_frames += 1
        self._buf.clear()
        self._pos = 0
        self._prev = None
        self._synced = False
        self._ref = None
        self._hunt_dropped = False
        self._recent.clear()
        self._step = None
        self._hunted = 0
        self._reply_over = False

    def feed(self, data: bytes) -> list[tuple[int, ...]]:
        """Add received bytes; return the records completed by them (possibly none)."""
        data = bytes(data)
        self.stats.bytes_in += len(data)
        if self.polled:
            return self._feed_polled(data)
        self._buf += data
        return self._process(final=False)

    def flush(self) -> list[tuple[int, ...]]:
        """End of stream: decide the frames still waiting for look-ahead bytes, drop the rest."""
        if self.polled:
            return []
        out = self._process(final=True)
        if self._buf:
            self.stats.dropped_bytes += len(self._buf)
            if not self._hunt_dropped:
                self.stats.dropped_frames += 1
            self._prev = self._buf[-1]
            self._pos += len(self._buf)
            self._buf.clear()
        return out

    # -- polled
    def _feed_polled(self, data: bytes) -> list[tuple[int, ...]]:
        L = self.frame_len
        if self._reply_over:
            self.stats.dropped_bytes += len(data)
            return []
        self._buf += data
        if len(self._buf) < L:
            return []
        buf = bytes(self._buf)
        self._buf.clear()
        self._reply_over = True
        if len(buf) == L and buf[-1] == _TERM:
            self.stats.frames += 1
            return [self._unpack(buf, 0)]
        self.stats.dropped_bytes += len(buf)
        self.stats.dropped_frames += 1
        return []

    # -- streaming
    def _accept(self, buf: bytearray, i: int, out: list) -> None:
        rec = self._unpack(buf, i)
        if self._recent:
            step = sum(abs(a - b) for a, b in zip(rec, self._recent[-1]))
            self._step = step if self._step is None else 0.9 * self._step + 0.1 * step
        self._recent.append(rec)
        self._hunted = 0
        out.append(rec)
        self.stats.frames += 1

    def _drop(self, count: int) -> None:
        if count <= 0:
            return
        self.stats.dropped_bytes += count
        self._hunted += count
        if not self._hunt_dropped:
            self.stats.dropped_frames += 1
            self._hunt_dropped = True

    def _distance(self, buf: bytearray, s: int) -> int:
        # how far the frame at s is from the last accepted record (sensor data is smooth)
        if not self._recent:
            return 0
        rec = self._unpack(buf, s)
        return min(sum(abs(a - b) for a, b in zip(rec, last)) for last in self._recent)

    def _roughness(self, buf: bytearray, s: int, frames: int) -> int:
        # mean change between the consecutive frames from s on: small for the true phase, large
        # for a false one (its values put a noisy low byte in the high byte: noise x 256)
        if frames < 2:
            return 0
        L = self.frame_len
        recs = [self._unpack(buf, s + j * L) for j in range(frames)]
        total = sum(
            sum(abs(a - b) for a, b in zip(r0, r1)) for r0, r1 in zip(recs, recs[1:])
        )
        return total // (frames - 1)

    def _process(self, *, final: bool) -> list[tuple[int, ...]]:
        L = self.frame_len
        M = self._HUNT_FRAMES
        buf = self._buf
        n = len(buf)
        i = 0
        out: list[tuple[int, ...]] = []
        while n - i >= L:
            if self._synced:
                if n - i < M * L and not final:
                    break
                if all(buf[e] == _TERM for e in range(i + L - 1, min(i + M * L, n), L)):
                    self._accept(buf, i, out)
                    i += L
                    continue
                self._synced = False
                self._ref = (self._pos + i) % L
                self._hunt_dropped = False
            # hunting: choose a frame start among [i, i + 4L)
            if n - i < (M + 4) * L and not final:
                break
            best = -1
            best_score: tuple[int, int] = (0, 0)
            scores: dict[int, int] = {}
            for s in range(i, min(i + 4 * L, n)):
                prev = buf[s - 1] if s > 0 else self._prev
                if self._ref is None:
                    dist = 0
                else:
                    shift = (self._pos + s - self._ref) % L
                    dist = min(shift, L - shift)
                if prev is not None and prev != _TERM:
                    continue
                lined_up = 0
                for k in range(1, M + 1):
                    e = s + k * L - 1
                    if e >= n:
                        break
                    if buf[e] != _TERM:
                        lined_up = -1
                        break
                    lined_up += 1
                if lined_up <= 0:
                    continue
                if prev is None and (lined_up == M or final):
                    best, best_score = s, (0, 0)  # a stream that starts with a whole frame
                    break
                score = (self._distance(buf, s) + self._roughness(buf, s, lined_up), dist)
                scores[s] = score[0]
                if best < 0 or score < best_score:
                    best, best_score = s, score
            bound = 2 * best_score[0] + 16 * self.channels
            # the same phase a frame earlier passed the checks too and is about as smooth:
            # take the earlier frame rather than drop it
            while best - L >= i and scores.get(best - L, bound + 1) <= bound:
                best -= L
            if (
                best >= 0
                and self._step is not None
                and best_score[0] > max(16 * self._step, 32 * self.channels)
                and self._hunted < 8 * L
            ):
                best = -1  # far from everything recent: a false phase; keep looking a while
            if best < 0 or best >= i + L:
                # nothing here, or the best start lies a frame ahead: look again from there,
                # so that it is weighed against every start up to a frame after it
                step = min(L, n - i)
                self._drop(step)
                i += step
                continue
            self._drop(best - i)
            i = best
            self._synced = True
            self._accept(buf, i, out)
            i += L
        if i:
            self._prev = buf[i - 1]
            self._pos += i
            del buf[:i]
        return out


class FramedDecoder:
    """Decode the framed protocol: COBS(seq + K int16 LE + CRC-16/CCITT-FALSE LE) + 0x00.

    Parameters
    ----------
    channels : int, optional
        K. ``None`` takes K from the first good frame and then drops frames of other lengths.

    Notes
    -----
    Frames are split on 0x00, COBS-decoded, and checked for length and CRC; bad frames are
    dropped and counted (``stats.dropped_frames``). A changed payload or CRC byte is always
    detected (CRC-16 catches every burst of up to 16 bits); damage to COBS structure bytes
    breaks the length or the COBS chain, and what gets past that (about 1 in 65536) is caught
    by the CRC. Records exclude ``seq``; ``stats.last_seq`` holds the last one and
    ``stats.lost_frames`` the sequence gaps. The bytes before the first 0x00 of a stream can be
    the tail of a frame and are dropped (counted) if they do not decode.

    Examples
    --------
    >>> d = FramedDecoder(3)
    >>> d.feed(encode_framed([1, 2, 3], seq=0) + encode_framed([4, 5, 6], seq=2))
    [(1, 2, 3), (4, 5, 6)]
    >>> d.stats.lost_frames, d.stats.last_seq
    (1, 2)
    """

    def __init__(self, channels: int | None = None) -> None:
        self.channels = _check_channels(channels, "framed", required=False)
        self.stats = DecoderStats()
        self._buf = bytearray()
        self._overflow = False
        # frames longer than the longest valid one (plus garbage room) are not kept whole
        self._max_encoded = 2 * self._encoded_len(MAX_CHANNELS)

    @property
    def buffered(self) -> int:
        """Bytes held back waiting for the rest of a frame or line (bounded)."""
        return len(self._buf)

    def reset(self) -> None:
        """Discard a partial frame (counters kept; the next seq starts a new run)."""
        self.stats.dropped_bytes += len(self._buf)
        self._buf.clear()
        self._overflow = False
        self.stats.last_seq = None

    def flush(self) -> list[tuple[int, ...]]:
        """End of stream: an unterminated partial frame is dropped."""
        if self._buf or self._overflow:
            self.stats.dropped_bytes += len(self._buf)
            self.stats.dropped_frames += 1
        self._buf.clear()
        self._overflow = False
        return []

    def feed(self, data: bytes) -> list[tuple[int, ...]]:
        """Add received bytes; return the records of the frames they complete."""
        data = bytes(data)
        self.stats.bytes_in += len(data)
        out: list[tuple[int, ...]] = []
        parts = data.split(b"\x00")
        for j, part in enumerate(parts):
            last = j == len(parts) - 1
            if self._overflow:
                self.stats.dropped_bytes += len(part)
            else:
                self._buf += part
                if len(self._buf) > self._max_encoded:
                    self.stats.dropped_bytes += len(self._buf)
                    self._buf.clear()
                    self._overflow = True
            if last:
                break
            # a 0x00 delimiter ended this frame
            if self._overflow:
                self.stats.dropped_frames += 1
                self._overflow = False
            elif self._buf:
                rec = self._decode(bytes(self._buf))
                if rec is not None:
                    out.append(rec)
                self._buf.clear()
        return out

    def _decode(self, frame: bytes) -> tuple[int, ...] | None:
        rec = self._check(frame)
        if rec is None and self.channels is not None:
            # garbage with no 0x00 in it glued itself in front of a good frame: an encoded
            # frame of K channels has a fixed length, so try the tail
            size = self._encoded_len(self.channels)
            if len(frame) > size:
                rec = self._check(frame[-size:])
                if rec is not None:
                    self.stats.dropped_bytes += len(frame) - size
                    return rec
        if rec is None:
            self.stats.dropped_bytes += len(frame) + 1
            self.stats.dropped_frames += 1
        return rec

    @staticmethod
    def _encoded_len(k: int) -> int:
        raw = 1 + 2 * k + 2
        return raw + 1 + (raw - 1) // 254

    def _check(self, frame: bytes) -> tuple[int, ...] | None:
        try:
            payload = cobs_decode(frame)
        except CalibrationError:
            payload = b""
        ok = len(payload) >= 5 and (len(payload) - 3) % 2 == 0
        k = (len(payload) - 3) // 2
        if ok and self.channels is not None and k != self.channels:
            ok = False
        if ok:
            crc = payload[-2] | (payload[-1] << 8)
            ok = crc16_ccitt(payload[:-2]) == crc
        if not ok:
            return None
        if self.channels is None:
            self.channels = k
        seq = payload[0]
        if self.stats.last_seq is not None:
            self.stats.lost_frames += (seq - self.stats.last_seq - 1) % 256
        self.stats.last_seq = seq
        self.stats.frames += 1
        return struct.unpack_from(f"<{k}h", payload, 1)


_INT_RE = re.compile(r"[+-]?\d+", re.ASCII)
_FLOAT_RE = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?", re.ASCII)
_LABEL_RE = re.compile(r"\s*[A-Za-z_][A-Za-z0-9_ .\-]*:", re.ASCII)
_SPLIT_RE = re.compile(r"\s*,\s*|[ \t]+", re.ASCII)


def _parse_number(tok: str) -> Number | None:
    """The number ``tok`` writes, or None when it is none, or not a reading: not finite, or
    larger in size than any sensor reads (``MAGNITUDE``; the detectors and fits refuse such a
    value, so one damaged line would end a capture). The line is then skipped and counted."""
    if _INT_RE.fullmatch(tok):
        if len(tok) > 20:  # past 1e15 whatever the digits; int() of a huge text is slow
            return None
        i = int(tok)
        return i if abs(i) <= MAGNITUDE[1] else None
    if _FLOAT_RE.fullmatch(tok):
        f = float(tok)
        return f if math.isfinite(f) and abs(f) <= MAGNITUDE[1] else None
    return None


class _LineDecoder:
    """Shared line splitting with a bounded buffer, ``\\r\\n`` and partial lines."""

    def __init__(self) -> None:
        self.stats = DecoderStats()
        self._buf = bytearray()
        self._overlong = False

    @property
    def buffered(self) -> int:
        """Bytes held back waiting for the rest of a frame or line (bounded)."""
        return len(self._buf)

    def reset(self) -> None:
        """Discard a partial line (counters kept)."""
        self.stats.dropped_bytes += len(self._buf)
        self._buf.clear()
        self._overlong = False

    def feed(self, data: bytes) -> list[tuple[Any, ...]]:
        """Add received bytes; return the records of the lines they complete."""
        data = bytes(data)
        self.stats.bytes_in += len(data)
        out: list[tuple[Any, ...]] = []
        parts = data.split(b"\n")
        for j, part in enumerate(parts):
            last = j == len(parts) - 1
            if self._overlong:
                self.stats.dropped_bytes += len(part)
            else:
                self._buf += part
                if len(self._buf) > MAX_LINE_BYTES:
                    self.stats.dropped_bytes += len(self._buf)
                    self._buf.clear()
                    self._overlong = True
            if last:
                break
            if self._overlong:
                self.stats.lines_skipped += 1
                self._overlong = False
                continue
            line = bytes(self._buf)
            self._buf.clear()
            self._line(line, out)
        return out

    def flush(self) -> list[tuple[Any, ...]]:
        """End of stream: decode a last line that has no newline."""
        out: list[tuple[Any, ...]] = []
        if self._overlong:
            self.stats.lines_skipped += 1
        elif self._buf:
            self._line(bytes(self._buf), out)
        self._buf.clear()
        self._overlong = False
        out += self._end()
        return out

    def _end(self) -> list[tuple[Any, ...]]:
        return []

    def _skip(self, line: bytes) -> None:
        self.stats.lines_skipped += 1
        self.stats.dropped_bytes += len(line) + 1

    def _line(self, line: bytes, out: list) -> None:  # pragma: no cover - overridden
        raise NotImplementedError


class TextDecoder(_LineDecoder):
    """Decode text lines of K numbers (commas, spaces or tabs; optional ``label:`` prefix).

    Parameters
    ----------
    channels : int, optional
        K. ``None`` learns K from the first two consecutive good lines with the same count
        (a stream joined mid-line starts with a partial line); then lines with another count
        are skipped.

    Notes
    -----
    Integers stay ``int``; other finite decimals become ``float``; ``nan``, ``inf``, hex and
    anything else make the line skipped and counted. Blank lines are ignored (not counted).

    Examples
    --------
    >>> TextDecoder(3).feed(b"acc: 1, 2, 3\\r\\n4\\t5 6.5\\nbad line\\n")
    [(1, 2, 3), (4, 5, 6.5)]
    """

    def __init__(self, channels: int | None = None) -> None:
        super().__init__()
        self.channels = _check_channels(channels, "text", required=False)
        self._pending: tuple[Number, ...] | None = None

    def reset(self) -> None:
        super().reset()
        if self._pending is not None:
            self.stats.lines_skipped += 1
            self._pending = None

    def _end(self) -> list[tuple[Any, ...]]:
        # a lone first line of a stream, with no second line to confirm K
        if self._pending is not None:
            rec = self._pending
            self._pending = None
            self.channels = len(rec)
            self.stats.frames += 1
            return [rec]
        return []

    def _line(self, line: bytes, out: list) -> None:
        text = line.decode("latin-1").rstrip("\r")
        m = _LABEL_RE.match(text)
        body = text[m.end():] if m else text
        body = body.strip()
        if not body:
            if m:  # a label and nothing else
                self._skip(line)
            return
        vals = []
        for tok in _SPLIT_RE.split(body):
            v = _parse_number(tok)
            if v is None:
                self._skip(line)
                return
            vals.append(v)
        rec = tuple(vals)
        if self.channels is None:
            if self._pending is not None and len(self._pending) == len(rec):
                self.channels = len(rec)
                out.append(self._pending)
                self.stats.frames += 1
                self._pending = None
            else:
                if self._pending is not None:
                    self.stats.lines_skipped += 1
                self._pending = rec
                return
        if len(rec) != self.channels:
            self._skip(line)
            return
        self.stats.frames += 1
        out.append(rec)


_RAW_RE = re.compile(r"Raw:\s*([+-]?\d+(?:\s*,\s*[+-]?\d+){8})\s*", re.ASCII)


class RawDecoder(_LineDecoder):
    """Decode PJRC MotionCal ``Raw:ax,ay,az,gx,gy,gz,mx,my,mz`` lines (int16 counts).

    Other lines (MotionCal's ``Uni:``, ``Cal1:``, boot messages, ...) are skipped and counted.
    Convert with ``RAW_SCALES``: g = counts / 8192, deg/s = counts / 16, uT = counts / 10.

    Examples
    --------
    >>> RawDecoder().feed(b"Raw:1,2,3,4,5,6,7,8,9\\r\\nUni:0.1\\r\\n")
    [(1, 2, 3, 4, 5, 6, 7, 8, 9)]
    """

    channels = 9

    def _line(self, line: bytes, out: list) -> None:
        text = line.decode("latin-1").rstrip("\r")
        if not text.strip():
            return
        m = _RAW_RE.fullmatch(text)
        if not m:
            self._skip(line)
            return
        vals = tuple(int(t) for t in m.group(1).split(","))
        if not all(_I16_MIN <= v <= _I16_MAX for v in vals):
            self._skip(line)
            return
        self.stats.frames += 1
        out.append(vals)


Decoder = Union[BinaryDecoder, FramedDecoder, TextDecoder, RawDecoder]


def make_decoder(protocol: str, channels: int | None, *, polled: bool = False) -> Decoder:
    """Return a fresh decoder for one of ``PROTOCOLS``.

    Parameters
    ----------
    protocol : {"binary", "framed", "text", "raw"}
    channels : int or None
        K values per record; required for ``binary``; for ``raw`` it must be None or 9.
    polled : bool
        Only for ``binary``: one reply per request byte (see :class:`BinaryDecoder`).

    Examples
    --------
    >>> make_decoder("framed", 7).channels
    7
    """
    if protocol not in PROTOCOLS:
        raise CalibrationError(f"unknown protocol {protocol!r}: use one of {PROTOCOLS}")
    if polled and protocol != "binary":
        raise CalibrationError(
            f"polled mode is for the legacy binary protocol only; the {protocol} protocol "
            "streams (the device is switched to it with a mode byte)"
        )
    if protocol == "binary":
        return BinaryDecoder(channels, polled=polled)  # type: ignore[arg-type]
    if protocol == "framed":
        return FramedDecoder(channels)
    if protocol == "text":
        return TextDecoder(channels)
    if channels not in (None, 9):
        raise CalibrationError(
            f"Raw: lines carry 9 values (ax ay az gx gy gz mx my mz), got channels={channels}"
        )
    return RawDecoder()
