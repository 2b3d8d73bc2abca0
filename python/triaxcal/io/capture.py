"""Guided capture: records from a :class:`~triaxcal.io.serial.SerialReader` into a session CSV.

The session file is written as data arrives, so nothing captured is lost: a header row
``t,<channel names>``, then one row per record, ``t`` the host time in seconds
(``time.time()``, Unix epoch, microseconds) at which the record arrived and the values exactly
as received (integers for counts). Rows are written whole, flushed after every batch and
``fsync``-ed at least once a second; Ctrl-C (SIGINT) ends the capture between two batches.

While capturing, an online :class:`~triaxcal.detect.PoseDetector` on the accelerometer
columns registers still poses; each one rings the terminal bell, and a status line shows the
samples, the poses, the share of the sphere of directions covered so far (equal-area cells
hit) and which way to turn the board next.
"""

from __future__ import annotations

import contextlib
import math
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from ..detect import Pose, PoseDetector
from ..errors import CalibrationError
from ..units import DEVICE_COUNTS_PER_UNIT
from .protocol import CHANNELS_7, CHANNELS_10
from .serial import ReaderStats, Record, SerialReader

ACCEL_COUNTS_PER_G = DEVICE_COUNTS_PER_UNIT["accel"][0]

__all__ = [
    "CaptureResult",
    "SessionWriter",
    "capture",
    "channel_names",
    "coverage",
    "read_session",
    "sphere_cells",
    "suggest_turn",
]

#: Counts per g of the accelerometer columns, per protocol (``Raw:`` is 8192 counts/g).
UNITS_PER_G = {"binary": ACCEL_COUNTS_PER_G, "framed": ACCEL_COUNTS_PER_G,
               "text": ACCEL_COUNTS_PER_G, "raw": 8192.0}


def channel_names(protocol: str, channels: int | None) -> tuple[str, ...]:
    """Column names for K channels in device order.

    K=10: ``ax ay az gx gy gz mx my mz temp``; K=9 (and ``raw``): ``ax .. mz``; K=7 (AVR,
    MPU-6050): ``ax ay az gx gy gz temp``; K=6: ``ax .. gz``; K=3: ``ax ay az``; other K:
    ``c0 .. c{K-1}``.

    Examples
    --------
    >>> channel_names("binary", 7)
    ('ax', 'ay', 'az', 'gx', 'gy', 'gz', 'temp')
    """
    if protocol == "raw":
        return CHANNELS_10[:9]
    if channels is None:
        raise CalibrationError(f"the {protocol} session needs a channel count (--channels K)")
    named = {10: CHANNELS_10, 9: CHANNELS_10[:9], 7: CHANNELS_7, 6: CHANNELS_10[:6],
             3: CHANNELS_10[:3]}
    return named.get(int(channels), tuple(f"c{i}" for i in range(int(channels))))


def _fmt(v: Any) -> str:
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    return repr(float(v))


class SessionWriter:
    """Append records to a session CSV as they arrive; nothing written is ever lost.

    Parameters
    ----------
    path : str or Path
        The CSV file.
    columns : sequence of str
        Channel names (the ``t`` column is added in front).
    mode : {"new", "append", "overwrite"}
        ``new`` refuses an existing non-empty file; ``append`` continues one whose header
        matches; ``overwrite`` replaces it.
    fsync_s : float
        Longest time between ``os.fsync`` calls (rows are flushed to the OS on every write).
    """

    def __init__(
        self, path: Any, columns: Sequence[str], *, mode: str = "new", fsync_s: float = 1.0
    ) -> None:
        self.path = Path(path)
        self.columns = ("t", *columns)
        self.k = len(columns)
        self.fsync_s = float(fsync_s)
        self.rows = 0
        header = ",".join(self.columns)
        exists = self.path.exists() and self.path.stat().st_size > 0
        if mode not in ("new", "append", "overwrite"):
            raise CalibrationError(f"mode must be 'new', 'append' or 'overwrite', got {mode!r}")
        if exists and mode == "new":
            raise CalibrationError(
                f"{self.path} exists already: pass another --out, or --append to add to it, "
                "or --overwrite to replace it"
            )
        if exists and mode == "append":
            with open(self.path, encoding="ascii", errors="replace") as f:
                first = f.readline().strip()
            if first != header:
                raise CalibrationError(
                    f"cannot append to {self.path}: its header {first!r} differs from "
                    f"{header!r} (other protocol or channel count?)"
                )
            self._f: TextIO = open(self.path, "a", encoding="ascii", newline="")  # noqa: SIM115
            self._ensure_newline()
        else:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._f = open(self.path, "w", encoding="ascii", newline="")  # noqa: SIM115
            self._f.write(header + "\n")
        self._flush(force=True)

    def _ensure_newline(self) -> None:
        with open(self.path, "rb") as f:
            f.seek(-1, os.SEEK_END)
            last = f.read(1)
        if last != b"\n":  # a row cut by a crash: end it, readers skip short rows
            self._f.write("\n")

    def write(self, records: Iterable[Record]) -> int:
        """Write rows for ``records`` (host time, values), flush; returns rows written."""
        lines = []
        for t, values in records:
            if len(values) != self.k:
                continue  # a decoder never returns these; be safe with hand-made records
            lines.append(f"{t:.6f}," + ",".join(_fmt(v) for v in values) + "\n")
        if lines:
            self._f.write("".join(lines))
            self.rows += len(lines)
            self._flush()
        return len(lines)

    def _flush(self, force: bool = False) -> None:
        self._f.flush()
        now = time.monotonic()
        if force or now - getattr(self, "_synced", 0.0) >= self.fsync_s:
            with contextlib.suppress(OSError):
                os.fsync(self._f.fileno())
            self._synced = now

    def close(self) -> None:
        """Flush, fsync and close (idempotent)."""
        if not self._f.closed:
            self._flush(force=True)
            self._f.close()

    def __enter__(self) -> SessionWriter:  # noqa: PYI034
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def read_session(path: Any) -> tuple[tuple[str, ...], np.ndarray]:
    """Read a session CSV: ``(columns, data)`` with ``data`` float64 of shape (N, 1 + K).

    Rows with a wrong number of fields (a row cut by a power cut) are skipped.
    """
    with open(path, encoding="ascii", errors="replace") as f:
        header = f.readline().strip().split(",")
        if not header or header[0] != "t":
            raise CalibrationError(f"{path} is not a session CSV: its first column must be 't'")
        rows = []
        for line in f:
            parts = line.strip().split(",")
            if len(parts) != len(header):
                continue
            try:
                rows.append([float(p) for p in parts])
            except ValueError:
                continue
    return tuple(header), np.array(rows, dtype=np.float64).reshape(-1, len(header))


# ------------------------------------------------------------------------- sphere coverage


def sphere_cells(bands: int = 4, sectors: int = 6) -> np.ndarray:
    """Unit vectors (bands*sectors, 3) at the centres of equal-area cells of the sphere.

    Cells are ``bands`` zones of equal height in z (equal area, Archimedes' hat-box theorem)
    times ``sectors`` equal slices of longitude.
    """
    z = 1.0 - (np.arange(bands) + 0.5) * 2.0 / bands
    lon = (np.arange(sectors) + 0.5) * 2.0 * math.pi / sectors
    zz, ll = np.meshgrid(z, lon, indexing="ij")
    r = np.sqrt(1.0 - zz**2)
    return np.stack([r * np.cos(ll), r * np.sin(ll), zz], axis=-1).reshape(-1, 3)


def _cell_index(dirs: np.ndarray, bands: int, sectors: int) -> np.ndarray:
    u = dirs / np.maximum(np.linalg.norm(dirs, axis=1, keepdims=True), 1e-300)
    band = np.clip(((1.0 - u[:, 2]) * bands / 2.0).astype(int), 0, bands - 1)
    lon = np.mod(np.arctan2(u[:, 1], u[:, 0]), 2.0 * math.pi)
    sector = np.clip((lon * sectors / (2.0 * math.pi)).astype(int), 0, sectors - 1)
    return band * sectors + sector


def coverage(points: Any, *, center: Any = None, bands: int = 4, sectors: int = 6) -> float:
    """Fraction (0..1) of the equal-area cells of :func:`sphere_cells` hit by ``points``.

    ``points`` (N, 3) are readings (e.g. pose means of the accelerometer); their directions
    from ``center`` (default: the origin, fine for raw counts whose offset is small compared
    with the radius) pick the cells.

    Examples
    --------
    >>> coverage([[0, 0, 1], [0, 0, -1]])
    0.08333333333333333
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(pts) == 0:
        return 0.0
    if center is not None:
        pts = pts - np.asarray(center, dtype=np.float64)
    hit = np.unique(_cell_index(pts, bands, sectors))
    return len(hit) / (bands * sectors)


_AXES = ("X", "Y", "Z")


def _describe(d: np.ndarray) -> str:
    """Words for 'this body direction points up': '+Z up', '+X and -Z up'."""
    order = np.argsort(-np.abs(d))
    main = [order[0]]
    if abs(d[order[1]]) > 0.5 * abs(d[order[0]]):
        main.append(order[1])
    parts = [("+" if d[i] > 0 else "-") + _AXES[i] for i in main]
    return " and ".join(parts) + " up"


def suggest_turn(
    points: Any, current: Any = None, *, bands: int = 4, sectors: int = 6
) -> str:
    """Which way to turn the board next, in words, towards the emptiest part of the sphere.

    Parameters
    ----------
    points : array_like (N, 3)
        Accelerometer readings of the poses so far (any units; the direction matters).
    current : array_like (3,), optional
        The accelerometer reading now (default: the last point).

    Returns
    -------
    str
        E.g. ``"turn it upside down (-Z and +X up)"``, ``"tilt the +X side up (+X up)"``, or
        ``"every direction covered"``.

    Examples
    --------
    >>> suggest_turn([[0, 0, 1.0]])
    'turn it upside down (-Z and +X up)'
    >>> suggest_turn([[0, 0, 1.0], [0, 0, -1.0]], [0, 0, 1.0])
    'tilt the +X side up (+X and +Y up)'
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    cells = sphere_cells(bands, sectors)
    if len(pts):
        hit = set(np.unique(_cell_index(pts, bands, sectors)).tolist())
        u = pts / np.maximum(np.linalg.norm(pts, axis=1, keepdims=True), 1e-300)
        # the empty cell farthest from every pose
        empty = [i for i in range(len(cells)) if i not in hit]
        if not empty:
            return "every direction covered: add poses anywhere or stop"
        cand = cells[empty]
        gap = (cand @ u.T).max(axis=1)
        target = cand[int(np.argmin(gap))]
    else:
        target = np.array([0.0, 0.0, 1.0])
    now = np.asarray(current, dtype=np.float64) if current is not None else (
        pts[-1] if len(pts) else np.array([0.0, 0.0, 1.0])
    )
    now = now / max(float(np.linalg.norm(now)), 1e-300)
    # snap the target to the nearest axis or axis pair, which is easier to aim for
    aim = _describe(target)
    if not len(pts):
        return "hold it still to register the first pose"
    if float(now @ target) > 0.9:
        return f"hold it still here ({aim})"
    if float(now @ target) < -0.7:
        return f"turn it upside down ({aim})"
    push = target - now * float(now @ target)  # the side that must rise
    i = int(np.argmax(np.abs(push)))
    side = ("+" if push[i] > 0 else "-") + _AXES[i]
    other = ("-" if push[i] > 0 else "+") + _AXES[i]
    if abs(push[i]) < 1e-9:
        return f"turn it to {aim}"
    if push[i] > 0:
        return f"tilt the {side} side up ({aim})"
    return f"tilt the {other} side down ({aim})"


# --------------------------------------------------------------------------------- capture


@dataclass(frozen=True)
class CaptureResult:
    """What :func:`capture` did.

    ``path`` the session CSV; ``samples`` rows written; ``poses`` registered still poses
    (means over all channels, sample indices into the session's rows); ``coverage`` fraction
    of the sphere cells hit; ``stopped_by`` one of ``"samples"``, ``"poses"``,
    ``"duration"``, ``"stop"``, ``"interrupt"``; ``elapsed_s``; ``stats`` the reader's
    counters; ``events`` the (kind, message) pairs the reader reported.
    """

    path: Path
    samples: int
    poses: tuple[Pose, ...]
    coverage: float
    stopped_by: str
    elapsed_s: float
    stats: ReaderStats
    events: tuple[tuple[str, str], ...] = field(default=())


class _Status:
    """The one-line progress display (carriage return, no dependencies)."""

    def __init__(self, stream: TextIO | None, bell: bool) -> None:
        self.stream = stream
        self.bell = bell
        self.last = 0.0
        self.width = 0

    def line(self, text: str, *, force: bool = False) -> None:
        if self.stream is None:
            return
        now = time.monotonic()
        if not force and now - self.last < 0.2:
            return
        self.last = now
        pad = max(0, self.width - len(text))
        self.stream.write("\r" + text + " " * pad)
        self.width = len(text)
        self.stream.flush()

    def message(self, text: str) -> None:
        if self.stream is None:
            return
        if self.width:
            self.stream.write("\r" + " " * self.width + "\r")
            self.width = 0
        self.stream.write(text + "\n")
        self.stream.flush()

    def ring(self) -> None:
        if self.stream is not None and self.bell:
            self.stream.write("\a")
            self.stream.flush()

    def end(self) -> None:
        if self.stream is not None and self.width:
            self.stream.write("\n")
            self.stream.flush()
            self.width = 0


@contextlib.contextmanager
def _sigint_to_flag(flag: threading.Event, enabled: bool) -> Any:
    """First Ctrl-C sets ``flag`` (a clean stop between batches); a second one raises."""
    if not enabled or threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum: int, frame: Any) -> None:
        if flag.is_set():
            raise KeyboardInterrupt
        flag.set()

    old = signal.signal(signal.SIGINT, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old)


def capture(
    reader: SerialReader,
    out: Any,
    *,
    samples: int | None = None,
    poses: int | None = None,
    duration_s: float | None = None,
    stop: threading.Event | None = None,
    mode: str = "new",
    columns: Sequence[str] | None = None,
    accel_columns: Sequence[int] = (0, 1, 2),
    units_per_g: float | None = None,
    window: int = 25,
    hold_windows: int = 4,
    threshold_g: float = 0.07,
    progress: TextIO | None = sys.stderr,
    bell: bool = True,
    handle_sigint: bool = True,
    on_records: Callable[[list[Record]], None] | None = None,
) -> CaptureResult:
    """Capture records from ``reader`` into the session CSV ``out`` until told to stop.

    Parameters
    ----------
    reader : SerialReader
        Opened here if it is not open yet; closed at the end.
    out : str or Path
        Session CSV (see :class:`SessionWriter`).
    samples, poses, duration_s : optional
        Stop after this many rows, registered poses, or seconds. With none of them (and no
        ``stop``) the capture runs until Ctrl-C.
    stop : threading.Event, optional
        Set it to stop; when streaming, the bytes already on their way are read first (until
        0.3 s pass with no record).
    mode : {"new", "append", "overwrite"}
        What to do with an existing ``out``.
    columns : sequence of str, optional
        Channel names (default :func:`channel_names`).
    accel_columns : 3 ints
        Channels of the accelerometer, for pose detection and coverage.
    units_per_g : float, optional
        Accelerometer counts per g (default 16384, or 8192 for ``raw``).
    window, hold_windows, threshold_g
        Pose detection (:class:`~triaxcal.detect.PoseDetector`): samples per averaging
        window; a pose is registered (and the bell rings) after ``hold_windows`` steady
        windows; steady means every axis of the window mean moved by at most
        ``threshold_g`` g (the seed's 0.07 g).
    progress : text stream or None
        Where the status line goes (``None``: silent).
    bell : bool
        Ring the terminal bell (``\\a``) on each registered pose.
    handle_sigint : bool
        Turn the first Ctrl-C into a clean stop (main thread only).
    on_records : callable(records), optional
        Called in the capture loop with every non-empty batch of records, right after they
        were written to the session (the live page, :mod:`triaxcal.live`, watches the stream
        this way). It must return quickly; an exception it raises ends the capture.

    Returns
    -------
    CaptureResult
    """
    for name, v in (("samples", samples), ("poses", poses)):
        if v is not None and (isinstance(v, bool) or not isinstance(v, int) or v < 1):
            raise CalibrationError(f"{name} must be a whole number >= 1, got {v!r}")
    upg = float(units_per_g) if units_per_g is not None else UNITS_PER_G[reader.protocol]
    names = tuple(columns) if columns is not None else channel_names(
        reader.protocol, reader.channels
    )
    events: list[tuple[str, str]] = []
    status = _Status(progress, bell)
    user_event = reader.on_event

    def on_event(kind: str, msg: str) -> None:
        events.append((kind, msg))
        status.message(f"triaxcal capture: {msg}")
        if user_event is not None:
            user_event(kind, msg)

    reader.on_event = on_event
    detect = len(names) >= 3 and max(accel_columns) < len(names)
    detector = PoseDetector(
        window=window, threshold=threshold_g * upg, units_per_g=upg,
        max_windows=max(2, hold_windows), columns=tuple(accel_columns),
    ) if detect else None
    registered: list[Pose] = []
    interrupted = threading.Event()
    t0 = time.monotonic()
    stopped_by = "interrupt"
    last = None
    if not reader.is_open:
        reader.open()  # a missing port is reported before any file is made
    try:
        writer = SessionWriter(out, names, mode=mode)
    except BaseException:
        reader.close()
        reader.on_event = user_event
        raise
    try:
        with _sigint_to_flag(interrupted, handle_sigint):
            quiet_since = None
            while True:
                if interrupted.is_set():
                    stopped_by = "interrupt"
                    break
                if duration_s is not None and time.monotonic() - t0 >= duration_s:
                    stopped_by = "duration"
                    break
                recs = reader.read()
                if samples is not None:
                    recs = recs[: samples - writer.rows]
                writer.write(recs)
                if recs and on_records is not None:
                    on_records(recs)
                if recs and detector is not None:
                    vals = np.array([r.values for r in recs], dtype=np.float64)
                    last = vals[-1, list(accel_columns)]
                    for p in detector.update(vals):
                        registered.append(p)
                        status.ring()
                if samples is not None and writer.rows >= samples:
                    stopped_by = "samples"
                    break
                if poses is not None and len(registered) >= poses:
                    stopped_by = "poses"
                    break
                if stop is not None and stop.is_set():
                    if reader.polled:  # nothing is in flight between requests
                        stopped_by = "stop"
                        break
                    if recs:
                        quiet_since = None
                    elif quiet_since is None:
                        quiet_since = time.monotonic()
                    elif time.monotonic() - quiet_since > 0.3:
                        stopped_by = "stop"
                        break
                status.line(_status_text(writer.rows, registered, accel_columns, last,
                                         reader, poses, samples))
    except KeyboardInterrupt:
        stopped_by = "interrupt"
    except BaseException:
        # a failed start (silent board, wrong baud rate) leaves no empty session behind that
        # would block running the same command again
        writer.close()
        if writer.rows == 0 and mode != "append":
            with contextlib.suppress(OSError):
                writer.path.unlink()
        status.end()
        raise
    finally:
        writer.close()
        reader.close()
        reader.on_event = user_event
    cov = coverage([p.mean[list(accel_columns)] for p in registered]) if registered else 0.0
    status.line(_status_text(writer.rows, registered, accel_columns, last, reader, poses,
                             samples), force=True)
    status.end()
    return CaptureResult(
        path=writer.path,
        samples=writer.rows,
        poses=tuple(registered),
        coverage=cov,
        stopped_by=stopped_by,
        elapsed_s=time.monotonic() - t0,
        stats=reader.stats,
        events=tuple(events),
    )


def _status_text(
    rows: int,
    registered: list[Pose],
    cols: Sequence[int],
    last: Any,
    reader: SerialReader,
    want_poses: int | None,
    want_samples: int | None,
) -> str:
    pts = np.array([p.mean[list(cols)] for p in registered]).reshape(-1, 3)
    cov = coverage(pts) if len(pts) else 0.0
    s = f"{rows}" + (f"/{want_samples}" if want_samples else "") + " samples"
    s += f"  {len(registered)}" + (f"/{want_poses}" if want_poses else "") + " poses"
    s += f"  sphere {100 * cov:.0f}%"
    dropped = reader.stats.dropped
    if dropped:
        s += f"  dropped {dropped}"
    if not reader.connected:
        s += "  [disconnected]"
    elif last is not None or len(pts):
        s += f"  next: {suggest_turn(pts, last)}"
    return s
