"""Production line: fit every board's session, judge it against limits, write a record per board.

Each board is fitted exactly as ``triaxcal fit SESSION.csv [options]`` fits one file (the same
code: :func:`triaxcal.calibration.session.fit_table`), so a board's calibration is the same
whether it was fitted alone or in a batch of thousands. Then the board is judged against
:class:`Limits`; the checks run in this order and every failed one is recorded (the first is the
main reason):

=======================  ===========================================================================
reason                   fails when
=======================  ===========================================================================
``unreadable``           the session cannot be read (not a table of numbers, no such columns)
``dead_axis``            an axis's readings, averaged over blocks of ``window`` samples, span less
                         than ``dead_axis_ratio`` of the readings' median magnitude (the axis does
                         not respond to gravity; a board turned through too few orientations still
                         moves every axis by far more)
``stuck``                more than ``stuck_max_pct`` % of the rows repeat the previous row exactly
                         on all three axes (a frozen sensor or bus; noise makes exact repeats rare)
``saturation``           more than ``saturation_max_pct`` % of the readings of an axis sit at the
                         full-scale rails, ``|v| >= full_scale`` (raw units)
``coverage``             the calibrated poses cover less than ``coverage_min_pct`` % of the 24
                         equal-area cells of the sphere of directions (the ``sphere`` figure of
                         ``triaxcal capture``'s status line): too few orientations for the model
``fit_failed``           the fit raised an error (degenerate data, implausible gains ...)
``not_a_calibration``    the validity gate refused the fit (:mod:`triaxcal.calibration.gate`:
                         the same refusal as ``triaxcal fit``); its calibration.json is marked
                         ``valid: false`` with the reasons
``too_few_poses``        fewer than ``min_points`` points (poses) were fitted
``rms``                  residual RMS above ``rms_max_pct`` % of the radius
``noise``                the sensor noise exceeds ``noise_max`` (calibrated units: g rms): within
                         each still pose the standard deviation of sample-to-sample differences
                         over sqrt(2), largest axis, median over the poses
``offset``               an axis's offset exceeds ``offset_max`` (calibrated units: g)
``gain``                 an axis's gain differs from ``1 / counts_per_unit`` by more than
                         ``gain_max_dev`` (relative; skipped when ``counts_per_unit`` is 0)
``cross_axis``           ``|offdiag_ij| / sqrt(diag_i diag_j)`` exceeds ``cross_axis_max``
=======================  ===========================================================================

Defaults suit an accelerometer at +-2 g (16384 counts/g, int16 counts) calibrated to g, the
MPU-6050 class: offsets up to 0.1 g (the datasheet's zero-g tolerance is +-50 mg on X/Y and
+-80 mg on Z), gains within 5 % of nominal (datasheet: +-3 %), cross-axis up to 3 % (+-2 %),
noise up to 10 mg rms. Change them with ``Limits(...)`` or ``--limit name=value``.
"""

from __future__ import annotations

import csv
import hashlib
import math
import os
import re
import sys
import time
from collections.abc import Iterable, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from .._checks import options
from .._checks.fields import parse_json
from ..calibration.file import Calibration
from ..calibration.part import SensorCalibration
from ..calibration.request import FitRequest, SourceOptions
from ..conventions.names import COEFFICIENTS
from ..errors import CalibrationError
from ..io.files import check_regular, open_regular, read_bounded
from ..io.tables import _is_number, _plain, iter_csv
from ..quality.bounds import LOW_COVERAGE_PCT
from ..quality.coverage import coverage

__all__ = [
    "REASONS",
    "SUMMARY_COLUMNS",
    "BoardResult",
    "Limits",
    "batch_fit",
    "batch_request",
    "judge",
    "read_grouped_table",
    "write_summary",
]

#: Fail reasons, in the order the checks run.
REASONS = ("unreadable", "dead_axis", "stuck", "saturation", "coverage", "fit_failed",
           "not_a_calibration", "too_few_poses", "rms", "noise", "offset", "gain", "cross_axis")


@dataclass(frozen=True)
class Limits:
    """Pass/fail limits of :func:`judge` (see the module notes for what each one checks).

    Units: ``noise_max`` and ``offset_max`` in calibrated units (g for an accelerometer fitted
    with radius 1 g); ``full_scale`` and ``counts_per_unit`` in raw units (counts);
    percentages in %.

    Examples
    --------
    >>> Limits().offset_max
    0.1
    >>> Limits.from_items(["offset_max=0.05", "coverage_min_pct=60"]).coverage_min_pct
    60.0
    """

    dead_axis_ratio: float = 0.05
    stuck_max_pct: float = 5.0
    full_scale: float = 32767.0
    saturation_max_pct: float = 0.1
    coverage_min_pct: float = LOW_COVERAGE_PCT
    min_points: int = 12
    rms_max_pct: float = 1.0
    noise_max: float = 0.01
    offset_max: float = 0.1
    counts_per_unit: float = 16384.0
    gain_max_dev: float = 0.05
    cross_axis_max: float = 0.03

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise CalibrationError(f"limit {f.name} must be a finite number, got {v!r}")
            if v < 0:
                raise CalibrationError(f"limit {f.name} must be >= 0, got {v}")
        object.__setattr__(self, "min_points", int(self.min_points))

    @classmethod
    def from_items(cls, items: Iterable[str], base: Limits | None = None) -> Limits:
        """Limits from ``name=value`` strings (the CLI's ``--limit``), over ``base``."""
        names = {f.name for f in fields(cls)}
        changes: dict[str, Any] = {}
        for item in items:
            name, sep, value = str(item).partition("=")
            name = name.strip().replace("-", "_")
            if not sep or name not in names:
                raise CalibrationError(
                    f"--limit {item!r}: use name=value with a name from {', '.join(sorted(names))}"
                )
            try:
                changes[name] = float(value)
            except ValueError:
                raise CalibrationError(f"--limit {item!r}: {value!r} is not a number") from None
        return replace(base or cls(), **changes)

    @classmethod
    def from_mapping(cls, d: Mapping[str, Any]) -> Limits:
        """Limits from a JSON object (``--limits FILE.json``); unknown names are refused."""
        if not isinstance(d, Mapping):
            raise CalibrationError("a limits file must hold a JSON object of name: number")
        return cls.from_items(f"{k}={v}" for k, v in d.items())


@dataclass(frozen=True)
class BoardResult:
    """The verdict on one board.

    ``verdict`` is ``"pass"`` or ``"fail"``; ``reasons`` the codes of the failed checks
    (:data:`REASONS`, first = main reason) and ``message`` the same in words with the
    numbers. ``part`` is the fitted :class:`~triaxcal.SensorCalibration` (``None`` when the fit
    failed); ``measures`` the numbers the checks looked at; ``outputs`` the files written.
    """

    board_id: str
    source: str
    verdict: str
    reasons: tuple[str, ...]
    message: str
    part: SensorCalibration | None
    measures: dict[str, Any] = field(default_factory=dict)
    outputs: tuple[str, ...] = ()

    @property
    def passed(self) -> bool:
        return self.verdict == "pass"


# ------------------------------------------------------------------------------ the checks


def _raw_checks(data: np.ndarray, limits: Limits, window: int = 25
                ) -> tuple[list[tuple[str, str]], dict]:
    """dead axis, stuck rows, saturation on the raw (N, 3) readings."""
    fails: list[tuple[str, str]] = []
    m: dict[str, Any] = {}
    if len(data) == 0:
        return [("unreadable", "no readings")], m
    nb = len(data) // window
    smooth = data[: nb * window].reshape(nb, window, 3).mean(axis=1) if nb >= 2 else data
    span = smooth.max(axis=0) - smooth.min(axis=0)
    size = float(np.median(np.linalg.norm(data, axis=1)))
    m["span"] = span.tolist()
    ratio = span / size if size > 0 else np.zeros(3)
    dead = [a for a, r in zip("xyz", ratio) if r < limits.dead_axis_ratio]
    if dead:
        fails.append(("dead_axis", f"axis {', '.join(dead)} spans only "
                      f"{100 * float(ratio.min()):.1f} % of the readings' magnitude "
                      f"(limit {100 * limits.dead_axis_ratio:g} %): it does not respond"))
    if len(data) > 1:
        same = np.all(data[1:] == data[:-1], axis=1)
        stuck = 100.0 * float(same.mean())
        m["stuck_pct"] = stuck
        if stuck > limits.stuck_max_pct:
            fails.append(("stuck", f"{stuck:.1f} % of the rows repeat the previous row exactly "
                          f"(limit {limits.stuck_max_pct:g} %): the sensor or its bus froze"))
    sat = 100.0 * (np.abs(data) >= limits.full_scale).mean(axis=0)
    m["saturation_pct"] = sat.tolist()
    if limits.full_scale > 0 and sat.max() > limits.saturation_max_pct:
        axes = ", ".join(a for a, s in zip("xyz", sat) if s > limits.saturation_max_pct)
        fails.append(("saturation", f"{sat.max():.2f} % of the readings of axis {axes} sit at "
                      f"full scale +-{limits.full_scale:g} (limit {limits.saturation_max_pct:g} "
                      "%): the range is too small or the gain is wrong"))
    return fails, m


def _fit_checks(part: SensorCalibration, noise_raw: float | None, limits: Limits
                ) -> tuple[list[tuple[str, str]], dict]:
    fails: list[tuple[str, str]] = []
    st = part.stats
    m: dict[str, Any] = {}
    unit = part.unit
    n = int(st.get("n", 0))
    if n < limits.min_points:
        fails.append(("too_few_poses", f"{n} points fitted (limit {limits.min_points}): "
                      "capture more poses"))
    rms_pct = float(st.get("rms_pct_of_radius", float("nan")))
    m["rms_pct"] = rms_pct
    if not rms_pct <= limits.rms_max_pct:
        fails.append(("rms", f"residual RMS {rms_pct:.3g} % of the radius (limit "
                      f"{limits.rms_max_pct:g} %)"))
    diag = np.abs(part.diag)
    if noise_raw is not None:
        noise = float(noise_raw * diag.max())
        m["noise"] = noise
        if noise > limits.noise_max:
            fails.append(("noise", f"noise {noise:.4g} {unit} rms within still poses (limit "
                          f"{limits.noise_max:g} {unit})"))
    off = np.abs(part.offset @ part.matrix.T)
    m["offset_cal"] = off.tolist()
    if off.max() > limits.offset_max:
        a = "xyz"[int(np.argmax(off))]
        fails.append(("offset", f"offset of axis {a} is {off.max():.4g} {unit} (limit "
                      f"{limits.offset_max:g} {unit})"))
    if limits.counts_per_unit > 0:
        nominal = 1.0 / limits.counts_per_unit
        dev = diag / nominal - 1.0
        m["gain_dev"] = dev.tolist()
        if np.abs(dev).max() > limits.gain_max_dev:
            a = "xyz"[int(np.argmax(np.abs(dev)))]
            worst = 100 * float(dev[int(np.argmax(np.abs(dev)))])
            fails.append(("gain", f"gain of axis {a} is {worst:+.2f} % from nominal "
                          f"1/{limits.counts_per_unit:g} (limit "
                          f"+-{100 * limits.gain_max_dev:g} %)"))
    mat = part.matrix
    cross = max(abs(mat[i, j]) / math.sqrt(abs(mat[i, i] * mat[j, j]))
                for i, j in ((0, 1), (0, 2), (1, 2)))
    m["cross_axis"] = float(cross)
    if cross > limits.cross_axis_max:
        fails.append(("cross_axis", f"cross-axis term {100 * cross:.2f} % (limit "
                      f"{100 * limits.cross_axis_max:g} %)"))
    return fails, m


def _pose_noise(table: Any, cols: list[int], request: FitRequest) -> float | None:
    """Sensor noise (raw units, rms): within each still pose (found as ``fit --poses`` finds
    them) the standard deviation of the sample-to-sample differences over sqrt(2) (blind to
    slow drift and to the slow ends of moves), largest axis; the median over poses."""
    if not request.source.poses:
        return None
    from ..detect.session import sensor_columns, session_poses

    accel = None if "accel" in sensor_columns(table.names) else cols
    det, _ = session_poses(table.names, table.data, request.source.detection, accel=accel)
    noise = []
    for p in det.poses:
        seg = table.data[p.start:p.end][:, cols]
        if len(seg) >= 3:
            noise.append(float(np.max(np.std(np.diff(seg, axis=0), axis=0))) / math.sqrt(2))
    return float(np.median(noise)) if noise else None


def judge(
    table: Any,
    request: FitRequest,
    limits: Limits,
    *,
    board_id: str,
) -> BoardResult:
    """Fit one board's table as ``triaxcal fit`` would, then judge it against ``limits``."""
    from ..calibration.gate import check_part, judged
    from ..calibration.session import fit_session
    from ..io.tables import pick_columns

    source = str(table.path)
    fails: list[tuple[str, str]] = []
    measures: dict[str, Any] = {}
    try:
        cols = pick_columns(table, request.source.columns, request.sensor)
    except CalibrationError as exc:
        return BoardResult(board_id, source, "fail", ("unreadable",), f"unreadable: {exc}", None)
    raw = table.data[:, cols]
    f, m = _raw_checks(raw, limits, request.source.detection.window)
    fails += f
    measures.update(m)
    part = None
    try:
        outcome = fit_session(table, request)
        gate = check_part(outcome.part, request.sensor)
        if not gate.valid:
            fails.append(("not_a_calibration", gate.text("the fit")))
        part = judged(outcome.part, gate, force=True)
    except CalibrationError as exc:
        # name the cause when it is a too narrow set of directions
        pts = raw
        if request.source.poses:
            try:
                from ..detect.session import pose_points

                pts, _ = pose_points(table, cols, request.source.detection)
            except CalibrationError:
                pts = raw[:0]
        cov = coverage(pts).percent
        measures["coverage_pct"] = cov
        if cov < limits.coverage_min_pct:
            fails.append(("coverage", f"the poses cover {cov:.0f} % of the sphere (limit "
                          f"{limits.coverage_min_pct:g} %): turn the board through more "
                          "orientations"))
        fails.append(("fit_failed", f"the fit failed: {exc}"))
    if part is not None:
        cov = coverage(part.apply(outcome.points)).percent
        measures["coverage_pct"] = cov
        if cov < limits.coverage_min_pct:
            fails.append(("coverage", f"the poses cover {cov:.0f} % of the sphere (limit "
                          f"{limits.coverage_min_pct:g} %): turn the board through more "
                          "orientations"))
        noise_raw = _pose_noise(table, cols, request)
        f, m = _fit_checks(part, noise_raw, limits)
        fails += f
        measures.update(m)
    order = {r: i for i, r in enumerate(REASONS)}
    fails.sort(key=lambda rm: order[rm[0]])
    reasons = tuple(dict.fromkeys(r for r, _ in fails))
    verdict = "fail" if fails else "pass"
    message = "; ".join(msg for _, msg in fails) if fails else "all checks passed"
    return BoardResult(board_id, source, verdict, reasons, message, part, measures)


# ------------------------------------------------------------------------------ reading input


def batch_request(**changes: Any) -> FitRequest:
    """The :class:`~triaxcal.calibration.request.FitRequest` of ``triaxcal batch`` by default:
    ``triaxcal fit``'s defaults with still poses (``source.poses``), then ``changes``.

    Examples
    --------
    >>> batch_request(model="full").model, batch_request().source.poses
    ('full', True)
    """
    base = FitRequest(source=SourceOptions(poses=True))
    return base.replace(**changes) if changes else base


_ID_UNSAFE = re.compile(r"[^A-Za-z0-9._-]")


def safe_id(text: str) -> str:
    """A board id usable as a file name (other characters become ``_``)."""
    s = _ID_UNSAFE.sub("_", str(text)).strip(".")[:100]
    return s or "board"


def read_grouped_table(path: Any, by: str) -> list[tuple[str, Any]]:
    """Split one table (CSV with a header, or Parquet) into per-board tables by column ``by``.

    Returns ``[(board id, Table)]`` in the order ids first appear; each board's rows keep the
    file's order. Parquet needs pyarrow (``pip install 'triaxcal[dask]'``).
    """
    from ..io.tables import Table

    p = Path(path)
    if not p.exists():
        raise CalibrationError(f"table {p} not found")
    if p.suffix.lower() in (".parquet", ".pq"):
        try:
            import pyarrow.parquet as pq
        except ImportError:
            raise CalibrationError(
                "reading Parquet needs pyarrow: pip install 'triaxcal[dask]'"
            ) from None
        check_regular(p, what="Parquet table")
        with open_regular(p, what="Parquet table") as fh:
            magic = fh.read(4)
        if magic != b"PAR1":
            raise CalibrationError(f"{p} is not a Parquet file (it does not start with PAR1)")
        try:
            t = pq.read_table(p)
        except Exception as exc:  # noqa: BLE001 - pyarrow raises many kinds
            raise CalibrationError(f"{p} is not a readable Parquet file: {exc}") from None
        names = list(t.column_names)
        if by not in names:
            raise CalibrationError(f"{p} has no column {by!r}; columns: {', '.join(names)}")
        ids = [str(v) for v in t.column(by).to_pylist()]
        others = [c for c in names if c != by]
        try:
            data = np.column_stack([np.asarray(t.column(c).to_numpy(), dtype=np.float64)
                                    for c in others])
        except (TypeError, ValueError) as exc:
            raise CalibrationError(f"{p}: the columns other than {by!r} must be numbers "
                                   f"({exc})") from None
    else:
        records = iter_csv(p, what="table of boards")
        try:
            _, head = next(records)
        except StopIteration:
            raise CalibrationError(f"{p} is empty") from None
        header = [h.strip() for h in head]
        if by not in header:
            raise CalibrationError(
                f"{p} has no column {by!r}; its header is {', '.join(header)}")
        k = header.index(by)
        others = [h for i, h in enumerate(header) if i != k]
        ids, rows = [], []
        for lineno, row in records:
            if not row or (len(row) == 1 and not row[0].strip()):
                continue
            if len(row) != len(header):
                raise CalibrationError(
                    f"{p}, line {lineno}: {len(row)} values, expected {len(header)}")
            ids.append(row[k])  # as written: ids that differ only by spaces are other boards
            values = [v.strip() for i, v in enumerate(row) if i != k]
            # numbers as the table reader reads them: plain ASCII decimals, finite
            if not all(_plain(v) and _is_number(v) for v in values):
                raise CalibrationError(f"{p}, line {lineno}: not all numbers")
            row_values = [float(v) for v in values]
            if not all(math.isfinite(v) for v in row_values):
                raise CalibrationError(f"{p}, line {lineno}: a value is not finite (nan or "
                                       "inf): drop or fix that row")
            rows.append(row_values)
        data = np.array(rows, dtype=np.float64).reshape(-1, len(others))
    if not ids:
        raise CalibrationError(f"{p} has no data rows")
    uniq, first, inverse = np.unique(np.asarray(ids, dtype=object), return_index=True,
                                     return_inverse=True)
    out = []
    for j in np.argsort(first):
        rows_j = np.flatnonzero(inverse == j)
        block = np.ascontiguousarray(data[rows_j])
        sha = hashlib.sha256(block.astype("<f8").tobytes()).hexdigest()
        out.append((str(uniq[j]), Table(names=tuple(others), data=block,
                                        path=Path(f"{p}#{uniq[j]}"), sha256=sha)))
    return out


# ------------------------------------------------------------------------------ the batch


def _work(job: tuple[str, Any, FitRequest, Limits, str | None, str]) -> BoardResult:
    board_id, src, request, limits, out_dir, prefix = job
    from ..io.tables import read_table

    if isinstance(src, (str, Path)):
        try:
            table = read_table(src)
        except CalibrationError as exc:
            return BoardResult(board_id, str(src), "fail", ("unreadable",),
                               f"unreadable: {exc}", None)
    else:
        table = src
    try:
        res = judge(table, request, limits, board_id=board_id)
    except Exception as exc:  # noqa: BLE001 - one bad board must not stop the line
        res = BoardResult(board_id, str(getattr(table, "path", src)), "fail", ("fit_failed",),
                          f"the fit failed: {exc!r}", None)
    if out_dir is not None and res.part is not None:
        res = replace(res, outputs=_write_board(res, request, limits, Path(out_dir), prefix))
    return res


def _write_board(res: BoardResult, request: FitRequest, limits: Limits, out: Path,
                 prefix: str) -> tuple[str, ...]:
    from ..export import export

    assert res.part is not None
    folder = out / res.board_id
    folder.mkdir(parents=True, exist_ok=True)
    sensor = request.sensor
    parts: dict[str, Any] = {sensor: res.part}
    cal = Calibration(**parts, sensor_id=res.board_id, extra={
        "verdict": res.verdict, "reasons": list(res.reasons), "message": res.message,
        "limits": asdict(limits)})
    paths = [cal.save(folder / "calibration.json")]
    if res.passed:  # headers only for boards fit to ship
        paths.append(export(cal, "c", folder / f"{prefix}_calibration.h", prefix=prefix))
        if res.part.raw_unit == "counts":
            paths.append(export(cal, "c-fixed", folder / f"{prefix}_calibration_fixed.h",
                                prefix=prefix))
    return tuple(str(p) for p in paths)


class _Progress:
    """A one-line progress bar on a text stream (``\\r``, no dependencies)."""

    def __init__(self, total: int, stream: TextIO | None) -> None:
        self.total, self.stream = total, stream
        self.t0 = time.monotonic()
        self.last = 0.0

    def update(self, done: int, failed: int, *, force: bool = False) -> None:
        if self.stream is None:
            return
        now = time.monotonic()
        if not force and now - self.last < 0.2:
            return
        self.last = now
        el = max(now - self.t0, 1e-9)
        rate = done / el
        eta = (self.total - done) / rate if rate > 0 else float("nan")
        width = 30
        fill = int(width * done / max(self.total, 1))
        self.stream.write(f"\r[{'#' * fill}{'.' * (width - fill)}] {done}/{self.total} boards,"
                          f" {failed} failed, {rate:.0f}/s, ETA {eta:.0f} s ")
        self.stream.flush()

    def end(self) -> None:
        if self.stream is not None:
            self.stream.write("\n")
            self.stream.flush()


#: Most worker processes one batch may start (each holds a Python interpreter and numpy, about
#: 30-60 MB): a larger ``jobs`` (``--jobs``) is refused by name, and no more workers than
#: boards are ever started.
MAX_JOBS = 1024


def batch_fit(
    sources: Sequence[tuple[str, Any]],
    *,
    request: FitRequest | None = None,
    limits: Limits | None = None,
    out_dir: Any = None,
    prefix: str = "triaxcal",
    jobs: int | None = None,
    progress: TextIO | None = None,
) -> list[BoardResult]:
    """Fit and judge many boards; write their files and ``summary.csv`` into ``out_dir``.

    Parameters
    ----------
    sources : sequence of (board id, session path or Table)
        One entry per board (see :func:`read_grouped_table` for one table of many boards).
    request : FitRequest, optional
        How each board is fitted (default: :func:`batch_request`, ``triaxcal fit``'s defaults
        with still poses).
    limits : Limits, optional
    out_dir : str or Path, optional
        Where to write ``<id>/calibration.json`` (every fitted board, with the verdict in
        ``extra``), ``<id>/<prefix>_calibration.h`` and ``..._fixed.h`` (passing boards only)
        and ``summary.csv``. ``None``: write nothing.
    prefix : str
        C identifier prefix of the headers.
    jobs : int, optional
        Worker processes (default: the number of CPUs; 1: in this process; at most
        :data:`MAX_JOBS`, and never more than there are boards).
    progress : text stream, optional
        Where the progress bar goes.

    Returns
    -------
    list of BoardResult
        In the order of ``sources``.
    """
    from ..export._cgen import _ident

    request = request if request is not None else batch_request()
    limits = limits or Limits()
    prefix = _ident(prefix)
    n_jobs = (os.cpu_count() or 1) if jobs is None else options.integer(
        jobs, "jobs", ge=1, le=MAX_JOBS, hint="worker processes; 1 fits in this process")
    ids = [safe_id(i) for i, _ in sources]
    seen: dict[str, int] = {}
    for k, i in enumerate(ids):
        if i in seen:
            seen[i] += 1
            ids[k] = f"{i}-{seen[i]}"
        else:
            seen[i] = 1
    out = None if out_dir is None else str(out_dir)
    if out is not None:
        Path(out).mkdir(parents=True, exist_ok=True)
    work = [(ids[k], src, request, limits, out, prefix) for k, (_, src) in enumerate(sources)]
    n_jobs = min(n_jobs, len(work))  # no more processes than boards
    bar = _Progress(len(work), progress)
    results: list[BoardResult] = []
    failed = 0
    if n_jobs <= 1:
        for w in work:
            r = _work(w)
            results.append(r)
            failed += not r.passed
            bar.update(len(results), failed)
    else:
        chunk = max(1, min(16, len(work) // (8 * n_jobs)))
        with ProcessPoolExecutor(max_workers=n_jobs) as pool:
            for r in pool.map(_work, work, chunksize=chunk):
                results.append(r)
                failed += not r.passed
                bar.update(len(results), failed)
    bar.update(len(results), failed, force=True)
    bar.end()
    if out is not None:
        write_summary(results, Path(out) / "summary.csv")
    return results


#: Columns of ``summary.csv``, one row per board.
SUMMARY_COLUMNS = (
    "id", "verdict", "reasons", "message", "model", "raw_unit", "unit", *COEFFICIENTS,
    "radius", "rms", "rms_pct", "coverage_pct", "points", "noise", "cross_axis", "source",
)


def _text_cell(s: str) -> str:
    """Keep a spreadsheet from reading a text cell as a formula."""
    return "'" + s if s[:1] in ("=", "+", "-", "@", "\t", "\r") else s


def write_summary(results: Sequence[BoardResult], path: Any) -> Path:
    """Write ``summary.csv``: one row per board, :data:`SUMMARY_COLUMNS`.

    Coefficients are the fit's: ``offset`` in raw units, ``diag``/``offdiag`` the matrix that
    **multiplies** (calibrated units per raw unit), ``rms`` in calibrated units; empty cells
    where the fit failed. ``reasons`` joins the fail codes with ``|``.
    """
    p = Path(path)
    tmp = p.with_name(p.name + ".tmp")
    with open(tmp, "w", encoding="utf-8", newline="") as f:
        w = csv.writer(f)
        w.writerow(SUMMARY_COLUMNS)
        for r in results:
            part = r.part
            row: dict[str, Any] = {k: "" for k in SUMMARY_COLUMNS}
            row.update(id=_text_cell(r.board_id), verdict=r.verdict,
                       reasons="|".join(r.reasons), message=_text_cell(r.message),
                       source=_text_cell(r.source))
            if part is not None:
                st = part.stats
                row.update(model=part.model or "", raw_unit=part.raw_unit, unit=part.unit,
                           radius=repr(float(part.radius or float("nan"))),
                           rms=repr(float(st.get("rms", float("nan")))),
                           rms_pct=repr(float(st.get("rms_pct_of_radius", float("nan")))),
                           points=int(st.get("n", 0)))
                for a, v in zip("xyz", part.offset):
                    row[f"offset_{a}"] = repr(float(v))
                for a, v in zip("xyz", part.diag):
                    row[f"diag_{a}"] = repr(float(v))
                for a, v in zip(("xy", "xz", "yz"), part.offdiag):
                    row[f"offdiag_{a}"] = repr(float(v))
            for k in ("coverage_pct", "noise", "cross_axis"):
                if k in r.measures:
                    row[k] = repr(float(r.measures[k]))
            w.writerow([row[k] for k in SUMMARY_COLUMNS])
    os.replace(tmp, p)
    return p


def load_limits(path: Any) -> Limits:
    """Read limits from a JSON file ``{"offset_max": 0.05, ...}``."""
    p = Path(path)
    data = read_bounded(p, limit=1 << 20, what="limits file")  # a regular file, <= 1 MiB
    try:
        d = parse_json(data.decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise CalibrationError(f"limits file {p} is not JSON: {exc}") from None
    except CalibrationError as exc:
        raise CalibrationError(f"limits file {p}: {exc}") from None
    return Limits.from_mapping(d)


def print_counts(results: Sequence[BoardResult], stream: TextIO | None = None) -> None:
    """Print ``boards: P pass, F fail (reason: count, ...)``."""
    stream = stream or sys.stdout
    fails = [r for r in results if not r.passed]
    counts: dict[str, int] = {}
    for r in fails:
        counts[r.reasons[0] if r.reasons else "?"] = counts.get(
            r.reasons[0] if r.reasons else "?", 0) + 1
    print(f"boards: {len(results) - len(fails)} pass, {len(fails)} fail"
          + (" (" + ", ".join(f"{k}: {v}" for k, v in sorted(counts.items())) + ")"
             if counts else ""), file=stream)
