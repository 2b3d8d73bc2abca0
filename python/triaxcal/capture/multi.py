"""Capture from several boards at once (a production rig with a USB hub): one thread per port.

Each port gets its own :class:`~triaxcal.io.serial.SerialReader` and its own
:func:`~triaxcal.capture.run.capture` running in a thread, writing its own session CSV, so
everything :func:`capture` promises holds per board: rows written as they arrive, a pulled
cable reported and waited for (the other boards carry on; the board that comes back resumes
into the same file), nothing already written ever lost. A board that cannot be started (port
missing, silent, wrong baud rate) is reported and left out; the others go on.

Session files are named after the board: before capturing, the host asks each board for its
serial number with the identify command, and falls back to the port's name
(``/dev/ttyUSB0`` -> ``ttyUSB0``) when the board does not answer.

The identify command (for firmware authors)
-------------------------------------------
The host sends ``P`` (stop streaming), waits 50 ms, discards what arrived, then sends one byte
``I`` (0x49). The board answers one ASCII line within ``id_timeout_s`` (0.5 s):

    ID:<serial>\\r\\n

``<serial>`` is 1 to 64 characters from ``A-Z a-z 0-9 . _ -`` (e.g. the MCU's unique id in
hex, or a number burnt into EEPROM at the factory). Anything else -- no answer, a longer or
malformed line -- is ignored and the port name is used. A board that does not know ``I``
must simply ignore the byte (the AVR firmware's command parser does). The simulated board
(:class:`triaxcal.sim.SimDevice`) answers it.
"""

from __future__ import annotations

import contextlib
import os
import re
import signal
import sys
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

import serial

from ..errors import CalibrationError
from ..io.serial import SerialReader
from .run import CaptureResult, capture

__all__ = [
    "ID_BYTE",
    "BoardCapture",
    "capture_many",
    "parse_id_reply",
    "port_label",
    "query_serial_number",
]

#: The identify command byte; the board answers ``ID:<serial>\r\n``.
ID_BYTE = b"I"
_ID_LINE = re.compile(rb"ID:([^\r\n]{0,200})\r?\n")
_SAFE_ID = re.compile(r"[A-Za-z0-9._-]{1,64}")


def parse_id_reply(data: bytes) -> str | None:
    """The serial number in a reply to ``I``, or ``None`` if there is no valid one.

    Only ``A-Z a-z 0-9 . _ -`` (1 to 64 characters) is accepted: the id becomes a file name.

    Examples
    --------
    >>> parse_id_reply(b"\\x00junk\\r\\nID:AB-0042\\r\\n")
    'AB-0042'
    >>> parse_id_reply(b"ID:../../etc/passwd\\r\\n") is None
    True
    """
    for m in _ID_LINE.finditer(data):
        text = m.group(1).decode("ascii", errors="replace").strip()
        if _SAFE_ID.fullmatch(text) and text not in (".", ".."):
            return text
    return None


def port_label(port: str) -> str:
    """A file-name-safe name for a port: ``/dev/ttyUSB0`` -> ``ttyUSB0``, ``COM3`` -> ``COM3``.

    Examples
    --------
    >>> port_label("/dev/serial/by-id/usb-FTDI_FT232R-if00:port0")
    'usb-FTDI_FT232R-if00_port0'
    """
    base = os.path.basename(str(port).rstrip("/\\")) or str(port)
    label = re.sub(r"[^A-Za-z0-9._-]", "_", base).strip(".")
    return label[:64] or "port"


def query_serial_number(
    port: str, *, baud: int = 115200, timeout_s: float = 0.5
) -> str | None:
    """Ask the board on ``port`` for its serial number (the ``I`` command); ``None`` if it
    does not answer with a valid one, or if the port cannot be opened (the capture reports
    that with the reason)."""
    try:
        link = serial.Serial(port, baud, timeout=0.02, write_timeout=1.0)
    except (serial.SerialException, OSError, ValueError):
        return None
    try:
        link.write(b"P")  # stop a streaming board so the reply is not buried in frames
        link.flush()
        time.sleep(0.05)
        link.reset_input_buffer()
        link.write(ID_BYTE)
        link.flush()
        data = bytearray()
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline and len(data) < 4096:
            data += link.read(max(1, link.in_waiting))
            found = parse_id_reply(bytes(data))
            if found is not None:
                return found
        return None
    except (serial.SerialException, OSError):
        return None
    finally:
        with contextlib.suppress(Exception):
            link.close()


@dataclass(frozen=True)
class BoardCapture:
    """What :func:`capture_many` did for one port.

    ``board_id`` names the session file ``<out_dir>/<board_id>.csv``; ``id_source`` is
    ``"serial"`` (the board answered ``I``) or ``"port"`` (fallback, or ``query_id=False``);
    ``result`` the :class:`~triaxcal.capture.run.CaptureResult` (``None`` when the capture could
    not start); ``error`` the reason it could not (``None`` otherwise).
    """

    port: str
    board_id: str
    id_source: str
    path: Path
    result: CaptureResult | None
    error: str | None = None

    @property
    def ok(self) -> bool:
        return self.error is None


class _BoardStream:
    """A text stream for one :func:`capture`: keeps its status line, forwards its messages."""

    def __init__(self, label: str, emit: Callable[[str], None], bell: Callable[[], None]):
        self.label = label
        self.status = "starting"
        self._emit = emit
        self._bell = bell
        self._buf = ""

    def write(self, text: str) -> int:
        if "\a" in text:
            self._bell()
            text = text.replace("\a", "")
        self._buf += text
        while True:
            i_r, i_n = self._buf.find("\r"), self._buf.find("\n")
            cuts = [i for i in (i_r, i_n) if i >= 0]
            if not cuts:
                break
            i = min(cuts)
            piece, sep, self._buf = self._buf[:i], self._buf[i], self._buf[i + 1:]
            if sep == "\n" and piece.strip():
                self._emit(f"{self.label}: {piece.strip()}")
            elif piece.strip():
                self.status = piece.strip()
        return len(text)

    def flush(self) -> None:
        return None


class _Display:
    """One status line per board; redrawn in place on a terminal, printed at the end else."""

    def __init__(self, stream: TextIO | None, bell: bool) -> None:
        self.stream = stream
        self.bell = bell
        self.tty = bool(stream is not None and getattr(stream, "isatty", lambda: False)())
        self.boards: list[_BoardStream] = []
        self.drawn = 0
        self.lock = threading.Lock()

    def message(self, text: str) -> None:
        if self.stream is None:
            return
        with self.lock:
            self._clear()
            self.stream.write(text + "\n")
            self._draw()

    def ring(self) -> None:
        if self.stream is not None and self.bell:
            with self.lock:
                self.stream.write("\a")
                self.stream.flush()

    def _lines(self, *, full: bool = False) -> list[str]:
        width = max((len(b.label) for b in self.boards), default=0)
        lines = [f"{b.label:<{width}}  {b.status}" for b in self.boards]
        # a wrapped line would break the redraw: cut at the terminal's width
        if self.tty and not full:
            try:
                cols = os.get_terminal_size(self.stream.fileno()).columns  # type: ignore[union-attr]
            except (OSError, ValueError, AttributeError):
                cols = 100
            lines = [ln[: max(20, cols - 1)] for ln in lines]
        return lines

    def _clear(self) -> None:
        if self.tty and self.drawn and self.stream is not None:
            self.stream.write(f"\x1b[{self.drawn}F\x1b[J")
            self.drawn = 0

    def _draw(self) -> None:
        if self.tty and self.stream is not None:
            lines = self._lines()
            self.stream.write("".join(line + "\n" for line in lines))
            self.drawn = len(lines)
            self.stream.flush()

    def refresh(self) -> None:
        if self.stream is None or not self.tty:
            return
        with self.lock:
            self._clear()
            self._draw()

    def end(self) -> None:
        if self.stream is None:
            return
        with self.lock:
            self._clear()
            for line in self._lines(full=True):
                self.stream.write(line + "\n")
            self.stream.flush()


def _unique(name: str, taken: set[str]) -> str:
    if name not in taken:
        return name
    k = 2
    while f"{name}-{k}" in taken:
        k += 1
    return f"{name}-{k}"


def capture_many(
    ports: Sequence[str],
    out_dir: Any,
    *,
    protocol: str = "framed",
    channels: int | None = None,
    query_id: bool = True,
    id_timeout_s: float = 0.5,
    reader_options: dict[str, Any] | None = None,
    samples: int | None = None,
    poses: int | None = None,
    duration_s: float | None = None,
    stop: threading.Event | None = None,
    mode: str = "new",
    progress: TextIO | None = sys.stderr,
    bell: bool = True,
    handle_sigint: bool = True,
    **capture_options: Any,
) -> tuple[BoardCapture, ...]:
    """Capture from every port in ``ports`` at once, one session CSV per board.

    Parameters
    ----------
    ports : sequence of str
        Serial ports (``/dev/ttyUSB0``, ``COM3``, ...), each given once.
    out_dir : str or Path
        Folder for the session files ``<board id>.csv`` (made if missing).
    protocol, channels
        As for :class:`~triaxcal.io.serial.SerialReader`, the same for every board.
    query_id : bool
        Ask each board for its serial number (``I``, see the module notes) to name its file;
        ``False`` (or a board that does not answer) names it after the port. Two boards with
        the same name get ``-2``, ``-3``, ... appended.
    id_timeout_s : float
        Longest wait for the reply to ``I``.
    reader_options : dict, optional
        More keyword arguments for every :class:`SerialReader` (``baud``, ``stream``,
        ``request_byte``, ``switch_mode``, ``poll_interval_s``, ``silent_s`` ...). Readers
        always wait for a pulled cable to come back.
    samples, poses, duration_s : optional
        Per-board stop conditions (as :func:`capture`); the call returns when every board
        has stopped.
    stop : threading.Event, optional
        Set it to stop every board.
    mode : {"new", "append", "overwrite"}
        What to do with an existing session file.
    progress : text stream or None
        Where the status lines go: one per board, redrawn in place on a terminal; the reader's
        messages are printed with the board's name in front.
    bell : bool
        Ring the bell when any board registers a pose.
    handle_sigint : bool
        Turn the first Ctrl-C into a clean stop of every board (main thread only).
    **capture_options
        Passed on to every :func:`capture` (``accel_columns``, ``units_per_g``, ``window``,
        ``hold_windows``, ``threshold_g``, ``columns``).

    Returns
    -------
    tuple of BoardCapture
        In the order of ``ports``.
    """
    ports = [str(p) for p in ports]
    if not ports:
        raise CalibrationError("give at least one --port")
    if len(set(ports)) != len(ports):
        dup = sorted({p for p in ports if ports.count(p) > 1})
        raise CalibrationError(f"port(s) given twice: {', '.join(dup)}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    opts = dict(reader_options or {})
    opts["reconnect"] = True
    opts.setdefault("reconnect_timeout_s", None)
    switch = opts.get("switch_mode", True)
    baud = int(opts.get("baud", 115200))
    stop_event = stop if stop is not None else threading.Event()

    names: list[tuple[str, str]] = []
    taken: set[str] = set()
    for port in ports:
        sn = query_serial_number(port, baud=baud, timeout_s=id_timeout_s) if (
            query_id and switch) else None
        name, source = (sn, "serial") if sn else (port_label(port), "port")
        name = _unique(name, taken)
        taken.add(name)
        names.append((name, source))

    display = _Display(progress, bell)
    results: list[BoardCapture | None] = [None] * len(ports)

    def run(i: int) -> None:
        port, (name, source) = ports[i], names[i]
        path = out / f"{name}.csv"
        board = display.boards[i]
        try:
            reader = SerialReader(port, protocol=protocol, channels=channels, **opts)
            res = capture(
                reader, path, samples=samples, poses=poses, duration_s=duration_s,
                stop=stop_event, mode=mode, progress=board,  # type: ignore[arg-type]
                bell=True, handle_sigint=False, **capture_options,
            )
            results[i] = BoardCapture(port, name, source, path, res)
            board.status = f"done: {res.samples} rows, {len(res.poses)} poses -> {path}"
        except CalibrationError as exc:
            results[i] = BoardCapture(port, name, source, path, None, str(exc))
            board.status = f"FAILED: {exc}"
            display.message(f"{name}: {exc}")
        except Exception as exc:  # noqa: BLE001 - one board's bug must not stop the others
            results[i] = BoardCapture(port, name, source, path, None, repr(exc))
            board.status = f"FAILED: {exc!r}"
            display.message(f"{name}: {exc!r}")

    for i, port in enumerate(ports):
        name, source = names[i]
        label = f"{name} ({port})" if source == "serial" else name
        display.boards.append(_BoardStream(label, display.message, display.ring))
    threads = [threading.Thread(target=run, args=(i,), name=f"capture-{names[i][0]}",
                                daemon=True) for i in range(len(ports))]
    interrupted = False

    def on_sigint(signum: int, frame: Any) -> None:
        nonlocal interrupted
        if interrupted:
            raise KeyboardInterrupt
        interrupted = True
        stop_event.set()

    use_sigint = handle_sigint and threading.current_thread() is threading.main_thread()
    old = signal.signal(signal.SIGINT, on_sigint) if use_sigint else None
    try:
        for t in threads:
            t.start()
        while any(t.is_alive() for t in threads):
            for t in threads:
                t.join(timeout=0.2 / len(threads))
            display.refresh()
    finally:
        if use_sigint:
            signal.signal(signal.SIGINT, old)
    display.end()
    return tuple(r for r in results if r is not None)
