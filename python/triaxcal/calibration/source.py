"""One way in for every command that reads a session: a table (CSV / whitespace) or a log.

``.ulg`` (PX4), ``.bin`` (ArduPilot), ``.bag`` (ROS 1), ``.db3`` / ``.mcap`` / a bag folder
(ROS 2) go to :func:`triaxcal.read_log`; everything else to the table reader.
:class:`~triaxcal.calibration.request.SourceOptions` says which readings to take (columns,
still poses, and for logs the instance, topics and whether to undo the autopilot's
calibration).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..detect.session import PoseSettings
from ..errors import CalibrationError
from ..io.logs import is_log, read_log
from ..io.recording import LogRecording
from .request import SourceOptions

__all__ = ["Source", "autopilot_lines", "load_source", "table_source"]

_G = {"m/s^2": 9.80665, "g": 1.0, "mg": 1000.0}


@dataclass
class Source:
    """Readings of one sensor from a session file or a log."""

    points: np.ndarray
    path: Path
    sha256: str
    raw_unit: str | None = None
    columns: list[Any] = field(default_factory=list)
    table: Any = None
    recording: LogRecording | None = None
    extra: dict[str, Any] = field(default_factory=dict)


def file_sha256(path: Path) -> str:
    """SHA-256 of a file (of a ROS 2 bag folder: of its files' names and bytes, sorted)."""
    h = hashlib.sha256()
    files = sorted(q for q in path.iterdir() if q.is_file()) if path.is_dir() else [path]
    for q in files:
        if path.is_dir():
            h.update(q.name.encode() + b"\0")
        with open(q, "rb") as fh:
            for chunk in iter(lambda: fh.read(1 << 20), b""):
                h.update(chunk)
    return h.hexdigest()


def table_source(table: Any, sensor: str, options: SourceOptions | None = None) -> Source:
    """Readings of ``sensor`` from a table already read (:func:`triaxcal.io.tables.read_table`):
    the table half of :func:`load_source` (``triaxcal batch`` fits each board so)."""
    from ..detect.session import POSE_N_COLUMN, pose_points
    from ..io.tables import pick_columns

    opts = options if options is not None else SourceOptions()
    cols = pick_columns(table, opts.columns, sensor)
    pose_stats: dict[str, Any] = {}
    board = table.names is not None and POSE_N_COLUMN in table.names  # rows are pose means
    if opts.poses or board:  # the capture's pose detection, every sensor
        pts, pose_stats = pose_points(table, cols, opts.detection)
    else:
        pts = table.data[:, cols]
    return Source(points=pts, path=table.path, sha256=table.sha256, table=table,
                  columns=[table.names[c] if table.names else c for c in cols],
                  extra=pose_stats)


def load_source(path: str | Path, sensor: str, options: SourceOptions | None = None) -> Source:
    """Readings of ``sensor`` from ``path`` as ``options`` ask (columns, still poses, the log
    options); the same for ``fit``, ``report`` and every command that takes a session."""
    opts = options if options is not None else SourceOptions()
    p = Path(path)
    instance = opts.instance
    topic = opts.topics
    undo = opts.undo_autopilot_cal
    if not is_log(p):
        if opts.for_logs:
            raise CalibrationError(
                f"--instance, --topic and --undo-autopilot-cal apply to logs (.ulg, .bin, .bag, "
                f".db3, .mcap); {p} is read as a table"
            )
        from ..io.tables import read_table

        table = read_table(p, skip_bad_lines=opts.skip_bad_lines)
        return table_source(table, sensor, opts)
    if opts.columns:
        raise CalibrationError(f"--columns applies to tables; {p} is a log: choose the sensor "
                               "with --sensor (and --instance / --topic)")
    if not p.exists():
        raise CalibrationError(f"log file {p} not found")
    rec = read_log(p, instance=instance, topic=topic, undo_autopilot_cal=undo)
    stream = rec.stream(sensor)
    pts = stream.data
    extra: dict[str, Any] = {"log": {
        "format": rec.format, "stream": stream.name, "instance": instance,
        "topic": list(topic) if topic else None, "undo_autopilot_cal": undo,
        "calibrated_by_autopilot": stream.calibrated, "samples": len(stream),
        "rate_hz": stream.rate_hz,
        "device_id": (rec.meta.get("device_ids") or {}).get(sensor),
    }}
    if opts.poses:
        pts, pose_stats = _log_pose_points(rec, sensor, opts.detection)
        extra.update(pose_stats)
    return Source(points=pts, path=p, sha256=file_sha256(p), raw_unit=stream.unit,
                  columns=[f"{stream.name}:{sensor}"], recording=rec, extra=extra)


def _log_pose_points(
    rec: LogRecording, sensor: str, detection: PoseSettings
) -> tuple[np.ndarray, dict[str, Any]]:
    """Still-pose means of ``sensor``, poses found as ``triaxcal capture`` finds them: a pose
    ends when the accelerometer, the gyroscope (when the log has one) or the magnetometer (when
    it is the sensor fitted) says the vehicle moved."""
    from dataclasses import replace

    from ..detect.session import SENSOR_NAMES, session_poses

    acc = rec.stream("accel")
    per_g = _G.get(acc.unit)
    if per_g is None:
        raise CalibrationError(f"--poses needs the accelerometer in g or m/s^2; the log's is in "
                               f"{acc.unit}")
    wanted = ("accel", *(s for s in ("gyro", "mag") if s in rec.sensors and
                         (s == "gyro" or s == sensor)))
    if wanted == ("accel",):
        data = acc.data
    else:
        _, sync = rec.synchronized(wanted)
        data = np.hstack([sync[s] for s in wanted])
    names = tuple(n for s in wanted for n in SENSOR_NAMES[s])
    settings = replace(detection, counts_per_g=per_g)
    det, how = session_poses(names, data, settings)
    if len(det.poses) == 0:
        raise CalibrationError(
            f"no still poses found in {rec.source} (window {detection.window} samples): the "
            "vehicle must rest in each pose for a while, or drop --poses"
        )
    i = wanted.index(sensor)
    cols = [3 * i, 3 * i + 1, 3 * i + 2]
    stats = {"poses": True, "n_poses": len(det.poses),
             "pose_detection": settings.with_resolved(how).to_dict(),
             "pose_sensors": list(how.sensors)}
    return np.array([np.asarray(p.mean)[cols] for p in det.poses], dtype=np.float64), stats


def autopilot_lines(src: Source, sensor: str, offset: Any, matrix: Any, unit: str) -> list[str]:
    """The autopilot's stored calibration beside the new fit, in triaxcal's convention."""
    rec = src.recording
    if rec is None or rec.autopilot is None or getattr(rec.autopilot, sensor) is None:
        return []
    ap = rec.autopilot.part(sensor)
    stream = rec.stream(sensor)
    o, m = ap.triaxcal_offset, ap.triaxcal_matrix
    fo, fm = np.asarray(offset), np.asarray(matrix)
    lines = [
        f"  {ap.autopilot} stored calibration of this {sensor} ({ap.unit}): {ap.equation}",
        "    in triaxcal's form calibrated = (raw - offset) @ matrix.T, in the frame the "
        "autopilot corrects in:",
        f"    {ap.autopilot:9s} offset [{_v(o)}] diag [{_v(np.diag(m))}] "
        f"offdiag [{_v([m[0, 1], m[0, 2], m[1, 2]])}]",
        f"    {'this fit':9s} offset [{_v(fo)}] diag [{_v(np.diag(fm))}] "
        f"offdiag [{_v([fm[0, 1], fm[0, 2], fm[1, 2]])}] ({unit} per {ap.unit})",
        f"    source: {ap.citation}",
    ]
    if stream.calibrated:
        lines.append(
            f"  note: {stream.name} was already calibrated by {ap.autopilot}, so this fit is a "
            "correction on top of it; pass --undo-autopilot-cal to fit the raw sensor"
        )
    return lines


def autopilot_stats(src: Source, sensor: str) -> dict[str, Any]:
    """The autopilot's calibration, to record in the part's stats."""
    rec = src.recording
    if rec is None or rec.autopilot is None or getattr(rec.autopilot, sensor) is None:
        return {}
    ap = rec.autopilot.part(sensor)
    return {"autopilot": {
        "autopilot": ap.autopilot, "slot": ap.index, "unit": ap.unit,
        "equation": ap.equation, "source": ap.citation,
        "params": {k: float(v) for k, v in ap.params.items()},
        "offset": ap.triaxcal_offset.tolist(), "matrix": ap.triaxcal_matrix.tolist(),
    }}


def _v(values: Any) -> str:
    return ", ".join(f"{float(x):.6g}" for x in np.ravel(values))
