"""Guided capture: records from a :class:`~triaxcal.io.serial.SerialReader` into a session CSV.

The session file is written as data arrives, so nothing captured is lost: a header row
``t,<channel names>``, then one row per record, ``t`` the host time in seconds
(``time.time()``, Unix epoch, microseconds) at which the record arrived and the values exactly
as received (integers for counts). Rows are written whole, flushed after every batch and
``fsync``-ed at least once a second; Ctrl-C (SIGINT) ends the capture between two batches.

While capturing, an online :class:`~triaxcal.detect.PoseDetector` with every sensor the
session has (:class:`~triaxcal.detect.session.PoseSettings`: the same detection as ``triaxcal fit
--poses`` and ``report`` run on the saved file) registers still poses; each one rings the
terminal bell, and a status line shows the samples, the poses, the share of the sphere of
directions covered so far (:mod:`triaxcal.quality.coverage`, the measure every command uses) and
which way to turn the board next.

When the board finds the poses itself (a :class:`~triaxcal.io.serial.SerialReader` with
``board_poses``: the firmware's mode ``S``), every record is one pose and is written as one
row, the channel means followed by ``pose_n``, the samples the board averaged; that column
tells ``triaxcal fit`` and ``report`` that the rows are pose means already.
"""

from __future__ import annotations

import contextlib
import errno
import os
import signal
import stat
import sys
import threading
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, BinaryIO, TextIO

import numpy as np

from ..detect import Pose, PoseDetector
from ..detect.session import HEAD_ROWS, POSE_N_COLUMN, PoseSettings, ResolvedPoses
from ..errors import CalibrationError
from ..io.board_poses import BoardPoseSettings
from ..io.files import os_error_message
from ..io.protocol import CHANNELS_7, CHANNELS_10
from ..io.serial import ReaderStats, Record, SerialReader
from ..quality.coverage import coverage, suggest_turn

__all__ = [
    "POSE_N_COLUMN",
    "CaptureResult",
    "SessionWriteError",
    "SessionWriter",
    "capture",
    "channel_names",
    "read_session",
]


#: The column of a session whose rows are the board's pose means (samples averaged per row).


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


class SessionWriteError(CalibrationError):
    """The session file could not be written (a full disk, a file size limit, a read-only
    or vanished place). ``rows`` whole rows are safe in ``path``; the capture stopped."""

    def __init__(self, message: str, *, path: Path, rows: int) -> None:
        super().__init__(message)
        self.path = path
        self.rows = rows


# fsync is not possible on some files (pipes, some devices); that is no reason to stop.
_FSYNC_UNSUPPORTED = {errno.EINVAL, errno.EROFS, errno.ENOTSUP,
                      getattr(errno, "EOPNOTSUPP", errno.ENOTSUP)}


class SessionWriter:
    """Append records to a session CSV as they arrive; nothing written is ever lost.

    Rows are written whole: when the disk fills up (or the file cannot grow for another
    reason) the file is cut back to the end of the last whole row and
    :class:`SessionWriteError` says how many rows are safe in it. Opening a session to
    append to it first removes a row cut short by an earlier crash.

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
        self.created = False  # whether this writer made the file (so may remove it)
        self._failed = False
        self._synced = 0.0
        header = ",".join(self.columns)
        if mode not in ("new", "append", "overwrite"):
            raise CalibrationError(f"mode must be 'new', 'append' or 'overwrite', got {mode!r}")
        try:
            st = os.stat(self.path) if self.path.exists() else None
            regular = st is None or stat.S_ISREG(st.st_mode)
            exists = st is not None and regular and st.st_size > 0
            if st is not None and stat.S_ISDIR(st.st_mode):
                raise CalibrationError(
                    f"{self.path} is a folder: give a file name inside it, e.g. "
                    f"{self.path / 'session.csv'}"
                )
            if exists and mode == "new":
                raise CalibrationError(
                    f"{self.path} exists already: pass another --out, or --append to add to "
                    "it, or --overwrite to replace it"
                )
            if exists and mode == "append":
                with open(self.path, encoding="ascii", errors="replace") as f:
                    first = f.readline(65536).strip()
                if first != header:
                    raise CalibrationError(
                        f"cannot append to {self.path}: its header {first[:200]!r} differs "
                        f"from {header!r} (other protocol or channel count?)"
                    )
                self._good = _drop_cut_row(self.path)
                self._f: BinaryIO = open(self.path, "ab")  # noqa: SIM115
            else:
                self.path.parent.mkdir(parents=True, exist_ok=True)
                self.created = st is None
                self._f = open(self.path, "wb")  # noqa: SIM115
                self._good = 0
                self._put((header + "\n").encode("ascii"))
        except OSError as exc:
            self._fail(exc)
        self._flush(force=True)

    def _put(self, data: bytes) -> None:
        """Write ``data`` (whole rows), flush, and count it as safe."""
        try:
            self._f.write(data)
            self._flush()
        except OSError as exc:
            self._fail(exc)
        self._good += len(data)

    def write(self, records: Iterable[Record]) -> int:
        """Write rows for ``records`` (host time, values), flush; returns rows written.

        Raises
        ------
        SessionWriteError
            When the rows cannot be written; the rows written before are safe.
        """
        if self._failed:
            raise CalibrationError(f"{self.path}: writing has stopped after an error")
        lines = []
        for t, values in records:
            if len(values) != self.k:
                continue  # a decoder never returns these; be safe with hand-made records
            lines.append(f"{t:.6f}," + ",".join(_fmt(v) for v in values) + "\n")
        if lines:
            self._put("".join(lines).encode("ascii"))
            self.rows += len(lines)
        return len(lines)

    def _flush(self, force: bool = False) -> None:
        if self._failed:
            return
        try:
            self._f.flush()
            now = time.monotonic()
            if force or now - self._synced >= self.fsync_s:
                try:
                    os.fsync(self._f.fileno())
                except OSError as exc:
                    if exc.errno not in _FSYNC_UNSUPPORTED:
                        raise
                self._synced = now
        except OSError as exc:
            self._fail(exc)

    def _fail(self, exc: OSError) -> None:
        """Close, cut the file back to its last whole row, and raise SessionWriteError."""
        self._failed = True
        f = getattr(self, "_f", None)
        if f is not None:
            with contextlib.suppress(OSError):
                f.close()  # may try (and fail) to write what is still buffered
        cut = False
        good = getattr(self, "_good", 0)
        with contextlib.suppress(OSError):
            if stat.S_ISREG(os.stat(self.path).st_mode):
                if os.stat(self.path).st_size > good:
                    os.truncate(self.path, good)
                cut = True
        if self.rows == 0:
            safe = "nothing was captured"
        else:
            safe = (f"the capture stopped; the first {self.rows} rows are safe in {self.path}"
                    + ("" if cut else " (its last row may be cut short; triaxcal fit skips "
                                      "such a row)"))
        raise SessionWriteError(f"{os_error_message(exc, self.path)}; {safe}",
                                path=self.path, rows=self.rows) from None

    def close(self) -> None:
        """Flush, fsync and close (idempotent)."""
        if self._failed or self._f.closed:
            return
        self._flush(force=True)
        try:
            self._f.close()
        except OSError as exc:
            self._fail(exc)

    def __enter__(self) -> SessionWriter:  # noqa: PYI034
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _drop_cut_row(path: Path) -> int:
    """Cut a regular file back to its last line break (a row cut short by a crash); returns
    the new size."""
    with open(path, "rb+") as f:
        size = f.seek(0, os.SEEK_END)
        pos = size
        while pos > 0:
            step = min(65536, pos)
            f.seek(pos - step)
            chunk = f.read(step)
            i = chunk.rfind(b"\n")
            if i >= 0:
                end = pos - step + i + 1
                if end < size:
                    f.truncate(end)
                return end
            pos -= step
        return size


def read_session(path: Any) -> tuple[tuple[str, ...], np.ndarray]:
    """Read a session CSV: ``(columns, data)`` with ``data`` float64 of shape (N, 1 + K).

    Rows that are not whole (a row cut by a power cut or a full disk) are skipped; see
    :func:`triaxcal.io.tables.read_table` for a reader that reports them.
    """
    from ..io.tables import read_table

    table = read_table(path, skip_bad_lines=True, allow_empty=True)
    if not table.names or table.names[0] != "t":
        raise CalibrationError(f"{path} is not a session CSV: its first column must be 't'")
    return table.names, table.data


# --------------------------------------------------------------------------------- capture


@dataclass(frozen=True)
class CaptureResult:
    """What :func:`capture` did.

    ``path`` the session CSV; ``samples`` rows written; ``poses`` registered still poses
    (means over all channels, sample indices into the session's rows); ``coverage`` fraction
    of the sphere cells hit; ``stopped_by`` one of ``"samples"``, ``"poses"``,
    ``"duration"``, ``"stop"``, ``"interrupt"``; ``elapsed_s``; ``stats`` the reader's
    counters; ``events`` the (kind, message) pairs the reader reported; ``detection`` the pose
    settings with the values the data decided (counts per g, sample rate), which replay the
    same poses on the saved session (:func:`triaxcal.detect.session.session_poses`); ``thresholds``
    each sensor's threshold in its raw units (learnt ones as learnt). When the board found the
    poses (``board_poses``), each pose is one row of the session (``start``, ``end`` are its
    row index and the next; ``n`` the samples the board averaged), ``detection`` is None and
    ``board_settings`` holds the settings the board reported.
    """

    path: Path
    samples: int
    poses: tuple[Pose, ...]
    coverage: float
    stopped_by: str
    elapsed_s: float
    stats: ReaderStats
    events: tuple[tuple[str, str], ...] = field(default=())
    detection: PoseSettings | None = None
    thresholds: dict[str, float | None] = field(default_factory=dict)
    board_settings: BoardPoseSettings | None = None


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
    accel_columns: Sequence[int] | None = None,
    units_per_g: float | None = None,
    window: int = 25,
    hold_windows: int = 4,
    threshold_g: float = 0.07,
    detection: PoseSettings | None = None,
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
    accel_columns : 3 ints, optional
        Channels of the accelerometer, for pose detection and coverage (default: the ones
        named ``ax ay az``, else the first three).
    units_per_g, window, threshold_g, hold_windows
        Shorthands for ``detection`` (:class:`~triaxcal.detect.session.PoseSettings`
        ``counts_per_g`` -- default: from the first readings --, ``window``, ``accel_threshold_g``
        and ``hold_windows``: a pose is registered, and the bell rings, once it has been still for
        that many windows), used when ``detection`` is not given.
    detection : PoseSettings, optional
        Pose detection: a pose ends when any sensor of the session says the board moved (the
        same settings give the same poses in ``triaxcal fit --poses`` on the saved file).
        The detector starts once the first :data:`~triaxcal.detect.session.HEAD_ROWS` rows are in
        (they fix the counts per g and, for a hold-off, the sample rate).
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
    settings = detection if detection is not None else PoseSettings(
        window=window, accel_threshold_g=threshold_g, counts_per_g=units_per_g,
        hold_windows=max(2, int(hold_windows)))
    cols = tuple(accel_columns) if accel_columns is not None else None
    if cols is None and not all(c in names for c in ("ax", "ay", "az")):
        cols = (0, 1, 2)
    board = getattr(reader, "board_poses", None) is not None
    live: _LivePoses | _BoardPoses | None
    if board:
        if not names or names[-1] != POSE_N_COLUMN:
            names = (*names, POSE_N_COLUMN)
        live = _BoardPoses(names, reader, on_event)
    else:
        live = _LivePoses(settings, names, cols) if len(names) >= 3 else None
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
                if recs and live is not None:
                    for p in live.update(recs):
                        if poses is None or len(registered) < poses:
                            registered.append(p)
                            status.ring()
                    last = live.last
                if isinstance(live, _BoardPoses):
                    last = live.watch()
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
                status.line(_status_text(writer.rows, registered, live, last, reader, poses,
                                         samples))
    except KeyboardInterrupt:
        stopped_by = "interrupt"
    except BaseException:
        # a failed start (silent board, wrong baud rate) leaves no empty session behind that
        # would block running the same command again
        with contextlib.suppress(CalibrationError):
            writer.close()
        if writer.rows == 0 and writer.created and writer.path.is_file():
            with contextlib.suppress(OSError):
                writer.path.unlink()
        status.end()
        raise
    finally:
        writer.close()
        reader.close()
        reader.on_event = user_event
    if live is not None and stopped_by != "poses":
        # the end of the stream decides on the pose in progress
        registered += live.finish()[: None if poses is None else poses - len(registered)]
    if live is not None and live.det is not None:
        # the same poses, each averaged over its whole still run (the bell rang earlier)
        registered = live.det.poses[:len(registered)]
    if isinstance(live, _BoardPoses):
        live.watch()
    cov = (coverage(live.points(registered)).fraction if live is not None and registered
           else 0.0)
    status.line(_status_text(writer.rows, registered, live, last, reader, poses, samples),
                force=True)
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
        detection=live.settings if live is not None else None,
        thresholds=live.thresholds if live is not None else {},
        board_settings=live.board_settings if isinstance(live, _BoardPoses) else None,
    )


class _BoardPoses:
    """The board's own poses (firmware mode ``S``): every record is one pose, ``(*means, n)``."""

    det = None
    settings = None

    def __init__(self, names: Sequence[str], reader: SerialReader, on_event: Any) -> None:
        self.names = tuple(names)
        self.reader = reader
        self.on_event = on_event
        self.rows = 0
        self.last: np.ndarray | None = None
        self.board_settings: BoardPoseSettings | None = None
        self.thresholds: dict[str, float | None] = {}
        named = all(c in self.names for c in ("ax", "ay", "az"))
        self.accel_columns = tuple(self.names.index(c) for c in ("ax", "ay", "az")) if named \
            else (0, 1, 2)

    def update(self, recs: Sequence[Record]) -> list[Pose]:
        out = []
        for r in recs:
            if len(r.values) != len(self.names):
                continue
            mean = np.asarray(r.values[:-1], dtype=np.float64)
            out.append(Pose(start=self.rows, end=self.rows + 1, mean=mean, n=int(r.values[-1])))
            self.rows += 1
        return out

    def watch(self) -> np.ndarray | None:
        """Follow the board's status: its last window's accelerometer mean (for the next-turn
        hint) and the settings it reports (told once if they differ from those sent)."""
        dec = self.reader.decoder
        st = getattr(dec, "status", None)
        if st is not None:
            self.last = np.asarray(st.accel, dtype=np.float64)
        got = getattr(dec, "settings", None)
        if got is not None and got != self.board_settings:
            self.board_settings = got
            sent = self.reader.board_poses
            gyro = got.gyro_threshold
            self.thresholds = {"accel": float(got.accel_threshold),
                               "gyro": float(gyro) if gyro else None}
            if sent is not None and got != sent:
                refused = getattr(dec, "settings_accepted", None) is False
                self.on_event("settings", f"the board uses other pose settings than sent "
                              f"({got.to_dict()} instead of {sent.to_dict()})"
                              + (": it refused them" if refused else ""))
        return self.last

    def finish(self) -> list[Pose]:
        return []

    def points(self, poses: Sequence[Pose]) -> np.ndarray:
        cols = list(self.accel_columns)
        return np.array([p.mean[cols] for p in poses]).reshape(-1, 3)


class _LivePoses:
    """The capture's pose detector: started once the first rows fix what the data decide."""

    def __init__(self, settings: PoseSettings, names: Sequence[str],
                 accel: Sequence[int] | None) -> None:
        self.base = settings
        self.names = tuple(names)
        self.accel = accel
        self.head: list[Record] = []
        self.det: PoseDetector | None = None
        self.how: ResolvedPoses | None = None
        self.last: np.ndarray | None = None

    def _start(self) -> list[Pose]:
        vals = np.array([r.values for r in self.head], dtype=np.float64)
        # the times as the session file stores them, so that a fit of the file agrees
        t = np.array([float(f"{r.t:.6f}") for r in self.head])
        self.how = self.base.resolve(self.names, vals, accel=self.accel, t=t)
        self.det = self.how.detector()
        self.head = []
        return self.det.update(vals)

    def update(self, recs: Sequence[Record]) -> list[Pose]:
        recs = [r for r in recs if len(r.values) == len(self.names)]
        if not recs:
            return []
        vals = np.array([r.values for r in recs], dtype=np.float64)
        cols = list(self.accel_columns)
        self.last = vals[-1, cols] if cols else None
        if self.det is None:
            self.head += recs
            return self._start() if len(self.head) >= HEAD_ROWS else []
        return self.det.update(vals)

    def finish(self) -> list[Pose]:
        if self.det is None:
            if not self.head:
                return []
            new = self._start()
        else:
            new = []
        assert self.det is not None
        return new + self.det.finish()

    @property
    def accel_columns(self) -> tuple[int, ...]:
        if self.how is not None:
            return tuple(self.how.kwargs["columns"])
        if self.accel is not None:
            return tuple(self.accel)
        return tuple(self.names.index(c) for c in ("ax", "ay", "az"))

    def points(self, poses: Sequence[Pose]) -> np.ndarray:
        cols = list(self.accel_columns)
        return np.array([p.mean[cols] for p in poses]).reshape(-1, 3)

    @property
    def settings(self) -> PoseSettings | None:
        return self.base.with_resolved(self.how) if self.how is not None else None

    @property
    def thresholds(self) -> dict[str, float | None]:
        return self.det.thresholds if self.det is not None else {}


def _status_text(
    rows: int,
    registered: list[Pose],
    live: _LivePoses | _BoardPoses | None,
    last: Any,
    reader: SerialReader,
    want_poses: int | None,
    want_samples: int | None,
) -> str:
    pts = live.points(registered) if live is not None else np.zeros((0, 3))
    cov = coverage(pts).fraction
    s = f"{rows}" + (f"/{want_samples}" if want_samples else "") + " samples"
    s += f"  {len(registered)}" + (f"/{want_poses}" if want_poses else "") + " poses"
    s += f"  coverage {100 * cov:.0f} %"
    dropped = reader.stats.dropped
    if dropped:
        s += f"  dropped {dropped}"
    if not reader.connected:
        s += "  [disconnected]"
    elif last is not None or len(pts):
        s += f"  next: {suggest_turn(pts, last)}"
    return s
