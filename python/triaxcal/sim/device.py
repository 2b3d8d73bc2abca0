"""The simulated serial device: a pseudo-terminal that speaks the firmware's protocols."""

from __future__ import annotations

import contextlib
import math
import os
import select
import tempfile
import threading
import time
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from .._checks.options import named, number
from .._checks.options import seed as seed_of
from ..errors import CalibrationError
from ..io.protocol import encode_binary, encode_framed, encode_raw, encode_text
from ..quality.bounds import sample_rate
from .imu import SimIMU
from .scripts import Script, globe_script

if TYPE_CHECKING:
    from ..io.motioncal import MotionCalPacket


# --------------------------------------------------------------------------------------------
# simulated serial device

#: Mode bytes of the device commands (as ``firmware/src/protocol.c``): the streaming protocol
#: each byte switches to.
MODE_BYTES = {b"P": None, b"B": "binary", b"F": "framed", b"T": "text", b"R": "raw"}
#: The identify command: the board answers ``ID:<serial number>\r\n`` (see
#: :func:`triaxcal.capture.multi.query_serial_number`).
ID_BYTE = b"I"
_MODE_OF = {None: "P", "binary": "B", "framed": "F", "text": "T", "raw": "R"}


@dataclass(frozen=True)
class Faults:
    """Faults a :class:`SimDevice` injects into the bytes it sends (at random, at most one
    per frame; damage to a frame's delimiter also spoils the next frame, marked so in the log).

    Attributes
    ----------
    garbage_prob : float
        Chance per frame of 1..``garbage_max`` random bytes just before it. In the text and
        ``Raw:`` modes the junk is line noise (bytes 0x80-0xFF and control characters, never
        digits or signs), and half the time ends with a newline of its own.
    garbage_max : int
        Most garbage bytes in one burst.
    drop_prob : float
        Chance per frame that one of its bytes is lost.
    drop_where : {"any", "structure"}
        Which byte is lost: any, or (text and ``Raw:`` lines) only a separator or the line
        end. A lost digit turns a text number into another number, which no decoder can see.
    flip_prob : float
        Chance per frame that one bit of one of its bytes is flipped.
    seed : int
        Seed of the fault generator.
    """

    garbage_prob: float = 0.0
    garbage_max: int = 8
    drop_prob: float = 0.0
    drop_where: str = "any"
    flip_prob: float = 0.0
    seed: int = 0


@dataclass(frozen=True)
class SentFrame:
    """One frame as the :class:`SimDevice` sent it (its log, for tests).

    ``index`` is the sample index (sim time ``index / rate_hz`` s); ``protocol`` the encoding;
    ``values`` the counts encoded; ``polled`` whether it answered a ``!`` request; ``intact``
    is False when its bytes were damaged (dropped or flipped), cut off by an unplug, or glued
    to garbage in front of it (so that a decoder cannot tell where the frame starts).

    ``reply_s`` (polled replies only): an upper bound of the time the reply took, from the last
    moment the device found its input empty before the request to the whole reply being in the
    pty. A host that gave up on the request sooner (its poll timeout) may lose the reply or take
    it for the answer to its next request. ``inf`` when the request came while an earlier reply
    was still unsent (after a stall, e.g. on a loaded machine): the replies then reach the host
    back to back, and it cannot tell them apart.
    """

    index: int
    protocol: str
    values: tuple[int, ...]
    polled: bool
    intact: bool
    reply_s: float | None = None


#: Frames a second the simulated board may send (``rate_hz * speed``): at least one a second
#: (the host gives up on a board silent for 3 s), at most a million (past what any serial link
#: or the host's reader keeps up with; the sample counter would overflow near 1e308).
FRAMES_PER_SECOND = (1.0, 1e6)


class SimDevice:
    """A simulated sensor board on a pseudo-terminal: open :attr:`port` with pyserial.

    The device runs in a background thread. It samples a :class:`SimIMU` following a
    :class:`Script` at ``rate_hz`` of simulated time, ``speed`` times faster than real time,
    and implements the firmware's commands (``firmware/README.md``): ``!`` answers one legacy
    binary frame of
    the current sample (in any mode); ``P`` stops streaming (the boot default), ``B``
    streams legacy binary frames, ``F`` framed (COBS + CRC-16) frames, ``T`` text lines, ``R``
    MotionCal ``Raw:`` lines; ``I`` answers the board's serial number as one line
    ``ID:<serial>\\r\\n``; a 68-byte MotionCal calibration packet with a valid CRC is
    answered with ``Cal1:``/``Cal2:`` lines (stored in :attr:`motioncal`).

    The script starts when the host first asks for data (a poll, or a mode byte that starts a
    stream; at :meth:`start` when ``mode`` streams from power-on), as a user starts turning
    the board once the capture runs: the time the host takes to open the port costs none of
    the script (at ``speed=10`` a host that took 0.3 s would miss the first 3 s still pose).

    Parameters
    ----------
    imu : SimIMU, optional
        The sensor (default ``SimIMU(seed)``).
    script : Script, optional
        The motion (default :func:`globe_script`).
    rate_hz : float
        Samples per second of simulated time.
    speed : float
        Simulated seconds per real second; frames go out at ``rate_hz * speed`` per second.
    channels : {10, 7}
        Values per frame: 10 = ``ax ay az gx gy gz mx my mz temp``, 7 = no magnetometer.
        ``Raw:`` lines always carry 9 (magnetometer zeros when ``channels=7``).
    mode : {"P", "B", "F", "T", "R"}
        Mode at power-on (``"P"``, polled, like the firmware).
    loop : bool
        Start the script again at its end; otherwise hold the last pose and set
        :attr:`finished` (streaming stops) once every frame of the script is in the pty.
    faults : Faults, optional
        Bytes to damage, for tests.
    temp_c : float or (start, end)
        Die temperature (see :meth:`SimIMU.record`).
    wrong_baud : bool
        Behave like a board on another baud rate: every byte sent is scrambled and commands
        are not understood (use with a streaming ``mode``).
    link : str or path, optional
        Path of the symlink that :attr:`port` names (default: in a fresh temporary folder,
        made by :meth:`start`). It stays the same across :meth:`unplug`, as ``/dev/ttyUSB0``
        does.
    seed : int
        Seed of the default IMU and of the noise.
    serial : str or None
        Serial number answered to ``I`` (default ``"SIM-<seed>"``); ``None``: the board does
        not know the command and ignores it, as older firmware does.

    Examples
    --------
    >>> import serial
    >>> from triaxcal.sim import SimDevice
    >>> with SimDevice(speed=10) as dev:
    ...     with serial.Serial(dev.port, 115200, timeout=1) as port:
    ...         _ = port.write(b"!")
    ...         len(port.read(21))
    21
    """

    def __init__(
        self,
        imu: SimIMU | None = None,
        script: Script | None = None,
        *,
        rate_hz: float = 100.0,
        speed: float = 1.0,
        channels: int = 10,
        mode: str = "P",
        loop: bool = True,
        faults: Faults | None = None,
        temp_c: float | tuple[float, float] = 25.0,
        wrong_baud: bool = False,
        link: Any = None,
        seed: int = 0,
        serial: str | None = "",
    ) -> None:
        if channels not in (10, 7):
            raise CalibrationError(f"SimDevice channels must be 10 or 7, got {channels}")
        if mode.encode() not in MODE_BYTES:
            raise CalibrationError(f"mode must be one of P, B, F, T, R, got {mode!r}")
        rate_hz = sample_rate(rate_hz)
        speed = number(speed, "speed", gt=0, hint="simulated seconds per real second")
        lo, hi = FRAMES_PER_SECOND
        if not lo <= rate_hz * speed <= hi:
            raise CalibrationError(
                f"{named('speed')}={speed:g} at {rate_hz:g} Hz sends {rate_hz * speed:.3g} frames "
                f"a second: give a speed that sends {lo:g} to {hi:g} (a slower board sends "
                "nothing the host can wait for, a faster one more than a serial link carries)")
        faults = faults or Faults()
        if faults.drop_where not in ("any", "structure"):
            raise CalibrationError("Faults.drop_where must be 'any' or 'structure'")
        self.imu = imu if imu is not None else SimIMU(seed)
        self.script = script if script is not None else globe_script(seed=seed)
        self.recording = self.imu.record(self.script, rate_hz, temp_c=temp_c)
        self.rate_hz = float(rate_hz)
        self.speed = float(speed)
        self.channels = int(channels)
        self.loop = bool(loop)
        self.faults = faults
        self.wrong_baud = bool(wrong_baud)
        self.serial = f"SIM-{int(seed)}" if serial == "" else serial
        self.boot_mode = MODE_BYTES[mode.encode()]
        self.protocol: str | None = self.boot_mode
        self._frames = self.recording.frames(self.channels)
        self._frames9 = (
            self.recording.frames(9)
            if self.channels == 10
            else np.hstack([self._frames[:, :6], np.zeros((len(self._frames), 3), np.int32)])
        )
        self._frng = np.random.default_rng([seed_of(faults.seed, "faults.seed"), 0xFA17])
        self._brng = np.random.default_rng([seed_of(seed), 0xBAD])
        self.sent: list[SentFrame] = []
        self.received = bytearray()
        self.motioncal: MotionCalPacket | None = None
        self.finished = threading.Event()
        self.unplugs = 0
        self._link_dir: str | None = None
        #: Path to open with pyserial (a symlink to the pty; set by :meth:`start` if not given).
        self.port: str = "" if link is None else str(link)
        self._master: int | None = None
        self._slave: int | None = None
        self.pty_path: str | None = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._pending: list[list[Any]] = []  # [bytes, SentFrame, bytes written, since]
        self._pending_bytes = 0
        self._seq = 0
        self._next = 0  # next sample index to stream
        self._t0 = 0.0  # when the script started (see _begin)
        self._started = False
        self._unplug_until = 0.0
        self._silent_until = 0.0
        self._stall_until = 0.0
        self._idle_at = 0.0  # last time the input was found empty with no reply unsent
        self._reply_at = -1.0  # last time a polled reply was queued
        self._packet: bytearray | None = None
        self._packet_t = 0.0
        self._damage_next = False
        self._requests: list[tuple[float, threading.Event]] = []

    # -- life cycle
    def start(self) -> SimDevice:
        """Open the pseudo-terminal and start the device thread; returns ``self``."""
        if self._thread is not None:
            return self
        if not self.port:
            self._link_dir = tempfile.mkdtemp(prefix="triaxcal-sim-")
            self.port = os.path.join(self._link_dir, "ttySIM0")
        self._stop.clear()
        self._plug()
        self._t0 = time.monotonic()
        self._started = self.boot_mode is not None  # a board that streams from power-on
        self._thread = threading.Thread(target=self._run, name="SimDevice", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop the thread, close the pseudo-terminal and remove the port symlink."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None
        self._unplug_now()
        if self._link_dir is not None:
            with contextlib.suppress(OSError):
                os.rmdir(self._link_dir)
            self._link_dir = None
            self.port = ""

    def __enter__(self) -> SimDevice:  # noqa: PYI034
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def __repr__(self) -> str:
        return (
            f"SimDevice(port={self.port!r}, mode={_MODE_OF[self.protocol]!r}, "
            f"rate_hz={self.rate_hz:g}, speed={self.speed:g}, sent={len(self.sent)})"
        )

    # -- test hooks
    def unplug(self, seconds: float) -> None:
        """Pull the cable for ``seconds`` (real time): the port vanishes, then comes back on
        the same :attr:`port` path with the device rebooted (boot mode, polled)."""
        done = threading.Event()
        self._requests.append((float(seconds), done))
        if self._thread is not None and self._thread.is_alive():
            done.wait(timeout=2.0)

    def silence(self, seconds: float) -> None:
        """Stop answering and streaming for ``seconds`` (real time); commands are ignored."""
        self._silent_until = time.monotonic() + float(seconds)

    def stall(self, seconds: float) -> None:
        """Stop reading the port for ``seconds`` (real time), as a busy board does: requests
        wait in its input and are all answered afterwards (their ``reply_s`` says so)."""
        self._stall_until = time.monotonic() + float(seconds)

    @property
    def sim_time_s(self) -> float:
        """Simulated seconds since the script started (0 until the host asks for data)."""
        return (time.monotonic() - self._t0) * self.speed if self._started else 0.0

    def frames_sent(self, *, intact_only: bool = False) -> np.ndarray:
        """Values of the frames sent so far, (n, K) int (``intact_only``: undamaged ones)."""
        rows = [f.values for f in list(self.sent) if f.intact or not intact_only]
        k = len(rows[0]) if rows else self.channels
        return np.array(rows, dtype=np.int64).reshape(-1, k)

    # -- pty
    def _plug(self) -> None:
        import tty  # POSIX only: importing triaxcal.sim must work everywhere

        master, slave = os.openpty()
        tty.setraw(slave)
        os.set_blocking(master, False)
        self._master, self._slave = master, slave
        self.pty_path = os.ttyname(slave)
        tmp = self.port + ".new"
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        os.symlink(self.pty_path, tmp)
        os.replace(tmp, self.port)

    def _unplug_now(self) -> None:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(self.port)
        for fd in (self._master, self._slave):
            if fd is not None:
                with contextlib.suppress(OSError):
                    os.close(fd)
        self._master = self._slave = None
        # whatever was half sent is lost; log it as damaged
        for item in self._pending:
            if item[2] and item[1] is not None:
                self.sent.append(replace(item[1], intact=False,
                                         reply_s=None if item[3] is None else math.inf))
        self._pending.clear()
        self._pending_bytes = 0
        self._packet = None

    # -- the device loop
    def _sample(self) -> int:
        if not self._started:
            return 0
        return int((time.monotonic() - self._t0) * self.speed * self.rate_hz)

    def _begin(self) -> None:
        """Start the script's clock (once): the host asked for data."""
        if not self._started:
            self._t0 = time.monotonic()
            self._started = True

    def _run(self) -> None:
        n = len(self._frames)
        while not self._stop.is_set():
            now = time.monotonic()
            while self._requests:  # unplug requests, served here so no fd is closed under us
                seconds, done = self._requests.pop(0)
                self._unplug_until = now + seconds
                self._unplug_now()
                self.unplugs += 1
                done.set()
            with self._lock:
                if self._master is None:
                    if now >= self._unplug_until:
                        self._plug()
                        self.protocol = self.boot_mode  # the board rebooted
                        self._seq = 0
                        self._damage_next = False
                        self._next = self._sample()
                    else:
                        time.sleep(0.005)
                        continue
                master = self._master
            assert master is not None
            try:
                if time.monotonic() < self._stall_until:
                    time.sleep(0.001)
                    continue
                ready, _, _ = select.select([master], [], [], 0)
                if not ready:
                    if not self._pending:
                        self._idle_at = time.monotonic()
                    ready, _, _ = select.select([master], [], [], self._wait_s())
                if ready:
                    data = os.read(master, 4096)
                    if now >= self._silent_until and not self.wrong_baud:
                        self._commands(data)
                cur = self._sample()
                if not self.loop and cur >= n:
                    cur = n - 1
                silent = time.monotonic() < self._silent_until
                if self.protocol is not None and not silent:
                    while self._next <= cur and self._pending_bytes < 8192:
                        self._emit(self._next, self.protocol, polled=False)
                        self._next += 1
                if silent or self.protocol is None:
                    self._next = max(self._next, cur + 1)  # no burst of old samples later
                self._flush()
                if not self.loop and self._next >= n and not self._pending:
                    # the script is over and every byte of it is in the pty: whatever the
                    # host has not read yet is in its input buffer, not still to come
                    self.finished.set()
            except OSError:
                # unplugged under our feet (stop() or unplug() from another thread)
                time.sleep(0.002)

    def _wait_s(self) -> float:
        if self._pending:
            return 0.0005
        if self.protocol is None:
            return 0.005
        due = (self._next / (self.rate_hz * self.speed)) - (time.monotonic() - self._t0)
        return min(0.005, max(0.0005, due))

    def _commands(self, data: bytes) -> None:
        self.received += data
        now = time.monotonic()
        for b in data:
            if self._packet is not None:
                if now - self._packet_t > 1.0:
                    self._packet = None
                else:
                    self._packet.append(b)
                    if len(self._packet) == 2 and b != 84:
                        self._packet = None
                        self._command(b)
                    elif len(self._packet) == 68:
                        self._motioncal(bytes(self._packet))
                        self._packet = None
                    continue
            if b == 117:
                self._packet = bytearray([b])
                self._packet_t = now
                continue
            self._command(b)

    def _command(self, b: int) -> None:
        c = bytes([b])
        if c == b"!":
            self._begin()
            cur = min(self._sample(), len(self._frames) - 1) if not self.loop else self._sample()
            # the request came after the input was last seen empty; an earlier reply queued
            # since then reaches the host back to back with this one
            since = -1.0 if self._reply_at >= self._idle_at else self._idle_at
            self._reply_at = time.monotonic()
            self._emit(cur, "binary", polled=True, since=since)
        elif c == ID_BYTE and self.serial is not None:
            self._queue(f"ID:{self.serial}\r\n".encode("utf-8", "replace"), None)
        elif c in MODE_BYTES:
            new = MODE_BYTES[c]
            if new != self.protocol:
                self.protocol = new
                if new is not None:
                    self._begin()
                self._next = self._sample()

    def _motioncal(self, packet: bytes) -> None:
        from ..io.motioncal import decode_motioncal, format_cal_lines

        try:
            cal = decode_motioncal(packet)
        except CalibrationError:
            return  # a board ignores a packet whose CRC is wrong
        self.motioncal = cal
        self._queue(format_cal_lines(cal), None)

    def _values(self, index: int, protocol: str) -> tuple[int, ...]:
        i = index % len(self._frames)
        row = self._frames9[i] if protocol == "raw" else self._frames[i]
        return tuple(int(v) for v in row)

    def _emit(self, index: int, protocol: str, *, polled: bool, since: float = 0.0) -> None:

        values = self._values(index, protocol)
        if protocol == "binary":
            frame = encode_binary(values)
        elif protocol == "framed":
            frame = encode_framed(values, self._seq)
            self._seq = (self._seq + 1) & 0xFF
        elif protocol == "text":
            frame = encode_text(values)
        else:
            frame = encode_raw(values)
        frame, junk, intact = self._damage(frame, protocol, polled)
        if junk:
            self._queue(junk, None)
        self._queue(frame, SentFrame(index, protocol, values, polled, intact),
                    since if polled else None)

    def _damage(self, frame: bytes, protocol: str, polled: bool) -> tuple[bytes, bytes, bool]:
        f, rng = self.faults, self._frng
        if self.wrong_baud:
            return bytes(self._brng.integers(0, 256, len(frame), dtype=np.uint8)), b"", False
        intact = not self._damage_next
        self._damage_next = False
        junk = b""
        lines = protocol in ("text", "raw")
        data = bytearray(frame)
        r = rng.random()  # at most one fault per frame
        if r < f.garbage_prob:
            n = int(rng.integers(1, max(1, f.garbage_max) + 1))
            if lines:
                alphabet = np.r_[1:9, 11:13, 14:32, 128:256].astype(np.uint8)
                junk = bytes(rng.choice(alphabet, n))
                if rng.random() < 0.5:
                    junk += b"\n"
                glued = not junk.endswith(b"\n")
            else:
                junk = bytes(rng.integers(0, 256, n, dtype=np.uint8))
                glued = protocol != "framed" or not junk.endswith(b"\x00")
            if glued or polled:
                intact = False
        elif r < f.garbage_prob + f.drop_prob:
            if lines and f.drop_where == "structure":
                where = [i for i, c in enumerate(data) if c in b",\n"]
            else:
                where = list(range(len(data)))
            i = int(rng.choice(where))
            del data[i]
            intact = False
            # a lost delimiter glues the frame to the next one
            self._damage_next = not polled and i == len(frame) - 1
        elif r < f.garbage_prob + f.drop_prob + f.flip_prob:
            i = int(rng.integers(len(data)))
            data[i] ^= 1 << int(rng.integers(8))
            intact = False
            self._damage_next = not polled and i == len(frame) - 1
        return bytes(data), junk, intact

    def _queue(self, data: bytes, entry: SentFrame | None, since: float | None = None) -> None:
        """Send ``data`` (logged as ``entry``); ``since``: a polled reply's start (see
        :attr:`SentFrame.reply_s`; negative: it follows an earlier reply back to back)."""
        self._pending.append([data, entry, 0, since])
        self._pending_bytes += len(data)

    def _flush(self) -> None:
        master = self._master
        while self._pending and master is not None:
            item = self._pending[0]
            data, entry, done, since = item
            try:
                n = os.write(master, data[done:])
            except BlockingIOError:
                return
            item[2] = done + n
            self._pending_bytes -= n
            if item[2] < len(data):
                return
            self._pending.pop(0)
            if entry is not None:
                if since is not None:  # a polled reply, now wholly in the pty
                    entry = replace(entry, reply_s=math.inf if since < 0
                                    else time.monotonic() - since)
                self.sent.append(entry)
