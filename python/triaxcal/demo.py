"""The demo use case: capture from a simulated board, fit, and compare with the truth.

The simulated board (:class:`triaxcal.sim.SimDevice`) runs on a pseudo-terminal, and the
capture goes through exactly the code a real board uses (:func:`triaxcal.capture.run.capture`
over :class:`triaxcal.io.serial.SerialReader`). The session CSV is then read back, still
poses are detected as ``triaxcal fit --poses`` detects them
(:func:`triaxcal.detect.session.session_poses` with the given pose settings: nothing else),
the accelerometer and magnetometer are fitted (:func:`triaxcal.fit_ellipsoid`, model "full")
and the gyroscope bias is averaged over the still poses. Finally the calibration is written as
a calibration file, C headers (float and fixed point), the MotionCal packet, and a quality
report with a figure per sensor (:func:`triaxcal.export.write_outputs`).

``triaxcal demo`` is this module's :func:`run_demo` with the command line's options; it sits
above the whole pipeline (capture, detection, fits, calibration file, exports, the live page)
and nothing in the package imports it.
"""

from __future__ import annotations

import hashlib
import json
import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from ._checks.options import choice, number
from ._checks.spelling import opt
from .calibration.file import Calibration
from .calibration.gate import check_part, direction_stats, judged
from .calibration.part import SensorCalibration
from .capture.run import CaptureResult, capture, channel_names, read_session
from .detect.session import PoseSettings, session_poses
from .errors import CalibrationError
from .export import write_outputs
from .fit.ellipsoid import EllipsoidFit, fit_ellipsoid
from .io.protocol import PROTOCOLS
from .io.serial import SerialReader
from .quality.coverage import coverage, coverage_warning
from .sim import (
    GYRO_COUNTS_PER_DPS,
    SIM_COUNTS_PER_UNIT,
    SensorTruth,
    SimDevice,
    SimIMU,
    globe_script,
    tumble_script,
)

__all__ = ["RATE_HZ", "WITHIN_SIGMA", "run_demo"]

#: Sample rate of the simulated board, Hz (simulated time).
RATE_HZ = 100.0

#: Errors up to this many standard errors count as "within the noise".
WITHIN_SIGMA = 4.0


def run_demo(
    out: Path,
    *,
    protocol: str = "framed",
    speed: float = 40.0,
    seed: int = 1,
    progress: Any = None,
    plot: bool = True,
    detection: PoseSettings | None = None,
    live: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Run the demo into folder ``out`` (made if missing); returns the results dict (also in
    results.json).

    Besides ``session.csv`` and ``results.json``, writes the calibration (``calibration.json``,
    ``triaxcal_calibration.h``, ``triaxcal_calibration_fixed.h``, ``motioncal.bin``) and a
    quality report per sensor (``report_<sensor>.txt`` and, with ``plot``, ``.png``).
    ``detection``: the pose options (default: the command line's defaults), used by the
    capture and by the detection on the saved session alike.

    ``live`` (``{"host", "port", "open_browser"}``) serves the live page during the capture
    (:class:`triaxcal.live.LivePage`, fitting the magnetometer to the simulated field; its
    buttons write into ``out/live``); the page, still serving, is returned as
    ``results["live_page"]``: close it when done.
    """
    choice(protocol, "protocol", PROTOCOLS)
    speed = number(speed, "speed", gt=0, hint="simulated seconds per real second")
    settings = detection if detection is not None else PoseSettings()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    t_start = time.monotonic()
    imu = SimIMU(seed)
    script = globe_script(hold_s=1.0, seed=seed)
    if live is not None:
        # the globe leaves the magnetometer's sphere unevenly covered (MotionCal's wobble
        # stays red): end with a tumble through 30 random orientations, as a user would
        script = script + tumble_script(30, seed=seed)
    session = out / "session.csv"
    channels = None if protocol == "raw" else 10
    with SimDevice(imu, script, rate_hz=RATE_HZ, speed=speed, loop=False, seed=seed) as dev:
        reader = SerialReader(dev.port, protocol=protocol, channels=channels, stream=True)
        if progress is not None:
            print(f"triaxcal demo: simulated board on {dev.port} ({dev.pty_path}), "
                  f"{len(script)} poses of the globe scheme"
                  + (" and a tumble" if live is not None else "") + f", {protocol} protocol, "
                  f"{speed:g}x real time", file=progress)
        page = None
        if live is not None:
            from .live import LiveOptions
            from .live.run import LivePage

            page = LivePage(reader, session, columns=channel_names(protocol, channels),
                            options=LiveOptions(mag_radius=f"{imu.truth.field_ut:g}uT",
                                                out_dir=out / "live", detection=settings,
                                                counts_per_unit=SIM_COUNTS_PER_UNIT),
                            host=live["host"], port=live["port"],
                            open_browser=live["open_browser"], progress=progress,
                            mode="overwrite").start()
            try:
                cap = page.capture(stop=dev.finished, bell=False, handle_sigint=False,
                                   detection=settings)
            except BaseException:
                page.close()
                raise
        else:
            cap = capture(reader, session, stop=dev.finished, mode="overwrite", bell=False,
                          progress=progress, handle_sigint=False, detection=settings)
    t_capture = time.monotonic() - t_start
    try:
        results = _analyse(out, session, protocol, speed, seed, plot, imu, dev, cap, t_start,
                           t_capture, settings)
    except BaseException:
        if page is not None:
            page.close()
        raise
    if page is not None:
        results["live_page"] = page
    return results


def _analyse(out: Path, session: Path, protocol: str, speed: float, seed: int, plot: bool,
             imu: SimIMU, dev: SimDevice, cap: CaptureResult, t_start: float,
             t_capture: float, settings: PoseSettings) -> dict[str, Any]:

    columns, data = read_session(session)
    values = data[:, 1:]
    a_cols, g_cols, m_cols = [0, 1, 2], [3, 4, 5], [6, 7, 8]
    # the poses `triaxcal fit session.csv --poses` finds, with the same options
    det, how = session_poses(columns, data, settings)
    if len(det.poses) < 10:
        raise CalibrationError(
            f"the demo found only {len(det.poses)} still poses in {len(values)} samples; "
            f"try a lower {opt('speed')} (the host may be too slow to keep up)"
        )
    means = np.array([p.mean[1:] for p in det.poses])  # without the t column
    still = np.concatenate([np.arange(p.start, p.end) for p in det.poses])
    n_windows = len(still) / settings.window

    truth = imu.truth
    # Raw: lines have MotionCal's fixed scales, not the device's: compare in physical units
    tr_accel, tr_gyro, tr_mag = truth.accel, truth.gyro, truth.mag
    accel_fit = fit_ellipsoid(means[:, a_cols], model="full", radius=1.0)
    mag_fit = fit_ellipsoid(means[:, m_cols], model="full", radius=truth.field_ut)
    gyro_bias = values[still][:, g_cols].mean(axis=0)
    gyro_se = values[still][:, g_cols].std(axis=0) / math.sqrt(n_windows)
    # the coverage every command reports: calibrated accelerometer directions of the poses
    cov = coverage(accel_fit.apply(means[:, a_cols]))

    report = {
        "accel": _compare(accel_fit, tr_accel, "g"),
        "mag": _compare(mag_fit, tr_mag, "uT"),
        "gyro": {
            "offset_true": tr_gyro.offset.tolist(),
            "offset": gyro_bias.tolist(),
            "offset_stderr": gyro_se.tolist(),
            "offset_error": (gyro_bias - tr_gyro.offset).tolist(),
            "units": "counts (131 counts = 1 deg/s)",
        },
    }
    ok = report["accel"]["within_noise"] and report["mag"]["within_noise"]
    table = _table(report, accel_fit, mag_fit, len(means), cap, truth.field_ut, cov.percent)
    results = {
        "ok": bool(ok),
        "protocol": protocol,
        "speed": speed,
        "seed": seed,
        "capture": {
            "rows": cap.samples,
            "poses_online": len(cap.poses),
            "coverage": cap.coverage,
            "coverage_pct": 100.0 * cap.coverage,
            "stopped_by": cap.stopped_by,
            "frames_sent": len(dev.sent),
            "dropped_frames": cap.stats.decoder.dropped_frames,
            "lost_frames": cap.stats.decoder.lost_frames,
            "seconds": round(t_capture, 3),
        },
        "poses": len(means),
        "coverage_pct": cov.percent,
        "pose_detection": settings.with_resolved(how).to_dict(),
        "thresholds": det.thresholds,
        "columns": list(columns),
        "truth": truth.to_dict(),
        "recovered": report,
        "seconds": round(time.monotonic() - t_start, 3),
        "session": str(session),
    }

    # the calibration a user ships: counts in, g / deg/s / uT out; each part records how
    # its poses were found, as `triaxcal fit --poses` does, so `triaxcal report` finds them again
    sha = hashlib.sha256(session.read_bytes()).hexdigest()
    pose_stats = {"poses": True, "n_poses": len(det.poses),
                  "pose_detection": settings.with_resolved(how).to_dict(),
                  "pose_sensors": list(how.sensors)}
    gyro_part = SensorCalibration(
        offset=gyro_bias,
        matrix=np.eye(3) / GYRO_COUNTS_PER_DPS,  # nominal sensitivity; bias from the poses
        raw_unit="counts",
        unit="deg/s",
        model="bias",
        stats={"n_samples": int(len(still)), **pose_stats, "columns": ["gx", "gy", "gz"]},
        input_sha256=sha,
        source=str(session),
    )

    def part(fit: EllipsoidFit, cols: list[int], unit: str) -> SensorCalibration:
        pts = means[:, cols]
        p = SensorCalibration.from_fit(
            fit, raw_unit="counts", unit=unit, points=pts, input_sha256=sha, source=str(session),
            extra_stats={**pose_stats, "columns": [columns[1 + c] for c in cols],
                         "n_input": len(pts)})
        stats = dict(p.stats)
        cov_part = coverage(p.apply(pts))
        stats["coverage_pct"] = cov_part.percent
        low = coverage_warning(cov_part, "accel" if unit == "g" else "mag")
        if low:
            stats["warnings"] = [*stats.get("warnings", []), low]
        stats["directions"] = direction_stats(p, pts)
        return p.replace(stats=stats)

    # every part through the validity gate, as `triaxcal fit` writes them
    parts = {"accel": part(accel_fit, a_cols, "g"), "gyro": gyro_part,
             "mag": part(mag_fit, m_cols, "uT")}
    cal = Calibration(
        accel=judged(parts["accel"], check_part(parts["accel"], "accel")),
        gyro=judged(parts["gyro"], check_part(parts["gyro"], "gyro")),
        mag=judged(parts["mag"], check_part(parts["mag"], "mag")),
        sensor_id=f"triaxcal-sim-seed{seed}",
    )
    outputs = write_outputs(
        cal, {"accel": means[:, a_cols], "mag": means[:, m_cols]}, out, plot=plot,
        counts_per_unit=SIM_COUNTS_PER_UNIT,  # the simulated board's driver scale
    )
    results["outputs"] = {k: str(v) for k, v in outputs.items()}
    path = out / "results.json"
    path.write_text(json.dumps(results, indent=2) + "\n")
    results["results"] = str(path)
    results["table"] = table
    return results


_PARAM_CELL = {"diag_x": (0, 0), "diag_y": (1, 1), "diag_z": (2, 2),
               "offdiag_xy": (0, 1), "offdiag_xz": (0, 2), "offdiag_yz": (1, 2)}


def _compare(fit: EllipsoidFit, truth: SensorTruth, units: str) -> dict[str, Any]:
    """Recovered vs true parameters; matrix terms as ``scale`` (matrix * counts_per_unit)."""
    cpu = truth.counts_per_unit
    rows: list[dict[str, Any]] = []
    se = fit.stderr_dict
    for i, axis in enumerate("xyz"):
        rows.append({"name": f"offset_{axis}", "true": float(truth.offset[i]),
                     "recovered": float(fit.offset[i]), "stderr": se[f"offset_{axis}"],
                     "units": "counts"})
    for name, (i, j) in _PARAM_CELL.items():
        rows.append({"name": name.replace("diag", "scale").replace("offscale", "cross"),
                     "true": float(truth.matrix[i, j] * cpu),
                     "recovered": float(fit.matrix[i, j] * cpu),
                     "stderr": se[name] * cpu, "units": f"x 1/{cpu:g} {units}/count"})
    for r in rows:
        r["error"] = r["recovered"] - r["true"]
        r["sigmas"] = abs(r["error"]) / r["stderr"] if r["stderr"] > 0 else math.inf
    return {
        "params": rows,
        "rms": fit.rms,
        "units": units,
        "converged": fit.converged,
        "within_noise": all(r["sigmas"] <= WITHIN_SIGMA for r in rows),
        "offset": fit.offset.tolist(),
        "matrix": fit.matrix.tolist(),
    }


def _table(rep: dict, accel: EllipsoidFit, mag: EllipsoidFit, poses: int, cap: CaptureResult,
           field_ut: float, coverage_pct: float) -> str:
    d = cap.stats.decoder
    lines = [
        f"triaxcal demo: {cap.samples} samples captured in {cap.elapsed_s:.1f} s (dropped "
        f"frames {d.dropped_frames}, lost {d.lost_frames}), {poses} still poses fitted, "
        f"coverage {coverage_pct:.0f} %",
        f"  (the capture counted {len(cap.poses)} poses, coverage {100 * cap.coverage:.0f} %; "
        f"`triaxcal fit {Path(str(cap.path)).name} --poses` finds the same)",
        "",
    ]
    head = f"  {'parameter':<10} {'true':>12} {'recovered':>12} {'error':>10} {'std.err':>9}  unit"
    titles = (
        ("accel", f"accelerometer (model full, radius 1 g, rms {accel.rms:.2g} g)"),
        ("mag", f"magnetometer (model full, radius {field_ut:g} uT, rms {mag.rms:.2g} uT)"),
    )
    for key, title in titles:
        lines += [title, head]
        for r in rep[key]["params"]:
            digits = 1 if r["units"] == "counts" else 5
            lines.append(
                f"  {r['name']:<10} {r['true']:>12.{digits}f} {r['recovered']:>12.{digits}f} "
                f"{r['error']:>10.{digits}f} {r['stderr']:>9.{digits}f}  {r['units']}"
            )
        verdict = "yes" if rep[key]["within_noise"] else "NO"
        lines += [f"  all within {WITHIN_SIGMA:g} standard errors: {verdict}", ""]
    g = rep["gyro"]
    lines += ["gyroscope bias from the still poses (counts; 131 counts = 1 deg/s)", head]
    for i, axis in enumerate("xyz"):
        t, v, s = g["offset_true"][i], g["offset"][i], g["offset_stderr"][i]
        lines.append(f"  {'offset_' + axis:<10} {t:>12.1f} {v:>12.1f} {v - t:>10.1f} {s:>9.1f}"
                     f"  counts ({(v - t) / GYRO_COUNTS_PER_DPS:+.3f} deg/s)")
    return "\n".join(lines)
