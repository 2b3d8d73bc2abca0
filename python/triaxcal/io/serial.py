"""Read records from a sensor board on a serial port (pyserial), whatever goes wrong.

:class:`SerialReader` opens the port, switches the board to the chosen protocol with a mode
byte (``firmware/README.md``: ``P`` polled, ``B`` binary, ``F`` framed, ``T`` text, ``R``
``Raw:``, ``S`` still poses found on the board: :mod:`triaxcal.io.board_poses`), and
returns records as they arrive, each with the host time at which it arrived. Decoding is done
by the pure decoders of :mod:`triaxcal.io.protocol`; this module only moves bytes.

Polled legacy binary (the default for ``protocol="binary"``): for each record the reader
resets the decoder, clears the input buffer, sends the request byte (``!``) and reads exactly
one frame of ``2K + 1`` bytes within ``poll_timeout_s``; a short, long (more bytes waiting
after it) or unterminated reply is dropped and the next request is sent, so a wrong row is
never written. Streaming modes read whatever has arrived and feed it to the decoder.

What goes wrong, and what the reader does:

* the port does not exist: :class:`PortNotFoundError` after ``open_timeout_s`` (it may be
  about to appear, e.g. a board that is booting);
* nothing arrives at all: :class:`SilentDeviceError` after ``silent_s``;
* bytes arrive but never a valid record (wrong baud rate, protocol or channel count):
  :class:`GarbageError` after ``garbage_s``;
* the cable is pulled (``SerialException``/``OSError``, the port vanishes): reported through
  ``on_event``; the reader retries until the port comes back (or ``reconnect_timeout_s``
  passes: :class:`DisconnectedError`), switches the board to the protocol again and goes on.

Silence or garbage *after* good records only produce an ``on_event`` warning: a board that was
working is more likely to be moved, reset or re-plugged than misconfigured.
"""

from __future__ import annotations

import contextlib
import errno
import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, NamedTuple

import serial
import serial.tools.list_ports

from ..errors import CalibrationError
from .board_poses import MODE_BYTE as POSES_MODE_BYTE
from .board_poses import BoardPoseDecoder, BoardPoseSettings
from .protocol import PROTOCOLS, DecoderStats, make_decoder

try:  # a vanished POSIX port can also fail in tcflush/tcsetattr with termios.error
    import termios

    _PORT_ERRORS: tuple[type[BaseException], ...] = (
        serial.SerialException, OSError, termios.error
    )
except ImportError:  # pragma: no cover - Windows
    _PORT_ERRORS = (serial.SerialException, OSError)

__all__ = [
    "CaptureError",
    "DisconnectedError",
    "GarbageError",
    "PortNotFoundError",
    "ReaderStats",
    "Record",
    "SerialReader",
    "SilentDeviceError",
    "mode_byte",
    "parse_request_byte",
]


class CaptureError(CalibrationError):
    """Capturing from a serial port failed; the message says why and what to try."""


class PortNotFoundError(CaptureError):
    """The serial port does not exist (or vanished and did not come back)."""


class SilentDeviceError(CaptureError):
    """The port opened but nothing at all arrived."""


class GarbageError(CaptureError):
    """Bytes arrived but not one valid record: likely a wrong baud rate or protocol."""


class DisconnectedError(CaptureError):
    """The port went away and did not come back within the reconnect timeout."""


class Record(NamedTuple):
    """One decoded record: host time ``t`` (s, ``time.time()``) and the values as received."""

    t: float
    values: tuple[Any, ...]


@dataclass
class ReaderStats:
    """Counters of a :class:`SerialReader` (cumulative over reconnects).

    ``decoder`` holds the decoder's counters (bytes in, frames, dropped bytes and frames,
    skipped lines, lost frames by sequence number). ``polls``: requests sent (polled mode);
    ``poll_failures``: requests not answered by exactly one good frame; ``disconnects`` and
    ``reconnects``: cable pulls seen and recoveries.
    """

    decoder: DecoderStats
    records: int = 0
    polls: int = 0
    poll_failures: int = 0
    disconnects: int = 0
    reconnects: int = 0

    @property
    def dropped(self) -> int:
        """Frames or lines lost to damage: rejected frames, skipped lines, sequence gaps."""
        d = self.decoder
        return max(d.dropped_frames + d.lines_skipped, d.lost_frames)


def mode_byte(protocol: str, *, polled: bool) -> bytes:
    """The mode byte that switches the firmware (and :class:`triaxcal.sim.SimDevice`) to a
    protocol: ``P`` (polled binary), ``B``, ``F``, ``T`` or ``R``."""
    if protocol == "binary":
        return b"P" if polled else b"B"
    return {"framed": b"F", "text": b"T", "raw": b"R"}[protocol]


def parse_request_byte(value: Any) -> bytes:
    """A request byte from ``0x21``, ``33``, ``"!"`` or ``b"!"`` (one byte)."""
    if isinstance(value, bytes) and len(value) == 1:
        return value
    if isinstance(value, int) and not isinstance(value, bool) and 0 <= value <= 255:
        return bytes([value])
    if isinstance(value, str):
        s = value.strip()
        if len(s) == 1 and not s.isdigit():
            return s.encode("latin-1")
        try:
            v = int(s, 0)
        except ValueError:
            v = -1
        if 0 <= v <= 255:
            return bytes([v])
    raise CaptureError(
        f"request byte must be one byte: 0x21, 33 or '!' (got {value!r})"
    )


def _ports_present() -> str:
    try:
        found = sorted(p.device for p in serial.tools.list_ports.comports())
    except Exception:  # pragma: no cover - platform specific  # noqa: BLE001
        found = []
    return ", ".join(found) if found else "none found"


class SerialReader:
    """Records from a serial port, for one protocol; survives a pulled cable.

    Parameters
    ----------
    port : str
        Device path or name: ``/dev/ttyUSB0``, ``/dev/ttyACM0``, ``COM3``, a pty.
    protocol : {"binary", "framed", "text", "raw"}
        Wire protocol (see :mod:`triaxcal.io.protocol`).
    channels : int, optional
        Values per record (K). Required for ``binary``; learnt from the data if ``None``
        for ``framed`` and ``text``; 9 for ``raw``.
    baud : int
        Baud rate (ignored by pseudo-terminals and USB CDC boards).
    stream : bool
        ``binary`` only: the board streams by itself (mode ``B``) instead of being polled with
        ``request_byte``. The other protocols always stream.
    request_byte : int, str or bytes
        Request byte of polled binary (default ``!``, 0x21).
    switch_mode : bool
        Send the mode byte after opening (and after every reconnect); turn off for boards
        that stream by themselves and do not know the commands.
    open_timeout_s, silent_s, garbage_s : float
        How long to wait for the port to exist, for the first byte, and for the first valid
        record while bytes do arrive, before raising.
    poll_timeout_s : float
        Longest wait for the reply to one request (polled binary).
    poll_interval_s : float
        Shortest time between requests (0: as fast as the board answers).
    poll_settle_s : float, optional
        After a full reply, wait this long and reject the reply if more bytes came (garbage
        in front of the frame makes a reply too long). Default: three characters' time at
        ``baud`` plus 0.5 ms.
    reconnect : bool
        Wait for a vanished port to come back (else raise :class:`DisconnectedError`).
    reconnect_timeout_s : float, optional
        Give up waiting after this long (``None``: wait until stopped).
    on_event : callable(kind, message), optional
        Called with ``("disconnected" | "reconnected" | "silent" | "garbage" | "resumed",
        message)``.
    board_poses : BoardPoseSettings, optional
        ``framed`` only: the board finds the still poses itself (firmware mode ``S``). After
        opening, the reader stops any stream, sends these settings and the mode byte ``S``;
        each record is then one pose, ``(*means, n)`` (:class:`~triaxcal.io.board_poses.
        BoardPoseDecoder`, whose ``status`` and ``settings`` say what the board reports).

    Attributes
    ----------
    on_bytes : callable(bytes) or None
        Called (in the reading thread) with every chunk of bytes read, before decoding; the
        live page listens this way for a board's ``Cal1:``/``Cal2:`` echo while streaming.

    Examples
    --------
    >>> from triaxcal.sim import SimDevice
    >>> with SimDevice(speed=20) as dev, SerialReader(dev.port, protocol="framed",
    ...                                                 channels=10) as reader:
    ...     recs = []
    ...     while len(recs) < 5:
    ...         recs += reader.read()
    >>> len(recs[0].values)
    10
    """

    def __init__(
        self,
        port: str,
        *,
        protocol: str = "framed",
        channels: int | None = None,
        baud: int = 115200,
        stream: bool = False,
        request_byte: Any = b"!",
        switch_mode: bool = True,
        open_timeout_s: float = 1.0,
        silent_s: float = 3.0,
        garbage_s: float = 3.0,
        poll_timeout_s: float = 0.1,
        poll_interval_s: float = 0.0,
        poll_settle_s: float | None = None,
        read_timeout_s: float = 0.05,
        reconnect: bool = True,
        reconnect_timeout_s: float | None = None,
        on_event: Callable[[str, str], None] | None = None,
        board_poses: BoardPoseSettings | None = None,
    ) -> None:
        if protocol not in PROTOCOLS:
            raise CaptureError(f"unknown protocol {protocol!r}: use one of {', '.join(PROTOCOLS)}")
        if isinstance(baud, bool) or not isinstance(baud, int) or baud <= 0:
            raise CaptureError(f"baud must be a positive whole number, e.g. 115200; got {baud!r}")
        self.baud = baud
        self.port_name = str(port)
        self.protocol = protocol
        self.polled = protocol == "binary" and not stream
        if board_poses is not None and (protocol != "framed" or
                                        not isinstance(board_poses, BoardPoseSettings)):
            raise CaptureError("board poses come in the framed protocol: use protocol='framed' "
                               "and a BoardPoseSettings")
        self.board_poses = board_poses
        self.decoder = (BoardPoseDecoder(channels) if board_poses is not None
                        else make_decoder(protocol, channels, polled=self.polled))
        self.channels = getattr(self.decoder, "channels", channels)
        self.request = parse_request_byte(request_byte)
        self.switch_mode = bool(switch_mode)
        self.open_timeout_s = float(open_timeout_s)
        self.silent_s = float(silent_s)
        self.garbage_s = float(garbage_s)
        self.poll_timeout_s = float(poll_timeout_s)
        self.poll_interval_s = float(poll_interval_s)
        # three characters' time plus a little: long enough for the rest of a reply that had
        # garbage in front of it to show up, so that the reply is rejected as too long
        self.poll_settle_s = 30.0 / baud + 0.0005 if poll_settle_s is None else float(
            poll_settle_s
        )
        self.read_timeout_s = float(read_timeout_s)
        self.reconnect = bool(reconnect)
        self.reconnect_timeout_s = reconnect_timeout_s
        self.on_event = on_event
        self.on_bytes: Callable[[bytes], None] | None = None
        self.stats = ReaderStats(decoder=self.decoder.stats)
        self._port: serial.Serial | None = None
        self._disconnected_at: float | None = None
        self._t_ok = 0.0  # since when we wait for data (open / reconnect / last record)
        self._bytes_since_record = 0
        self._first_bytes = bytearray()
        self._warned: str | None = None
        self._last_poll = 0.0

    # -- life cycle
    @property
    def is_open(self) -> bool:
        return self._port is not None and self._port.is_open

    @property
    def connected(self) -> bool:
        """False while waiting for a pulled cable to come back."""
        return self._disconnected_at is None

    def open(self) -> SerialReader:
        """Open the port (waiting up to ``open_timeout_s`` for it to appear) and set the mode."""
        deadline = time.monotonic() + self.open_timeout_s
        while True:
            try:
                self._open_once()
                break
            except PortNotFoundError:
                if time.monotonic() >= deadline:
                    raise PortNotFoundError(
                        f"serial port {self.port_name!r} does not exist (waited "
                        f"{self.open_timeout_s:g} s): check the cable and the name "
                        f"(ports present: {_ports_present()})"
                    ) from None
                time.sleep(0.1)
        return self

    def _open_once(self) -> None:
        try:
            port = serial.Serial(
                self.port_name,
                self.baud,
                timeout=self.poll_timeout_s if self.polled else self.read_timeout_s,
                write_timeout=1.0,
            )
        except _PORT_ERRORS as exc:
            code = getattr(exc, "errno", None)
            if code in (errno.ENOENT, errno.ENXIO, errno.ENODEV) or not os.path.exists(
                self.port_name
            ) and os.name == "posix":
                raise PortNotFoundError(str(exc)) from None
            if code in (errno.EACCES, errno.EPERM):
                raise CaptureError(
                    f"no permission to open {self.port_name!r}: add yourself to the port's "
                    "group (on Debian/Ubuntu: sudo usermod -aG dialout $USER, then log in "
                    "again)"
                ) from None
            if code == errno.EBUSY:
                raise CaptureError(
                    f"{self.port_name!r} is busy: close other programs using it (serial "
                    "monitors, MotionCal, another triaxcal)"
                ) from None
            raise CaptureError(f"could not open {self.port_name!r}: {exc}") from None
        try:
            if self.switch_mode and self.board_poses is not None:
                # stop a stream, drop what it sent, then the settings and 'S': the board's
                # answer (its settings) stays in the buffer for the decoder
                port.write(b"P")
                port.flush()
                time.sleep(0.02)
                port.reset_input_buffer()
                port.write(self.board_poses.packet() + POSES_MODE_BYTE)
                port.flush()
            elif self.switch_mode:
                port.write(mode_byte(self.protocol, polled=self.polled))
                port.flush()
                time.sleep(0.02)
                port.reset_input_buffer()
            else:
                port.reset_input_buffer()
        except _PORT_ERRORS as exc:
            with contextlib.suppress(Exception):
                port.close()
            raise CaptureError(f"{self.port_name} failed right after opening: {exc}") from None
        self._port = port
        self.decoder.reset()
        self._t_ok = time.monotonic()
        self._bytes_since_record = 0

    def close(self) -> None:
        """Switch a streaming board back to polled mode (best effort) and close the port."""
        port, self._port = self._port, None
        if port is None:
            return
        with contextlib.suppress(Exception):
            if self.switch_mode and not self.polled and self._disconnected_at is None:
                port.write(b"P")
                port.flush()
        with contextlib.suppress(Exception):
            port.close()

    def __enter__(self) -> SerialReader:  # noqa: PYI034
        return self.open()

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- reading
    def read(self) -> list[Record]:
        """Records that arrived since the last call (waits at most about 0.1 s for some).

        Raises
        ------
        SilentDeviceError, GarbageError
            Nothing, or nothing valid, arrived since the port was opened.
        DisconnectedError
            The port vanished and did not come back in ``reconnect_timeout_s``.
        """
        if self._port is None and self._disconnected_at is None:
            self.open()
        if self._disconnected_at is not None:
            self._try_reconnect()
            return []
        beats = getattr(self.decoder, "heartbeats", 0)
        try:
            recs = self._poll() if self.polled else self._read_stream()
        except _PORT_ERRORS as exc:
            self._lost(exc)
            return []
        # a board finding poses is alive when it sends its status, though no pose came yet
        self._check_health(bool(recs) or getattr(self.decoder, "heartbeats", 0) != beats)
        self.stats.records += len(recs)
        return recs

    def _read_stream(self) -> list[Record]:
        port = self._port
        assert port is not None
        data = port.read(port.in_waiting or 1)
        if data and port.in_waiting:
            data += port.read(port.in_waiting)
        if not data:
            return []
        t = time.time()
        self._seen(data)
        return [Record(t, v) for v in self.decoder.feed(data)]

    def _poll(self) -> list[Record]:
        port = self._port
        assert port is not None
        if self.poll_interval_s:
            wait = self._last_poll + self.poll_interval_s - time.monotonic()
            if wait > 0:
                time.sleep(wait)
        self._last_poll = time.monotonic()
        assert self.channels is not None  # binary needs K
        frame_len = 2 * int(self.channels) + 1
        self.decoder.reset()
        port.reset_input_buffer()
        port.write(self.request)
        self.stats.polls += 1
        data = port.read(frame_len)
        t = time.time()
        self._seen(data)
        recs = self.decoder.feed(data) if data else []
        if recs and self.poll_settle_s > 0:
            time.sleep(self.poll_settle_s)  # let the tail of a too-long reply arrive
        extra = port.in_waiting
        if extra:  # a reply longer than one frame: garbage in it, reject the lot
            more = port.read(extra)
            self._seen(more)
            self.decoder.feed(more)
            if recs:
                self.decoder.stats.dropped_frames += 1
                recs = []
        if not recs:
            self.stats.poll_failures += 1
            return []
        return [Record(t, recs[0])]

    def write(self, data: bytes) -> None:
        """Write ``data`` to the board (e.g. a MotionCal packet) while reading goes on.

        Safe to call from another thread than the one reading. Raises :class:`CaptureError`
        when the port is not open or the cable is pulled.
        """
        port = self._port
        if port is None or self._disconnected_at is not None:
            raise CaptureError(
                f"{self.port_name} is not connected: plug the board in and try again"
            )
        try:
            port.write(bytes(data))
            port.flush()
        except _PORT_ERRORS as exc:
            raise CaptureError(f"writing to {self.port_name} failed: {exc}") from None

    def _seen(self, data: bytes) -> None:
        if data and self.on_bytes is not None:
            self.on_bytes(data)
        self._bytes_since_record += len(data)
        if len(self._first_bytes) < 32:
            self._first_bytes += data[: 32 - len(self._first_bytes)]

    # -- health
    def _what(self) -> str:
        k = f"K={self.channels} " if self.channels else ""
        return {
            "binary": f"{k}binary frame",
            "framed": f"{k}framed (COBS/CRC) frame",
            "text": "text line",
            "raw": "Raw: line",
        }[self.protocol]

    def _check_health(self, got: bool) -> None:
        now = time.monotonic()
        if got:
            self._first_bytes.clear()
            if self._warned:
                self._event("resumed", f"{self.port_name}: data is arriving again")
            self._warned = None
            self._t_ok = now
            self._bytes_since_record = 0
            return
        waited = now - self._t_ok
        first = self.stats.records == 0
        if self._bytes_since_record == 0 and waited > self.silent_s:
            if self.polled:
                hint = (
                    f"it did not answer the request byte {self.request!r} (polled binary); "
                    "if it streams by itself, add --stream or pick its --protocol"
                )
            elif self.switch_mode and self.board_poses is not None:
                hint = (
                    "it sent nothing after the mode byte 'S'; does its firmware have the "
                    "still-pose mode (triaxcal firmware, firmware/README.md)? Without it, "
                    "capture without --board-poses"
                )
            elif self.switch_mode:
                mb = mode_byte(self.protocol, polled=False).decode()
                hint = (
                    f"it sent nothing after the mode byte {mb!r}; if it only answers "
                    "requests, use --protocol binary without --stream"
                )
            else:
                hint = "it sent nothing; is the firmware running and streaming?"
            msg = (
                f"no data from {self.port_name} in {waited:.1f} s: check that the board is "
                f"powered and running the firmware and that nothing else holds the port; {hint}"
            )
            if first:
                raise SilentDeviceError(msg)
            self._warn("silent", msg)
        elif self._bytes_since_record > 0 and waited > self.garbage_s:
            msg = (
                f"{self._bytes_since_record} bytes from {self.port_name} in {waited:.1f} s but "
                f"not one valid {self._what()} (first bytes: {bytes(self._first_bytes).hex(' ')}"
                f"): the baud rate is probably wrong (now {self.baud}; try 9600, 57600, 115200, "
                "230400) or the board speaks another protocol or channel count (--protocol, "
                "--channels)"
            )
            if first:
                raise GarbageError(msg)
            self._warn("garbage", msg)

    def _warn(self, kind: str, msg: str) -> None:
        if self._warned != kind:
            self._warned = kind
            self._event(kind, msg)

    def _event(self, kind: str, msg: str) -> None:
        if self.on_event is not None:
            self.on_event(kind, msg)

    # -- pulled cable
    def _lost(self, exc: BaseException) -> None:
        port, self._port = self._port, None
        if port is not None:
            with contextlib.suppress(Exception):
                port.close()
        self.stats.disconnects += 1
        self._disconnected_at = time.monotonic()
        if not self.reconnect:
            raise DisconnectedError(f"{self.port_name} disconnected ({exc})") from None
        self._event(
            "disconnected",
            f"{self.port_name} disconnected ({exc}); waiting for it to come back "
            "(plug the cable in again, or Ctrl-C to stop: everything so far is saved)",
        )

    def _try_reconnect(self) -> None:
        assert self._disconnected_at is not None
        try:
            self._open_once()
        except CaptureError as exc:
            gone = time.monotonic() - self._disconnected_at
            if self.reconnect_timeout_s is not None and gone > self.reconnect_timeout_s:
                raise DisconnectedError(
                    f"{self.port_name} disconnected and did not come back in {gone:.1f} s "
                    f"({exc})"
                ) from None
            time.sleep(0.1)
            return
        gone = time.monotonic() - self._disconnected_at
        self._disconnected_at = None
        self.stats.reconnects += 1
        self._event("reconnected", f"{self.port_name} is back after {gone:.1f} s; capturing")
