"""The live state: fed by the capture thread, refitted in the background, read by the page.

The capture loop (:func:`triaxcal.capture.run.capture`) hands every batch of records to
:meth:`LiveState.on_records`, which only updates bounded structures:

* the accelerometer's still poses, found online by a :class:`~triaxcal.detect.PoseDetector`
  with exactly the options of ``triaxcal fit --poses`` (so its poses are the ones that command
  finds in the session file);
* the magnetometer's :class:`~triaxcal.live.quality.SpreadBuffer` of at most 650 well-spread
  samples (MotionCal's size);
* thinned trails of the newest readings (25 per second, 10 s) and the stream's counters.

A background thread (:meth:`LiveState.start`) refits several times a second what has arrived
with the same Rust fits and options as ``triaxcal fit`` (:func:`triaxcal.fit.select.fit_robust`:
model choice by BIC, the default outlier rule) and publishes one JSON document
(:meth:`LiveState.document`, served as ``GET /api/state``) and the thinned point sets
(:meth:`LiveState.points`). Nothing grows with the length of the capture except one small
record per registered pose. When the capture ends, :meth:`LiveState.finish` fits the saved
session with ``triaxcal fit``'s own code, so the page then shows exactly what that command
gives.

Units: raw readings in the session's units (counts); calibrated accelerometer readings in g
(``--radius 1g``), magnetometer readings in the unit of its radius (the data's own scale, i.e.
counts, unless a field such as ``50uT`` is given), gyroscope rates in deg/s from the nominal
sensitivity (131 counts per deg/s; 16 for MotionCal ``Raw:`` lines).
"""

from __future__ import annotations

import json
import math
import threading
import time
from collections import deque
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..capture.run import _LivePoses
from ..errors import CalibrationError
from .options import (
    _MC_HELP,
    _MC_NAMES,
    _RECTS,
    _TRAIL_HZ,
    _TRAIL_S,
    ACCEL_LIMITS,
    SENSOR_COLUMNS,
    LiveOptions,
    _columns,
    _Fit,
    _jsonable,
    _round,
)
from .quality import MOTIONCAL_LIMITS, SpreadBuffer, biggest_empty_cap, motioncal_quality

__all__ = ["SENSOR_COLUMNS", "LiveOptions", "LiveState"]

class LiveState:
    """Bounded live state of a capture; see the module docstring.

    Parameters
    ----------
    session : str or Path
        The session CSV the capture writes (what Save fits).
    columns : sequence of str
        Channel names of the session, in device order (``ax ay az gx gy gz mx my mz temp``).
    protocol : str
        The wire protocol (``"raw"`` changes the nominal scales).
    port : str
        The serial port, for the page's header and messages.
    options : LiveOptions, optional
    existing_rows : int
        Rows the session file held before this capture (``--append``); Save fits them too,
        as ``triaxcal fit`` on that file would.

    Examples
    --------
    >>> import numpy as np, tempfile, os
    >>> from triaxcal.io.serial import Record
    >>> st = LiveState(os.path.join(tempfile.mkdtemp(), "s.csv"), ("ax", "ay", "az"),
    ...                protocol="framed", port="sim")
    >>> st.on_records([Record(0.0, (0, 0, 16384))] * 200)   # 2 s flat and still at 100 Hz
    >>> doc = st.refresh()
    >>> doc["samples"], doc["sensors"]["accel"]["poses"], doc["next"]
    (200, 1, 'Accelerometer: hold it still... registering this pose.')
    """

    def __init__(
        self,
        session: Any,
        columns: Sequence[str],
        *,
        protocol: str = "framed",
        port: str = "",
        options: LiveOptions | None = None,
        existing_rows: int = 0,
    ) -> None:
        self.options = opts = options or LiveOptions()
        self.existing_rows = int(existing_rows)
        self.last_fit_errors: list[str] = []
        self.session = Path(session)
        self.out_dir = Path(opts.out_dir) if opts.out_dir is not None else self.session.parent
        self.columns = tuple(columns)
        self.protocol = protocol
        self.port = port
        raw = protocol == "raw"
        from ..detect.session import PoseSettings

        self.detection = opts.detection if opts.detection is not None else PoseSettings()
        #: nominal accelerometer counts per g (for display until the data decide it)
        self.nominal_counts_per_g = 8192.0 if raw else 16384.0
        self.gyro_cpd = float(opts.gyro_counts_per_dps or (16.0 if raw else 131.0))
        names = self.columns
        self.cols: dict[str, list[int]] = {}
        for sensor, want in SENSOR_COLUMNS.items():
            c = _columns(names, want)
            if c is not None:
                self.cols[sensor] = c
        if "accel" not in self.cols and len(names) >= 3:
            self.cols["accel"] = [0, 1, 2]
        from ..calibration.request import parse_radius

        self.accel_radius, self.accel_unit = parse_radius(opts.accel_radius, "accel")
        if opts.mag_radius is not None:
            self.mag_radius: float | None
            self.mag_radius, self.mag_unit = parse_radius(opts.mag_radius, "mag")
        else:
            self.mag_radius, self.mag_unit = None, "counts"
        self._lock = threading.RLock()
        self._refresh_lock = threading.Lock()  # one refit-and-publish cycle at a time
        self._publish_cond = threading.Condition()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._reader: Any = None
        self._t_start = time.monotonic()
        self.status = "waiting"  # waiting | capturing | finished
        self.stopped_by: str | None = None
        self.final_error: str | None = None
        self.events: deque[dict[str, Any]] = deque(maxlen=20)
        self._banner: dict[str, Any] | None = None
        self.last_action: dict[str, Any] | None = None
        self.version = 0
        self._json = "{}"
        self._doc: dict[str, Any] = {}
        self._points_json: dict[str, tuple[int, str]] = {}
        self.publishes = 0
        self.refit_ms = 0.0
        self._echo: bytearray | None = None
        self.rows = 0  # records seen since the start (not reset)
        self.reset_row = 0  # self.rows at the last Reset
        self.resets = 0
        self._accel_version = 0
        self._magbuf = SpreadBuffer(opts.mag_buffer)
        self._reset_data()

    # ------------------------------------------------------------------ feeding (capture)
    def _reset_data(self) -> None:
        self.reset_row = self.rows
        # the capture's own detector: the same poses as the capture and `fit --poses`
        named = all(c in self.columns for c in ("ax", "ay", "az"))
        self._detector = _LivePoses(self.detection, self.columns, None if named else (0, 1, 2))
        self._pose_sig: tuple[int, int] = (0, 0)
        self._poses: list[np.ndarray] = []  # pose means, all channels
        self._accel_version += 1
        self._magbuf.clear()
        self._trail: deque[tuple[float, np.ndarray]] = deque(maxlen=int(_TRAIL_HZ * _TRAIL_S))
        self._trail_t = -math.inf
        self._trail_version = 0
        self._latest: np.ndarray | None = None
        self._last_rx: float | None = None
        self._rate: deque[tuple[float, int]] = deque()
        self._fits: dict[str, _Fit | None] = {"accel": None, "mag": None}
        self._fit_errors: dict[str, str | None] = {"accel": None, "mag": None}
        self._fitted_versions: dict[str, int] = {"accel": -1, "mag": -1}
        self._final_points: dict[str, np.ndarray] = {}
        self._derived_cache: dict[str, tuple[Any, float, Any]] = {}
        # (time, largest offset standard error): at most one a second; when 120 are kept,
        # every other one goes, so the history spans the whole capture in bounded memory
        self._precision: dict[str, list[tuple[float, float]]] = {"accel": [], "mag": []}

    def attach(self, reader: Any) -> None:
        """Watch ``reader`` (a :class:`~triaxcal.io.serial.SerialReader`): its counters,
        its events (pulled cable...) and its bytes (for the board's echo of Send)."""
        self._reader = reader
        previous = reader.on_event

        def on_event(kind: str, message: str) -> None:
            self.on_event(kind, message)
            if previous is not None:
                previous(kind, message)

        reader.on_event = on_event
        reader.on_bytes = self._on_bytes

    def _on_bytes(self, data: bytes) -> None:
        echo = self._echo
        if echo is not None and len(echo) < 1 << 16:
            echo += data

    def on_event(self, kind: str, message: str) -> None:
        """A reader event (``disconnected``, ``reconnected``, ``silent``, ``garbage``,
        ``resumed``): kept for the page, which shows a banner for the first three."""
        now = time.time()
        with self._lock:
            self.events.append({"time": now, "kind": kind, "message": message})
            if kind in ("disconnected", "silent", "garbage"):
                self._banner = {"kind": kind, "message": message, "since": now}
            elif kind in ("reconnected", "resumed"):
                self._banner = {"kind": kind, "message": message, "since": now}

    def on_records(self, records: Sequence[Any]) -> None:
        """Take a batch of :class:`~triaxcal.io.serial.Record` (the capture's ``on_records``
        hook): O(batch) work on bounded structures, nothing kept per record."""
        if not records:
            return
        vals = np.array([r.values for r in records], dtype=np.float64)
        if vals.ndim != 2 or vals.shape[1] != len(self.columns):
            return  # a record of another width: the writer skipped it as well
        now = time.monotonic()
        with self._lock:
            if self.status == "waiting":
                self.status = "capturing"
            self.rows += len(vals)
            self._last_rx = now
            self._rate.append((now, len(vals)))
            while self._rate and now - self._rate[0][0] > 2.0:
                self._rate.popleft()
            self._latest = vals[-1].copy()
            if "accel" in self.cols:
                self._detector.update(records)
                det = self._detector.det
                if det is not None:
                    ps = det.poses
                    sig = (len(ps), ps[-1].n if ps else 0)  # a held pose grows until it moves
                    if sig != self._pose_sig:
                        self._pose_sig = sig
                        self._poses = [np.asarray(p.mean, dtype=np.float64) for p in ps]
                        self._accel_version += 1
            if "mag" in self.cols:
                self._magbuf.add(vals[:, self.cols["mag"]])
            t = records[-1].t
            if t - self._trail_t >= 1.0 / _TRAIL_HZ:
                self._trail.append((t, vals[-1].copy()))
                self._trail_t = t
                self._trail_version += 1

    def finish_poses(self) -> None:
        """The end of the stream: decide on the pose in progress, as the capture does."""
        with self._lock:
            self._detector.finish()
            det = self._detector.det
            if det is not None:
                self._poses = [np.asarray(p.mean, dtype=np.float64) for p in det.poses]
                self._accel_version += 1

    # ----------------------------------------------------------------------- fitting
    def _fit_live(self, sensor: str, pts: np.ndarray) -> _Fit:
        from ..fit.select import fit_robust

        o = self.options
        radius = self.accel_radius if sensor == "accel" else self.mag_radius
        unit = self.accel_unit if sensor == "accel" else self.mag_unit
        rule = "sigma" if o.outliers == "magneto" else o.outliers
        rob = fit_robust(pts, model=o.model, radius=radius, rule=rule, sigma=o.sigma,
                         max_rounds=o.rounds, lengths="calibrated")
        f = rob.fit
        return _Fit(model=f.model, offset=np.array(f.offset), matrix=np.array(f.matrix),
                    radius=float(f.radius), rms=float(f.rms), stderr=f.stderr_dict, n=int(f.n),
                    rejected=[int(i) for i in rob.rejected], converged=bool(f.converged),
                    condition=float(f.condition) if math.isfinite(f.condition) else None,
                    reason=rob.model_reason, source="live", unit=unit)

    def refresh(self, *, force: bool = False) -> dict[str, Any]:
        """One refit-and-publish cycle: refit what changed, rebuild and publish the document.

        ``force`` refits and recomputes everything even if nothing changed (benchmarks).
        Returns the document (also :meth:`document`)."""
        with self._refresh_lock:
            return self._refresh(force)

    def _refresh(self, force: bool) -> dict[str, Any]:
        t0 = time.perf_counter()
        if force:
            self._fitted_versions = {"accel": -1, "mag": -1}
            self._derived_cache.clear()
        with self._lock:
            poses = np.array(self._poses).reshape(len(self._poses), len(self.columns))
            accel_version = self._accel_version
            mag_pts = self._magbuf.points
            mag_version = self._magbuf.version
            final = self.status in ("fitting", "finished")
        work = {"accel": (accel_version, poses[:, self.cols["accel"]] if "accel" in self.cols
                          and len(poses) else np.zeros((0, 3))),
                "mag": (mag_version, mag_pts)}
        for sensor, (version, pts) in work.items():
            if sensor not in self.cols or final:
                continue
            if version == self._fitted_versions[sensor]:
                continue
            self._fitted_versions[sensor] = version
            need = 10 if sensor == "accel" else 40
            if len(pts) < need:
                self._fits[sensor] = None
                self._fit_errors[sensor] = (
                    f"waiting for data: {len(pts)} of at least {need} "
                    + ("still poses" if sensor == "accel" else "well-spread samples"))
                continue
            try:
                fit = self._fit_live(sensor, pts)
            except CalibrationError as exc:
                self._fit_errors[sensor] = str(exc)
                continue
            self._fits[sensor] = fit
            self._fit_errors[sensor] = None
            hist = self._precision[sensor]
            now_s = time.time()
            if not hist or now_s - hist[-1][0] >= 1.0:
                hist.append((now_s, max(fit.stderr.get(f"offset_{a}", math.nan) for a in "xyz")))
                if len(hist) >= 120:
                    del hist[-2::-2]
        doc, points = self._build(poses)
        self.refit_ms = 1000.0 * (time.perf_counter() - t0)
        doc["timing"] = {"refit_ms": self.refit_ms, "publishes": self.publishes + 1,
                         "refresh_hz": self.options.refresh_hz}
        self._publish(doc, points)
        return doc

    # ------------------------------------------------------------------ the document
    def _stream(self, now: float) -> dict[str, Any]:
        r = self._reader
        rate = 0.0
        if self._rate:
            span = max(now - self._rate[0][0], 0.5)
            rate = sum(n for _, n in self._rate) / span if now - self._rate[-1][0] < 2 else 0.0
        d: dict[str, Any] = {
            "records": self.rows, "records_per_s": rate,
            "since_last_s": None if self._last_rx is None else now - self._last_rx,
            "connected": True if r is None else bool(r.connected),
            "dropped": 0, "resyncs": 0, "dropped_bytes": 0, "lost": 0,
            "disconnects": 0, "reconnects": 0,
        }
        if r is not None:
            st = r.stats
            dec = st.decoder
            d.update(dropped=st.dropped, resyncs=dec.dropped_frames + dec.lines_skipped,
                     dropped_bytes=dec.dropped_bytes, lost=dec.lost_frames,
                     disconnects=st.disconnects, reconnects=st.reconnects)
        banner = self._banner
        if banner is not None:
            age = time.time() - banner["since"]
            if banner["kind"] in ("reconnected", "resumed") and age > 10.0:
                self._banner = banner = None
            elif banner["kind"] == "disconnected" and r is not None and r.connected \
                    and d["reconnects"] >= d["disconnects"]:
                banner = None  # the reconnected event will follow
        d["banner"] = None if banner is None else {**banner, "age_s": time.time() - banner["since"]}
        d["events"] = list(self.events)[-8:]
        return d

    def _build(self, poses: np.ndarray) -> tuple[dict[str, Any], dict[str, Any]]:
        from ..quality.coverage import suggest_turn

        now = time.monotonic()
        with self._lock:
            stream = self._stream(now)
            latest = None if self._latest is None else self._latest.copy()
            trail = list(self._trail)
            trail_version = self._trail_version
            det = self._detector.det
            still = bool(det.still) if det is not None else False
            how = self._detector.how
            mag_pts = self._magbuf.points
            mag_version = self._magbuf.version
            accel_version = self._accel_version
            rows, reset_row = self.rows, self.reset_row
        sensors: dict[str, Any] = {}
        points: dict[str, Any] = {}
        hints: list[tuple[str, str, bool]] = []
        for sensor in ("accel", "mag"):
            if sensor not in self.cols:
                continue
            cols = self.cols[sensor]
            raw = poses[:, cols] if sensor == "accel" and len(poses) else (
                mag_pts if sensor == "mag" else np.zeros((0, 3)))
            if sensor in self._final_points:
                raw = self._final_points[sensor]  # the session's poses, as fitted
                accel_version = -2  # (the cache key of the session's points)
            fit = self._fits[sensor]
            s: dict[str, Any] = {
                "unit": fit.unit if fit else (self.accel_unit if sensor == "accel"
                                             else self.mag_unit),
                "raw_unit": "counts",
                "fit": None if fit is None else fit.doc(),
                "fit_error": self._fit_errors[sensor],
                "latest": None if latest is None else latest[cols],
                "precision": [[t, v] for t, v in self._precision[sensor]],
            }
            if sensor == "accel":
                s["poses"] = len(raw)
                s["still"] = bool(still)
            else:
                s["samples"] = len(raw)
                s["buffer"] = self.options.mag_buffer
            key = (accel_version if sensor == "accel" else mag_version, id(fit))
            cov, checks, q_gaps = self._derived(sensor, raw, fit, key)
            cap = cov["empty_cap"]
            s["coverage"] = cov
            if q_gaps is not None and fit is not None:
                with self._lock:
                    if self._magbuf.version == mag_version:
                        self._magbuf.set_fit(fit.offset, fit.matrix, fit.radius, q_gaps)
            s["quality"] = checks
            s["ready"] = bool(fit is not None and all(c["ok"] for c in checks))
            if sensor == "accel":
                cur = None if latest is None else latest[cols]
                if not len(raw):
                    hint = ("hold the board still, flat, for a second: the first pose registers"
                            if cur is not None else "waiting for data")
                elif still:
                    hint = "hold it still... registering this pose"
                else:
                    hint = suggest_turn(raw, cur) + ", then hold it still for a second"
                if s["ready"]:
                    hint = "accelerometer done: every direction has a pose"
            else:
                if s["ready"]:
                    hint = "magnetometer done: all four numbers are green"
                else:
                    hint = "keep turning the board slowly in every direction"
                    if cap is not None and cap["deg"] > 15.0:
                        hint += (f"; still empty: {cap['words']} -- point that side of the board"
                                 " along the Earth's field (north, and down in the northern "
                                 "hemisphere)")
            s["hint"] = hint
            hints.append((sensor, hint, s["ready"]))
            sensors[sensor] = s
            rej = fit.rejected if fit is not None and fit.source == "live" else []
            points[sensor] = {"version": accel_version if sensor == "accel" else mag_version,
                              "raw": _round(raw, 2), "rejected": rej}
        if "gyro" in self.cols:
            g = self.cols["gyro"]
            bias = (poses[:, g].mean(axis=0) / self.gyro_cpd).tolist() if len(poses) else None
            sensors["gyro"] = {
                "unit": "deg/s", "counts_per_unit": self.gyro_cpd,
                "latest": None if latest is None else latest[g] / self.gyro_cpd,
                "bias_from_poses": bias, "poses": len(poses),
            }
        tt = np.array([t for t, _ in trail])
        tv = np.array([v for _, v in trail]).reshape(len(trail), len(self.columns))
        trail_doc: dict[str, Any] = {"version": trail_version,
                                     "t": _round(tt - (tt[-1] if len(tt) else 0.0), 3)}
        for sensor, cols in self.cols.items():
            scale = self.gyro_cpd if sensor == "gyro" else 1.0
            trail_doc[sensor] = _round(tv[:, cols] / scale, 2)
        points["trail"] = trail_doc
        doc = {
            "version": self.version + 1,
            "time": time.time(),
            "status": self.status,
            "stopped_by": self.stopped_by,
            "final_error": self.final_error,
            "elapsed_s": now - self._t_start,
            "session": str(self.session),
            "out_dir": str(self.out_dir),
            "port": self.port,
            "protocol": self.protocol,
            "columns": list(self.columns),
            "samples": rows,
            "samples_since_reset": rows - reset_row,
            "resets": self.resets,
            "poses": len(poses),
            "coverage_pct": sensors["accel"]["coverage"]["pct"] if "accel" in sensors else None,
            "next": self._next_step(stream, hints),
            "stream": stream,
            "sensors": sensors,
            "fit_commands": self.fit_commands(),
            "actions": {"last": self.last_action,
                        "send_possible": self._reader is not None and not getattr(
                            self._reader, "polled", False) and self.status == "capturing"},
            "options": {"model": self.options.model, "outliers": self.options.outliers,
                        "sigma": self.options.sigma,
                        "rounds": self.options.rounds, "accel_radius": self.options.accel_radius,
                        "mag_radius": self.options.mag_radius,
                        "detection": self.detection.to_dict(),
                        "units_per_g": self.nominal_counts_per_g,
                        "detection_counts_per_g": how.counts_per_g if how is not None
                        else None,
                        "mag_buffer": self.options.mag_buffer},
        }
        return doc, points

    def _derived(self, sensor: str, raw: np.ndarray, fit: _Fit | None,
                 key: tuple[int, int]) -> tuple[dict[str, Any], list[dict[str, Any]],
                                                 float | None]:
        """Coverage, the biggest empty cap and the quality checks of one sensor; recomputed
        when its points or fit changed, at most 4 times a second (the cap search is the
        costly part)."""
        from ..quality.coverage import coverage, sphere_cells
        from ..report import direction_words

        now = time.monotonic()
        cached = self._derived_cache.get(sensor)
        # new points of the same fit wait up to 0.25 s; a new fit, or the session's final
        # points, are judged at once (else the state could pair a fit with its predecessor's
        # checks)
        if cached is not None and (cached[0] == key or (
                cached[0][1] == key[1] and key[0] != -2 and now - cached[1] < 0.25)):
            return cached[2]
        # directions: calibrated when there is a fit, else raw less a rough centre
        if len(raw):
            dirs = fit.apply(raw) if fit is not None else raw - (
                np.median(raw, axis=0) if sensor == "mag" and len(raw) > 20 else 0.0)
            cov_ = coverage(dirs)
            counts, pct = cov_.counts, cov_.percent
            found = biggest_empty_cap(dirs)
        else:
            counts, pct, found = np.zeros(sphere_cells().n, dtype=np.int64), 0.0, None
        cap: dict[str, Any] | None = None
        if found is not None:
            c, ang = found
            cap = {"center": c, "deg": ang, "words": direction_words(c)}
        cov = {"pct": pct, "counts": counts, "cells_hit": int(np.count_nonzero(counts)),
               "cells_total": int(counts.size), "rects": _RECTS, "empty_cap": cap}
        q_gaps = None
        if sensor == "accel":
            rms_pct = 100.0 * fit.rms / fit.radius if fit else math.inf
            checks = [
                _check("poses", "still poses", len(raw), "", ACCEL_LIMITS["poses"], ">=",
                       "orientations held still; each one adds a point"),
                _check("empty_cap", "largest empty region", cap["deg"] if cap else 180.0,
                       "deg", ACCEL_LIMITS["empty_cap_deg"], "<",
                       "angle from the emptiest direction to the nearest pose"),
                _check("fit_error", "fit error", rms_pct, "%", ACCEL_LIMITS["fit_error"],
                       "<", "RMS of |calibrated| - 1 g, in % of 1 g"),
            ]
        else:
            vals = {"gaps": 100.0, "variance": 100.0, "wobble": 100.0, "fit_error": 100.0}
            if fit is not None and len(raw):
                q = motioncal_quality(fit.apply(raw), fit.radius)
                vals = {k: getattr(q, k) for k in vals}
                q_gaps = q.gaps
            checks = [_check(k, _MC_NAMES[k], vals[k], "%", MOTIONCAL_LIMITS[k], "<",
                             _MC_HELP[k]) for k in MOTIONCAL_LIMITS]
        out = (cov, checks, q_gaps)
        self._derived_cache[sensor] = (key, now, out)
        return out

    def _next_step(self, stream: dict[str, Any], hints: list[tuple[str, str, bool]]) -> str:
        if self.status == "fitting":
            return (f"Capture ended ({self.stopped_by}): fitting the whole session file as "
                    "`triaxcal fit` does...")
        if self.status == "finished":
            if self.final_error:
                return f"Capture ended ({self.stopped_by}); the session could not be fitted: " \
                       f"{self.final_error}"
            if hints and all(ready for _, _, ready in hints):
                return (f"Capture ended: {self.rows} rows saved to {self.session.name}. All "
                        "green: press Save calibration.")
            return (f"Capture ended: {self.rows} rows saved to {self.session.name}. Some checks "
                    "are red: capture again for a better calibration, or Save this one anyway.")
        if not stream["connected"]:
            return ("The board is unplugged: plug the cable back in. The capture goes on by "
                    "itself and nothing captured is lost.")
        if self.rows == 0 or stream["since_last_s"] is None:
            return f"Waiting for data from the board on {self.port or 'the port'}..."
        if hints and all(ready for _, _, ready in hints):
            return ("All green: press Save calibration (then Export C header or Send to "
                    "board). Ctrl-C in the terminal ends the capture.")
        for sensor, hint, ready in hints:
            if not ready:
                name = "Accelerometer" if sensor == "accel" else "Magnetometer"
                return f"{name}: {hint}."
        return "Keep going."

    def fit_commands(self) -> list[str]:
        """The ``triaxcal fit`` commands that Save runs (on the session as it is)."""
        from .fitting import fit_argv, fit_request

        out = str(self.out_dir / "calibration.json")
        cmds = []
        first = True
        for sensor in ("accel", "mag"):
            if sensor in self.cols:
                argv = fit_argv(fit_request(self, sensor), str(self.session), out, new=first)
                cmds.append("triaxcal " + " ".join(_quote(a) for a in argv))
                first = False
        return cmds

    # ------------------------------------------------------------------ publishing
    def _publish(self, doc: dict[str, Any], points: dict[str, Any]) -> None:
        text = json.dumps(_jsonable(doc), allow_nan=False, separators=(",", ":"))
        # the point sets are plain lists of finite floats already (rounded with tolist)
        pj = {k: (int(v["version"]), json.dumps(v, allow_nan=False, separators=(",", ":")))
              for k, v in points.items()}
        with self._publish_cond:
            self.version = doc["version"]
            self._doc = doc
            self._json = text
            self._points_json = pj
            self.publishes += 1
            self._publish_cond.notify_all()

    def document(self) -> dict[str, Any]:
        """The last published document (what ``GET /api/state`` returns), as Python values."""
        with self._publish_cond:
            return json.loads(self._json)

    def document_json(self) -> tuple[int, str]:
        """``(version, JSON text)`` of the last published document."""
        with self._publish_cond:
            return self.version, self._json

    def points_json(self) -> dict[str, tuple[int, str]]:
        """Per set (``accel``, ``mag``, ``trail``): ``(version, JSON text)`` of the thinned
        points last published."""
        with self._publish_cond:
            return dict(self._points_json)

    def points(self) -> dict[str, Any]:
        """The thinned point sets last published, as Python values."""
        return {k: json.loads(v) for k, (_, v) in self.points_json().items()}

    def wait(self, version: int, timeout: float) -> int:
        """Block until a document newer than ``version`` is published (or ``timeout`` s)."""
        with self._publish_cond:
            self._publish_cond.wait_for(lambda: self.version > version, timeout=timeout)
            return self.version

    # ------------------------------------------------------------------ life cycle
    def start(self) -> LiveState:
        """Start the background refit-and-publish thread (``refresh_hz`` cycles a second)."""
        if self._thread is None:
            self.refresh()
            self._stop.clear()
            self._thread = threading.Thread(target=self._loop, name="triaxcal-live-refit",
                                            daemon=True)
            self._thread.start()
        return self

    def _loop(self) -> None:
        period = 1.0 / self.options.refresh_hz
        nxt = time.monotonic()
        while True:
            nxt += period
            if self._stop.wait(max(0.0, nxt - time.monotonic())):
                break
            try:
                self.refresh()
            except Exception as exc:  # noqa: BLE001 - keep the page alive, say what broke
                with self._lock:
                    self.events.append({"time": time.time(), "kind": "error",
                                        "message": f"live refit failed: {exc!r}"})
            if time.monotonic() > nxt + period:
                nxt = time.monotonic()  # a slow cycle: do not try to catch up

    def stop(self) -> None:
        """Stop the background thread (idempotent)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=10.0)
            self._thread = None

    def reset(self) -> dict[str, Any]:
        """Forget the poses, the magnetometer buffer and the fits (the session file keeps
        every row; Save then fits only the rows captured after the reset)."""
        with self._lock:
            self.resets += 1
            self._reset_data()
        self.refresh()
        return {"action": "reset", "ok": True,
                "message": f"cleared the live view; the fits start again from row "
                           f"{self.reset_row} of {self.session.name} (the file keeps "
                           "everything)"}

    def finish(self, result: Any = None) -> None:
        """The capture ended: fit the saved session exactly as ``triaxcal fit`` does (the
        accelerometer with ``--poses``, the magnetometer on every row) and publish that."""
        from .fitting import fit_saved_session

        self.finish_poses()
        with self._lock:
            self.status = "fitting"  # the live fits stop; the page says the file is fitted
            self.stopped_by = getattr(result, "stopped_by", None)
        self.refresh()
        error = None
        try:
            outcomes = fit_saved_session(self)
        except CalibrationError as exc:
            error = str(exc)
            outcomes = {}
        with self._refresh_lock:
            self._finish_fits(outcomes, error)
        self.refresh()

    def _finish_fits(self, outcomes: dict[str, Any], error: str | None) -> None:
        self.final_error = error
        for sensor, out in outcomes.items():
            p = out.part
            st = p.stats
            fit = _Fit(
                model=str(p.model), offset=np.array(p.offset), matrix=np.array(p.matrix),
                radius=float(p.radius if p.radius is not None else st["radius"]),
                rms=float(st["rms"]), stderr=dict(st.get("stderr") or {}), n=int(st["n"]),
                rejected=[int(i) for i in out.rejected], converged=bool(st["converged"]),
                condition=st.get("condition"), reason=out.reason, source="session",
                unit=p.unit)
            self._fits[sensor] = fit
            self._fit_errors[sensor] = None
            self._derived_cache.clear()
            self._precision[sensor].append(
                (time.time(), max(fit.stderr.get(f"offset_{a}", math.nan) for a in "xyz")))
            if sensor == "accel":
                with self._lock:
                    self._final_points["accel"] = np.asarray(out.points, dtype=np.float64)
                    self._accel_version += 1
        with self._lock:
            self.status = "finished"


def _check(key: str, name: str, value: float, unit: str, limit: float, op: str,
           help_text: str) -> dict[str, Any]:
    ok = value >= limit if op == ">=" else value < limit
    return {"key": key, "name": name, "value": value, "unit": unit, "limit": limit, "op": op,
            "ok": bool(ok), "help": help_text}


def _quote(arg: str) -> str:
    import shlex

    return shlex.quote(arg)
