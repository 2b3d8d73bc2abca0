"""A compass calibrated from a flight log (``triaxcal fit LOG --sensor mag --method attitude``):
the log's compass paired with its attitude, battery current or throttle and position, the
autopilot's calibration undone, :func:`triaxcal.methods.attitude.fit_attitude`, and the part
with what the flight determined, checked on the half of the flight it was not fitted to.

* **Raw readings.** The calibration the autopilot applied is undone with its own equation
  (:mod:`triaxcal.io.logs.autopilot`); a log whose calibration cannot be undone is refused.
  ArduPilot corrects the compass in the body frame (it rotates first), PX4 in the sensor frame
  (it rotates after): the fit runs in the body frame, and a PX4 part is turned back into the
  sensor frame (``S = R^T M R``, ``offset = R^T o``, interference ``R^T v``), so that each
  part is in the frame its autopilot corrects in.
* **The field.** The World Magnetic Model's at the log's position (GPS fix, EKF origin) or the
  request's ``field.location``; else fitted, with the overall scale held (see the method).
* **Attitude.** ArduPilot logs the vehicle body's attitude, trimmed by ``AHRS_TRIM_X/Y``; the
  compass reads in the autopilot's body, so the trim is put back (:func:`_ardupilot_trim`).
* **Heading.** The attitude's yaw is used only when the log's parameters show it came from
  elsewhere than this compass (ArduPilot ``COMPASS_USE`` off, ``EK3_SRC1_YAW`` GPS /
  ExternalNav / GSF, or another compass the estimator used; PX4 ``SYS_HAS_MAG`` /
  ``EKF2_MAG_TYPE`` none, GPS or vision yaw); otherwise only roll and pitch are
  (``heading="free"``), as MAGFit does: an estimator that fused the compass carries its errors
  in its yaw. How far the logged compass heading strays from the yaw is recorded
  (``stats["attitude"]["logged_heading_error_deg"]``).
* **Interference.** The battery current when it varies by ``MIN_CURRENT_SPAN_A`` or more, else
  the throttle when it varies by ``MIN_THROTTLE_SPAN``; otherwise none.
* **Held-out check.** The same fit on the first half of the flight, judged on the second: the
  scatter of the field turned to NED by the logged attitude, the field error as the fit
  measures it (:func:`field_error`) and the heading error, with the log's own calibration and
  with the fit (``stats["attitude"]["held_out"]``, which also keeps the first half's fit for
  the report's figure, :mod:`triaxcal.report.flight`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..conventions.rotations import euler_to_dcm
from ..conventions.units import unit_factor
from ..errors import CalibrationError
from ..io.logs import read_log, undo_autopilot_calibration
from ..io.logs.flight import FlightData, read_flight
from ..io.recording import LogRecording
from ..methods.attitude import AttitudeFit, fit_attitude, tilt_dcm
from ..quality import bounds as B
from .part import SensorCalibration, _norm_stats
from .request import FitRequest
from .source import file_sha256

__all__ = ["MIN_CURRENT_SPAN_A", "MIN_THROTTLE_SPAN", "FlightSource", "fit_flight",
           "field_error", "flight_source", "heading_error_deg", "ned_scatter",
           "record_instead", "write_demo_flight"]

#: Least range of the battery current (A) that makes a current interference term worth fitting.
MIN_CURRENT_SPAN_A = 2.0
#: Least range of the throttle (0..1) that makes a throttle interference term worth fitting.
MIN_THROTTLE_SPAN = 0.2


@dataclass
class FlightSource:
    """A log's compass readings with what the fit needs at each one."""

    path: Path
    recording: LogRecording
    flight: FlightData
    t: np.ndarray             # s
    raw: np.ndarray           # (N, 3) body frame, calibration undone, in ``unit``
    logged: np.ndarray        # (N, 3) body frame as the autopilot corrected it
    dcm: np.ndarray           # (N, 3, 3) body to NED
    x: np.ndarray | None      # interference regressor
    x_name: str | None
    x_per: str | None         # "A" or "throttle"
    unit: str
    to_body: np.ndarray       # sensor (the autopilot's correction frame) to body
    yaw_from_compass: bool
    yaw_reason: str
    trim_deg: tuple[float, float] | None = None  # ArduPilot AHRS_TRIM_X/Y applied to dcm


#: ArduPilot ``EK3_SRC1_YAW`` values whose yaw is not the compass's (``AP_NavEKF_Source.h``
#: ``SourceYaw``: 2 GPS, 6 ExternalNav, 8 GSF); 0 none and 1 compass are, and 3 (GPS with
#: compass fallback) may be.
AP_YAW_NOT_COMPASS = {2: "GPS", 6: "ExternalNav", 8: "the GSF (IMU and GPS velocity)"}


def _flag(p: Any, name: str, bit: int) -> bool:
    try:
        return bool(int(float(p.get(name, 0))) & bit)
    except (TypeError, ValueError):
        return False


def _yaw_from_compass(rec: LogRecording, instance: int) -> tuple[bool, str]:
    """Whether the attitude's yaw may have come from this compass, by the log's parameters.

    Only a yaw that the parameters show came from elsewhere is used; a yaw from an estimator
    that fused this compass is not, however far it strays from the logged compass heading:
    the estimator learns compass offsets in flight (ArduPilot ``EK2/EK3_MAG_CAL``, PX4's
    magnetometer bias states) and blends them with the gyroscopes, so its yaw carries the
    compass's own errors and a fit to it would be circular. Without parameters the yaw is
    taken to be the compass's.
    """
    p = rec.params
    if rec.format == "ardupilot-dataflash":
        sfx = "" if instance == 0 else str(instance + 1)
        use = f"COMPASS_USE{sfx}"
        if float(p.get(use, 1)) == 0:
            return False, f"{use} = 0: the autopilot did not use this compass for its yaw"
        src = p.get("EK3_SRC1_YAW")
        if src is not None and float(p.get("AHRS_EKF_TYPE", 3)) == 3 and \
                int(float(src)) in AP_YAW_NOT_COMPASS:
            return False, (f"EK3_SRC1_YAW = {int(float(src))}: the yaw came from "
                           f"{AP_YAW_NOT_COMPASS[int(float(src))]}, not the compass")
        # the compass the estimator used: COMPASS_PRIMARY (firmware to 4.0), else the first
        # one in use
        used = [k for k in range(3) if float(p.get(f"COMPASS_USE{'' if k == 0 else k + 1}",
                                                   1 if k == 0 else 0)) != 0]
        prim = p.get("COMPASS_PRIMARY")
        first = int(float(prim)) if prim is not None and int(float(prim)) in used else (
            used[0] if used else instance)
        if first != instance:
            return False, (f"the yaw came from compass {first + 1} (COMPASS_PRIMARY / the first "
                           f"compass in use), not this one (compass {instance + 1})")
        return True, (f"{use} = 1: the autopilot's yaw came from this compass (with the offsets "
                      "its estimator learned in flight), so only roll and pitch are used")
    if rec.format == "px4-ulog":
        if float(p.get("SYS_HAS_MAG", 1)) == 0 or float(p.get("EKF2_MAG_TYPE", 0)) == 5:
            return False, ("SYS_HAS_MAG = 0 / EKF2_MAG_TYPE = 5: PX4 did not fuse the "
                           "magnetometer")
        if _flag(p, "EKF2_GPS_CTRL", 8) or _flag(p, "EKF2_AID_MASK", 128):
            return False, ("EKF2_GPS_CTRL / EKF2_AID_MASK: the yaw came from a dual-antenna "
                           "GPS, which stops PX4's magnetometer heading fusion")
        if _flag(p, "EKF2_EV_CTRL", 8) or _flag(p, "EKF2_AID_MASK", 16):
            return False, ("EKF2_EV_CTRL / EKF2_AID_MASK: the yaw came from external vision, "
                           "not the magnetometer")
        return True, ("PX4 fused the magnetometer into its yaw (SYS_HAS_MAG, EKF2_MAG_TYPE), so "
                      "only roll and pitch are used")
    return True, "the log does not say where its yaw came from, so only roll and pitch are used"


def flight_source(path: str | Path, request: FitRequest) -> FlightSource:
    """The compass readings of log ``path`` paired with attitude, current or throttle."""
    p = Path(path)
    instance = request.source.instance
    logged_rec = read_log(p, instance=instance)  # read once: the logged and the raw readings
    try:
        rec = undo_autopilot_calibration(logged_rec)
    except CalibrationError as exc:
        raise CalibrationError(f"--method attitude fits the raw compass and needs the "
                               f"autopilot's calibration undone, which fails here: {exc}") from None
    mag = rec.stream("mag")
    flight = read_flight(p, time_origin_us=rec.meta.get("time_origin_us"))
    if flight.attitude is None:
        raise CalibrationError(
            f"{p} has no attitude (ArduPilot ATT, PX4 vehicle_attitude): a compass calibration "
            "from the flight needs the vehicle's attitude at each compass reading; fit the "
            "readings alone instead (--method ellipsoid)")
    a = flight.attitude.t
    keep = (mag.t >= a[0]) & (mag.t <= a[-1])
    if keep.sum() < 30:
        raise CalibrationError(f"{p}: only {int(keep.sum())} compass readings fall within the "
                               "logged attitude's time span; at least 30 are needed")
    t = mag.t[keep]
    raw = mag.data[keep]
    logged = logged_rec.stream("mag").data[keep]
    to_body = np.eye(3)
    if rec.autopilot is not None and rec.autopilot.mag is not None:
        to_body = np.asarray(rec.autopilot.mag.rotation)
    raw_body = raw @ to_body.T
    x, x_name, x_per = None, None, None
    cur, thr = flight.current, flight.throttle
    if cur is not None:
        xc = cur.at(t)
        if np.ptp(xc) >= MIN_CURRENT_SPAN_A:
            x, x_name, x_per = xc, cur.name, "A"
    if x is None and thr is not None:
        xt = thr.at(t)
        if np.ptp(xt) >= MIN_THROTTLE_SPAN:
            x, x_name, x_per = xt, thr.name, "throttle"
    used, why = _yaw_from_compass(rec, instance or 0)
    dcm = flight.dcm(t)
    trim = _ardupilot_trim(rec)
    if trim is not None:
        dcm = dcm @ euler_to_dcm([trim[0]], [trim[1]], [0.0])[0]
    return FlightSource(path=p, recording=rec, flight=flight, t=t, raw=raw_body, logged=logged,
                        dcm=dcm, x=x, x_name=x_name, x_per=x_per, unit=mag.unit,
                        to_body=to_body, yaw_from_compass=used, yaw_reason=why, trim_deg=trim)


def _ardupilot_trim(rec: LogRecording) -> tuple[float, float] | None:
    """ArduPilot's ``AHRS_TRIM_X/Y`` (deg) when not zero. ``ATT`` is the attitude of the vehicle
    body, the compass reads in the autopilot's: ``R_vehicle = R_autopilot @ R_trim.T`` with
    ``R_trim = from_euler(AHRS_TRIM_X, AHRS_TRIM_Y, 0)`` (``AP_AHRS::
    update_trim_rotation_matrices``; ``AP_AHRS_DCM`` and ``NavEKF3_core::getRotationBodyToNED``
    multiply by ``get_rotation_vehicle_body_to_autopilot_body()``), so the compass's attitude
    is ``R_vehicle @ R_trim``. (MAGFit adds the trims to the logged roll and pitch, the same to
    first order.)"""
    if rec.format != "ardupilot-dataflash":
        return None
    try:
        tx, ty = (float(rec.params.get(f"AHRS_TRIM_{a}", 0.0)) for a in "XY")
    except (TypeError, ValueError):
        return None
    if not (math.isfinite(tx) and math.isfinite(ty)) or (tx == 0 and ty == 0):
        return None
    return math.degrees(tx), math.degrees(ty)


def ned_scatter(calibrated: Any, dcm: Any) -> float:
    """RMS distance of the calibrated readings turned to NED by the attitude from their mean:
    the scatter a calibration leaves in the field, which should hold still."""
    v = np.einsum("nij,nj->ni", np.asarray(dcm), np.asarray(calibrated))
    return float(np.sqrt(((v - v.mean(axis=0)) ** 2).sum(axis=1).mean()))


def heading_error_deg(calibrated: Any, dcm: Any, declination_deg: float | None) -> np.ndarray:
    """Compass heading (tilt-compensated with the attitude's roll and pitch, plus the
    declination) minus the attitude's yaw, wrapped to +-180 deg; without a declination the
    circular mean is taken out."""
    d = np.asarray(dcm)
    h = np.einsum("nij,nj->ni", tilt_dcm(d), np.asarray(calibrated))
    psi = np.arctan2(-h[:, 1], h[:, 0])
    yaw = np.arctan2(d[:, 1, 0], d[:, 0, 0])
    e = psi - yaw
    if declination_deg is None:
        e = e - math.atan2(np.sin(e).mean(), np.cos(e).mean())
    else:
        e = e + math.radians(declination_deg)
    return np.degrees(np.angle(np.exp(1j * e)))


def _field(request: FitRequest, src: FlightSource) -> tuple[np.ndarray | None, str, Any]:
    """The Earth's field (NED, in the source's unit), where it came from, the ExpectedField."""
    from ..methods.field import expected_field

    loc = request.field.location
    how = "--location"
    if loc is None and src.flight.position is not None:
        loc, how = src.flight.position, f"the log's {src.flight.position_source}"
    if loc is None:
        return None, "fitted (no position in the log and no --location)", None
    ef = expected_field(*loc, date=request.field.date)
    b = np.array(ef.vector_ned_ut()) * unit_factor("uT", src.unit)
    return b, f"World Magnetic Model at {how}", ef


def _fit(src: FlightSource, sel: np.ndarray, b: np.ndarray | None, heading: str,
         soft: str) -> AttitudeFit:
    x = None if src.x is None else src.x[sel]
    return fit_attitude(src.raw[sel], src.dcm[sel], x=x, field_ned=b, heading=heading,
                        soft_iron=soft)


def field_error(calibrated: Any, dcm: Any, field_ned: Any, heading: str) -> np.ndarray:
    """Per reading, the distance (in the readings' unit) between the calibrated reading and the
    field as the fit compares it: turned into the body by the attitude (``heading=
    "attitude"``), or by the attitude's roll and pitch and the compass's own heading
    (``"free"``: ``|(|h_xy| - H, h_z - Z)|`` with ``h`` the reading turned level; MAGFit's
    measure)."""
    c, d, b = np.asarray(calibrated, float), np.asarray(dcm, float), np.asarray(field_ned, float)
    if heading == "attitude":
        return np.asarray(np.linalg.norm(c - np.einsum("nji,j->ni", d, b), axis=1))
    h = np.einsum("nij,nj->ni", tilt_dcm(d), c)
    return np.asarray(np.hypot(np.hypot(h[:, 0], h[:, 1]) - math.hypot(b[0], b[1]),
                               h[:, 2] - b[2]))


def _metrics(src: FlightSource, fit: AttitudeFit, sel: np.ndarray,
             declination: float | None) -> dict[str, Any]:
    x = None if src.x is None else src.x[sel]
    after = fit.apply(src.raw[sel], x)
    before = src.logged[sel] @ src.to_body.T
    eb = heading_error_deg(before, src.dcm[sel], declination)
    ea = heading_error_deg(after, src.dcm[sel], declination)
    fb = field_error(before, src.dcm[sel], fit.field_ned, fit.heading)
    fa = field_error(after, src.dcm[sel], fit.field_ned, fit.heading)
    return {
        "scatter_before": ned_scatter(before, src.dcm[sel]),
        "scatter_after": ned_scatter(after, src.dcm[sel]),
        "heading_rms_deg_before": float(np.sqrt((eb ** 2).mean())),
        "heading_rms_deg_after": float(np.sqrt((ea ** 2).mean())),
        "field_error_rms_before": float(np.sqrt((fb ** 2).mean())),
        "field_error_rms_after": float(np.sqrt((fa ** 2).mean())),
    }


def _device_id(rec: LogRecording) -> int | None:
    """The compass's device id: as the log's sensor topics name it, else (PX4) the
    ``CAL_MAGn_ID`` of the calibration slot whose calibration was undone."""
    dev = (rec.meta.get("device_ids") or {}).get("mag")
    if dev is None and rec.format == "px4-ulog" and rec.autopilot is not None and \
            rec.autopilot.mag is not None:
        v = rec.params.get(f"CAL_MAG{rec.autopilot.mag.index}_ID")
        try:
            dev = int(v) if v is not None and int(v) != 0 else None
        except (TypeError, ValueError):
            dev = None
    return dev


def record_instead(heading: str, field_fitted: bool, src: FlightSource) -> str:
    """What to fly instead when a flight does not calibrate its compass (the validity gate's
    advice for this part, ``stats["record_instead"]``)."""
    out = ["fly a log with several full, slow turns through every heading, with some roll and "
           "pitch in each (figure eights, banked circles), away from steel structures"]
    if src.x is None:
        out.append("vary the throttle -- climbs and descents at every heading -- so that the "
                   "battery current (logged: BAT / battery_status) changes independently of "
                   "the heading and the interference per amp can be told from the hard iron")
    else:
        out.append("vary the throttle at every heading, not only while turning one way, so "
                   f"that the interference per {'amp' if src.x_per == 'A' else 'unit of throttle'}"
                   " can be told from the hard iron")
    if field_fitted:
        out.append("log GPS (or give the place of the flight: --location LAT,LON) so that the "
                   "World Magnetic Model's field is known instead of fitted")
    if heading == "free":
        out.append("a yaw that does not come from this compass (ArduPilot EK3_SRC1_YAW = 2, "
                   "GPS, or COMPASS_USE = 0; PX4 EKF2_MAG_TYPE = 5 with GPS yaw) lets the fit "
                   "use the heading too")
    out.append("or calibrate on the ground by turning the vehicle through every orientation "
               "(--method ellipsoid)")
    return "; ".join(out)


def fit_flight(path: str | Path, request: FitRequest) -> tuple[SensorCalibration, FlightSource]:
    """The flight calibration of the compass in log ``path`` (module docstring), not yet judged
    by the validity gate, and the source it was fitted on."""
    if request.sensor != "mag":
        raise CalibrationError("--method attitude calibrates the compass: use --sensor mag")
    src = flight_source(path, request)
    b, field_how, ef = _field(request, src)
    n = len(src.t)
    # the parameters say whether the yaw may have come from this compass (then only roll and
    # pitch are used); how far the logged compass heading strays from it is recorded
    logged_err = heading_error_deg(src.logged @ src.to_body.T, src.dcm, None)
    heading = "free" if src.yaw_from_compass else "attitude"
    soft = {"sphere": "scale", "axis": "diagonal"}.get(request.model, "full")
    full = _fit(src, np.arange(n), b, heading, soft)
    half = n // 2
    first, second = np.arange(half), np.arange(half, n)
    decl = ef.declination_deg if ef is not None else (
        math.degrees(math.atan2(full.field_ned[1], full.field_ned[0]))
        if heading == "attitude" else None)
    held_out: dict[str, Any] = {}
    try:
        part_fit = _fit(src, first, b, heading, soft)
        held_out = _metrics(src, part_fit, second, decl)
        held_out.update({
            "fitted_on": "first half", "judged_on": "second half", "split_index": int(half),
            "declination_deg": decl,
            # the first half's fit in the body frame, for the report's figure
            "fit": {"offset": [float(c) for c in part_fit.offset],
                    "matrix": [[float(c) for c in row] for row in part_fit.matrix],
                    "interference": None if part_fit.interference is None else
                    [float(c) for c in part_fit.interference],
                    "field_ned": [float(c) for c in part_fit.field_ned]}})
    except CalibrationError as exc:
        held_out = {"error": str(exc)}
    whole = _metrics(src, full, np.arange(n), decl)
    o, m, v = full.offset, full.matrix, full.interference
    r = src.to_body
    if not np.allclose(r, np.eye(3)):  # back into the frame the autopilot corrects in
        o, m = r.T @ o, r.T @ m @ r
        v = None if v is None else r.T @ v
    und = list(full.undetermined)
    if full.rms_pct > B.ATTITUDE_MAX_RESIDUAL_PCT:
        und.append(f"the field does not hold still: the residual RMS is {full.rms_pct:.3g} % of "
                   f"the field (at most {B.ATTITUDE_MAX_RESIDUAL_PCT:g} %), so the compass "
                   "sees fields the model does not explain (iron or currents that move, or an "
                   "attitude that is not the compass's)")
    gain = None
    if "scatter_after" in held_out and held_out["scatter_after"] > 0:
        gain = held_out["scatter_before"] / held_out["scatter_after"]
        held_out["scatter_gain"] = gain
        if gain < B.ATTITUDE_MIN_SCATTER_GAIN:
            und.append(
                f"on the half of the flight it was not fitted to it shrinks the scatter of the "
                f"field turned to NED only {gain:.2f} times (at least "
                f"{B.ATTITUDE_MIN_SCATTER_GAIN:g}): the log's own calibration is about as good, "
                "or the field does not hold still")
    warnings = [f"{k}: {w}" for k, w in full.held.items()]
    stats: dict[str, Any] = {
        "model": "attitude",
        "n": int(full.n),
        "n_input": int(n),
        "rms": float(full.rms),
        "radius": float(full.field_strength),
        "rms_pct_of_radius": float(full.rms_pct),
        "iterations": int(full.iterations),
        "converged": bool(full.converged),
        "stderr": {k: float(s) for k, s in full.stderr.items() if math.isfinite(s)},
        "warnings": warnings,
        "rejected": [int(i) for i in full.rejected],
        "norms": _norm_stats(np.linalg.norm(full.apply(src.raw, src.x), axis=1)),
        "undetermined": und,
        "attitude": {
            "heading": heading,
            "heading_reason": src.yaw_reason,
            "logged_heading_error_deg": float(np.sqrt((logged_err ** 2).mean())),
            "trim_deg": None if src.trim_deg is None else list(src.trim_deg),
            "field": field_how,
            "field_ned": [float(c) for c in full.field_ned],
            "soft_iron": soft,
            "held": dict(full.held),
            "attitude_source": src.flight.attitude.name if src.flight.attitude else None,
            "frame": "body" if np.allclose(r, np.eye(3)) else "sensor (turned back from body)",
            "whole": whole,
            "held_out": held_out,
        },
        "log": {"format": src.recording.format, "stream": src.recording.stream("mag").name,
                "instance": request.source.instance, "undo_autopilot_cal": True,
                "calibrated_by_autopilot": False, "samples": int(n),
                "device_id": _device_id(src.recording)},
    }
    if und:
        stats["record_instead"] = record_instead(heading, b is None, src)
    if v is not None:
        stats["interference"] = {"per": src.x_per, "vector": [float(c) for c in v],
                                 "unit": src.unit, "source": src.x_name}
    part = SensorCalibration(offset=o, matrix=m, raw_unit=src.unit, unit=src.unit,
                             radius=float(full.field_strength), model="attitude", stats=stats,
                             input_sha256=file_sha256(src.path), source=str(src.path),
                             expected_field=ef)
    return part, src



#: Where the simulated flight of ``triaxcal demo --flight`` flies (lat deg, lon deg, alt m).
DEMO_LOCATION = (47.37, 8.54, 400.0)


def write_demo_flight(out_dir: str | Path, *, location: tuple[float, float, float] = DEMO_LOCATION,
                      date: str | None = None, seed: int = 7) -> dict[str, Path]:
    """Write the simulated flight of :mod:`triaxcal.sim.flight` into ``out_dir``:
    ``flight.BIN`` (ArduPilot DataFlash), ``flight.ulg`` (the same flight as a PX4 ULog) and
    ``flight_truth.json`` (the truth in ArduPilot's convention), with the World Magnetic
    Model's field at ``location`` on ``date`` (default today, as ``triaxcal fit`` takes it) --
    what ``triaxcal demo --flight`` writes. ``triaxcal fit DIR/flight.BIN --sensor mag
    --method attitude`` recovers the truth (the log's GPS gives the place)."""
    from ..methods.field import expected_field
    from ..sim.flight import write_flight

    ef = expected_field(*location, date=date)
    field_mg = np.array(ef.vector_ned_ut()) * unit_factor("uT", "mG")
    return write_flight(out_dir, field_mg, location=location, seed=seed, field_date=ef.date)
