"""MAGFit (MAVProxy) beside triaxcal's flight compass fit, on the same logs, in one run.

Run: ``pip install --no-deps MAVProxy`` (1.8.75 has ``MAVProxy/modules/lib/magfit.py``; its
other dependencies are for the ground station), then::

    python benches/bench_magfit.py [--quick] [--markdown docs/benchmarks/magfit.md]

``--quick`` gives both tools every 4th reading (MAGFit's ``Reduce``). The table written to
``--markdown`` is the one in ``docs/benchmarks/magfit.md``.

Logs: the simulated flight of :mod:`triaxcal.sim.flight` (DataFlash, with the truth), and the
two ArduPilot logs in ``../shared/realdata/ardupilot-erle-logs`` when present. Each log is
split in time at its middle compass reading: both tools fit the first half, and both fits are
judged on the second half by the same code (the field error RMS in mG: the calibrated reading
against the World Magnetic Model's field turned into the body by the logged attitude, and
against the field turned by the corrected compass's own heading, which is MAGFit's measure).

The same options for both:

* the same field: the World Magnetic Model's at the same latitude and longitude
  (:func:`triaxcal.expected_field`), given to MAGFit in place of pymavlink's table field
  (``mavextra.expected_earth_field_lat_lon``; the difference is printed). The Erle logs have no
  GPS fix: their place is assumed (Erle Robotics, Vitoria-Gasteiz) and is the same for both;
* the same readings (the stored calibration undone from the logged ``MAG`` with the offsets
  each ``MAG`` record carries), the same attitude (``ATT``, with ``AHRS_TRIM`` put back),
  and the same battery current: MAGFit reads only ``BAT``; the simulated flight logs ``BAT``
  (and ``CURR``), the 2016 logs only ``CURR``, which is handed to MAGFit under the name ``BAT``
  (centiamps to amps as triaxcal reads them). triaxcal fits the current too, although its own
  command would take the throttle where the current hardly varies (Erle-Brain3);
* MAGFit as its GUI runs it: elliptical and CMOT, offsets within +-1500 mG, diagonals
  0.8..1.2, off-diagonals +-0.2, COMPASS_MOT within +-10 mG/A, ``COMPASS_SCALE`` held at 1,
  every reading (``Reduce`` 1), the log's own ``COMPASS_ORIENT``. Its wx GUI modules
  (``wx_processguard``, ``wx_loader``) are replaced by empty modules when wxPython is not
  installed; the fit never touches them. Its plot is not drawn (the run stops where it prints
  the parameters);
* triaxcal's :func:`triaxcal.methods.attitude.fit_attitude`, full soft iron, with the heading
  rule of ``triaxcal fit --method attitude``: the attitude's yaw only where the log's
  parameters show it did not come from this compass.

Times: the fit alone (MAGFit's ``fit_WWW``; ``fit_attitude``, best of 5), reading the log and
fitting (MAGFit's ``magfit()`` from opening the log to the end of its fit; triaxcal's
``flight_source`` + ``fit_attitude``), and triaxcal's whole ``fit_flight`` (what ``triaxcal fit
LOG --method attitude`` runs: read, fit, the held-out fit and check). Wall clock and CPU time
of this process; one BLAS thread, ``OPENBLAS_CORETYPE`` / ``OPENBLAS_L2_SIZE`` unset, the BLAS
kernel recorded with threadpoolctl.
"""

from __future__ import annotations

import os

for _k in ("OPENBLAS_CORETYPE", "OPENBLAS_L2_SIZE"):
    os.environ.pop(_k, None)
for _k in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_k] = "1"

import argparse  # noqa: E402
import contextlib  # noqa: E402
import datetime  # noqa: E402
import io  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import platform  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
import types  # noqa: E402
from dataclasses import dataclass, field  # noqa: E402
from importlib import metadata  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402
import threadpoolctl  # noqa: E402
import triaxcal as tc  # noqa: E402
from triaxcal.calibration.flight import (  # noqa: E402
    FlightSource,
    fit_flight,
    flight_source,
    heading_error_deg,
    ned_scatter,
)
from triaxcal.calibration.request import FieldOptions, FitRequest  # noqa: E402
from triaxcal.methods.attitude import fit_attitude, tilt_dcm  # noqa: E402
from triaxcal.sim.flight import write_flight  # noqa: E402

REAL = Path(__file__).resolve().parents[2] / "shared" / "realdata" / "ardupilot-erle-logs"
ZURICH = (47.37, 8.54, 400.0)
#: The Erle logs have no GPS fix; Erle Robotics was in Vitoria-Gasteiz (assumed place).
VITORIA = (42.85, -2.67, 525.0)


@dataclass
class Case:
    name: str
    path: Path
    location: tuple[float, float, float]
    place: str
    truth: dict[str, Any] | None = None


@dataclass
class Result:
    """One tool on one log: the calibration in ArduPilot's terms and its times."""

    ofs: np.ndarray                 # COMPASS_OFS, ADDED to raw (mG)
    scale: float                    # COMPASS_SCALE
    matrix: np.ndarray              # DIA / ODI
    mot: np.ndarray                 # COMPASS_MOT (mG per A)
    n: int
    fit_s: float
    fit_cpu_s: float
    read_fit_s: float
    read_fit_cpu_s: float
    extra: dict[str, Any] = field(default_factory=dict)

    def apply(self, raw: np.ndarray, current: np.ndarray) -> np.ndarray:
        """``AP_Compass_Backend::correct_field``: ``M ((raw + OFS) * SCALE) + MOT * I``."""
        return ((raw + self.ofs) * self.scale) @ self.matrix.T + current[:, None] * self.mot


# ------------------------------------------------------------------------------------ MAGFit


def import_magfit() -> tuple[Any, bool]:
    """MAVProxy's magfit module; its wx GUI imports stubbed when wxPython is missing."""
    stubbed = False
    try:
        import wx  # noqa: F401
    except ImportError:
        stubbed = True
        guard = types.ModuleType("MAVProxy.modules.lib.wx_processguard")
        loader = types.ModuleType("MAVProxy.modules.lib.wx_loader")
        loader.wx = types.SimpleNamespace(Dialog=object)  # type: ignore[attr-defined]
        sys.modules[guard.__name__] = guard
        sys.modules[loader.__name__] = loader
    from MAVProxy.modules.lib import magfit

    return magfit, stubbed


class _Bat:
    """A ``CURR`` record as MAGFit's ``BAT``: ``Curr`` in A (older firmware logged centiamps
    as an integer, which triaxcal's reader divides by 100 too)."""

    def __init__(self, m: Any) -> None:
        v = m.Curr
        self.Curr = float(v) / 100.0 if isinstance(v, int) else float(v)
        self._timestamp = m._timestamp

    def get_type(self) -> str:
        return "BAT"


class CurrAsBat:
    """A pymavlink log whose ``CURR`` records MAGFit sees as ``BAT`` (it reads only ``BAT``)."""

    def __init__(self, mlog: Any) -> None:
        self.mlog = mlog

    def rewind(self) -> None:
        self.mlog.rewind()

    def recv_match(self, type: Any = None, **kw: Any) -> Any:  # noqa: A002 (pymavlink's name)
        types_ = None if type is None else ["CURR" if t == "BAT" else t for t in type]
        m = self.mlog.recv_match(type=types_, **kw)
        return _Bat(m) if m is not None and m.get_type() == "CURR" else m


def run_magfit(magfit: Any, case: Case, field_ned: np.ndarray, split_ts: float, reduce: int,
               orient: int, curr_as_bat: bool) -> Result:
    from pymavlink import mavextra, mavutil
    from pymavlink.rotmat import Vector3

    class _Stop(Exception):
        pass

    got: dict[str, Any] = {}
    orig_fit, orig_show = magfit.fit_WWW, magfit.Correction.show_parms
    orig_ef, orig_mf = mavextra.expected_earth_field_lat_lon, mavextra.get_mag_field_ef

    def timed_fit() -> Any:
        t, c = time.perf_counter(), time.process_time()
        out = orig_fit()
        got.update(fit_s=time.perf_counter() - t, fit_cpu_s=time.process_time() - c,
                   end=time.perf_counter(), end_cpu=time.process_time(), n=len(magfit.data))
        return out

    def stop(self: Any) -> None:  # where magfit() prints the parameters: the result
        got["c"] = self
        raise _Stop

    b = field_ned
    decl = math.degrees(math.atan2(b[1], b[0]))
    incl = math.degrees(math.atan2(b[2], math.hypot(b[0], b[1])))
    magfit.fit_WWW = timed_fit
    magfit.Correction.show_parms = stop
    mavextra.expected_earth_field_lat_lon = lambda lat, lon: Vector3(*map(float, b))
    mavextra.get_mag_field_ef = lambda lat, lon: (decl, incl, float(np.linalg.norm(b)) / 1000)
    magfit.margs = {
        "Magnetometer": "MAG", "Attitude": "ATT",
        "Orientation": magfit.RotationIDToString(orient),
        "Lattitude": case.location[0], "Longitude": case.location[1],
        "BatteryNum": 1, "Reduce": reduce, "Offsets": True, "OffsetMax": 1500,
        "ScaleMin": 1.0, "ScaleMax": 1.0, "Elliptical": True,
        "DiagonalMin": 0.8, "DiagonalMax": 1.2, "OffDiagMin": -0.2, "OffDiagMax": 0.2,
        "CMOT": True, "CMOT NoChange": False, "CMOT Max": 10.0,
    }
    out = io.StringIO()
    try:
        with contextlib.redirect_stdout(out):
            t0, c0 = time.perf_counter(), time.process_time()
            mlog = mavutil.mavlink_connection(str(case.path))
            if curr_as_bat:
                mlog = CurrAsBat(mlog)
            try:
                magfit.magfit(mlog, lambda ts: 0 if ts < split_ts else 1)
            except _Stop:
                pass
    finally:
        magfit.fit_WWW, magfit.Correction.show_parms = orig_fit, orig_show
        mavextra.expected_earth_field_lat_lon, mavextra.get_mag_field_ef = orig_ef, orig_mf
    if "c" not in got:
        raise RuntimeError(f"MAGFit did not fit {case.name}:\n{out.getvalue()[-2000:]}")
    c = got["c"]
    m = np.array([[c.diag.x, c.offdiag.x, c.offdiag.y], [c.offdiag.x, c.diag.y, c.offdiag.z],
                  [c.offdiag.y, c.offdiag.z, c.diag.z]])
    values = {"COMPASS_OFS": [c.offsets.x, c.offsets.y, c.offsets.z],
              "COMPASS_DIA": [c.diag.x, c.diag.y, c.diag.z],
              "COMPASS_ODI": [c.offdiag.x, c.offdiag.y, c.offdiag.z],
              "COMPASS_MOT": [c.cmot.x, c.cmot.y, c.cmot.z]}
    limits = {"COMPASS_OFS": (-1500, 1500), "COMPASS_DIA": (0.8, 1.2),
              "COMPASS_ODI": (-0.2, 0.2), "COMPASS_MOT": (-10.0, 10.0)}
    on_bound = [f"{k}_{a}" for k, v in values.items() for a, x in zip("XYZ", v)
                if min(abs(x - limits[k][0]), abs(x - limits[k][1])) <= 1e-6 * max(
                    1.0, abs(limits[k][1]))]
    return Result(ofs=np.array([c.offsets.x, c.offsets.y, c.offsets.z]), scale=float(c.scaling),
                  matrix=m, mot=np.array([c.cmot.x, c.cmot.y, c.cmot.z]), n=got["n"],
                  fit_s=got["fit_s"], fit_cpu_s=got["fit_cpu_s"], read_fit_s=got["end"] - t0,
                  read_fit_cpu_s=got["end_cpu"] - c0,
                  extra={"on_bound": on_bound,
                         "log": [ln for ln in out.getvalue().splitlines()
                                 if "Optimization" in ln or "Iterations" in ln
                                 or "evaluations" in ln]})


# ---------------------------------------------------------------------------------- triaxcal


def _request(case: Case) -> FitRequest:
    return FitRequest(sensor="mag", method="attitude", field=FieldOptions(location=case.location))


def _current(src: FlightSource) -> np.ndarray:
    cur = src.flight.current
    if cur is None:
        raise RuntimeError(f"{src.path} has no battery current for MAGFit's CMOT")
    return cur.at(src.t)


def run_triaxcal(case: Case, field_ned: np.ndarray, first: np.ndarray, reduce: int,
                 rounds: int) -> tuple[Result, FlightSource]:
    heading = "attitude"

    def fit(src: FlightSource) -> Any:
        sel = first[::reduce]
        return fit_attitude(src.raw[sel], src.dcm[sel], x=_current(src)[sel],
                            field_ned=field_ned, heading=heading)

    t0, c0 = time.perf_counter(), time.process_time()
    src = flight_source(case.path, _request(case))
    heading = "free" if src.yaw_from_compass else "attitude"
    f = fit(src)
    read_fit, read_fit_cpu = time.perf_counter() - t0, time.process_time() - c0
    best, best_cpu = math.inf, math.inf
    for _ in range(rounds):
        t, c = time.perf_counter(), time.process_time()
        f = fit(src)
        best, best_cpu = min(best, time.perf_counter() - t), min(best_cpu, time.process_time() - c)
    t, c = time.perf_counter(), time.process_time()
    part, _ = fit_flight(case.path, _request(case))
    whole, whole_cpu = time.perf_counter() - t, time.process_time() - c
    verdict = tc.check_part(part, "mag")
    assert f.interference is not None
    # the same fit on the readings truncated to whole milligauss, as MAGFit's remove_offsets does
    sel = first[::reduce]
    ft = fit_attitude(np.trunc(src.raw[sel]), src.dcm[sel], x=_current(src)[sel],
                      field_ned=field_ned, heading=heading)
    assert ft.interference is not None
    trunc = Result(ofs=-ft.offset, scale=1.0, matrix=ft.matrix, mot=ft.interference, n=ft.n,
                   fit_s=math.nan, fit_cpu_s=math.nan, read_fit_s=math.nan,
                   read_fit_cpu_s=math.nan)
    res = Result(ofs=-f.offset, scale=1.0, matrix=f.matrix, mot=f.interference, n=f.n,
                 fit_s=best, fit_cpu_s=best_cpu, read_fit_s=read_fit,
                 read_fit_cpu_s=read_fit_cpu,
                 extra={"heading": heading, "whole_s": whole, "whole_cpu_s": whole_cpu,
                        "held": list(f.held), "rejected": len(f.rejected),
                        "verdict": verdict, "trunc": trunc})
    return res, src


# ---------------------------------------------------------------------------------- judging


def judge(cal: np.ndarray, dcm: np.ndarray, b: np.ndarray, decl: float) -> dict[str, float]:
    """Field error RMS (mG) against the field turned by the attitude and against the field
    turned by the corrected compass's own heading (MAGFit's wmm_error, squared here), the
    heading error RMS (deg) and the scatter of the field turned to NED (mG)."""
    pred = np.einsum("nji,j->ni", dcm, b)
    h = np.einsum("nij,nj->ni", tilt_dcm(dcm), cal)
    own = np.hypot(np.hypot(h[:, 0], h[:, 1]) - math.hypot(b[0], b[1]), h[:, 2] - b[2])
    he = heading_error_deg(cal, dcm, decl)
    return {"att": float(np.sqrt((np.linalg.norm(cal - pred, axis=1) ** 2).mean())),
            "own": float(np.sqrt((own ** 2).mean())),
            "mean_own": float(own.mean()),
            "heading": float(np.sqrt((he ** 2).mean())),
            "scatter": ned_scatter(cal, dcm)}


def split(case: Case, src: FlightSource) -> tuple[np.ndarray, np.ndarray, float]:
    """The first and second half of triaxcal's readings by time, and the split time on
    pymavlink's clock (MAGFit's ``timestamp_in_range``)."""
    from pymavlink import mavutil

    t0 = src.recording.meta["time_origin_us"]
    t_us = np.round(src.t * 1e6).astype(np.int64) + t0
    split_us = int(t_us[len(t_us) // 2])
    with contextlib.redirect_stdout(io.StringIO()):
        mlog = mavutil.mavlink_connection(str(case.path))
        ts = None
        while True:
            m = mlog.recv_match(type=["MAG"])
            if m is None:
                break
            if int(m.TimeUS) >= split_us:
                ts = m._timestamp
                break
    if ts is None:
        raise RuntimeError(f"{case.path}: no MAG record after the split")
    first = np.flatnonzero(t_us < split_us)
    return first, np.flatnonzero(t_us >= split_us), float(ts)


# ----------------------------------------------------------------------------------- output


def fmt3(v: Any, d: int = 1) -> str:
    return ", ".join(f"{x:.{d}f}" for x in np.asarray(v, float))


def case_rows(case: Case, mf: Result, tx: Result, before: dict[str, float],
              after: dict[str, dict[str, float]], n2: int) -> list[str]:
    lines = [f"### {case.name}", "",
             f"Place: {case.place}. Fitted on the first half ({tx.n} readings for triaxcal "
             f"after its outlier round, {mf.n} for MAGFit), judged on the second "
             f"({n2} readings). triaxcal's heading: {tx.extra['heading']}.", "",
             "| held-out (second half) | log's calibration | MAGFit | triaxcal | triaxcal on "
             "int() readings |", "|---|---:|---:|---:|---:|"]
    names = {"att": "field error RMS, field turned by the attitude (mG)",
             "own": "field error RMS, field turned by the compass's own heading (mG)",
             "mean_own": "mean field error, own heading (MAGFit's criterion, mG)",
             "heading": "heading error RMS against the attitude's yaw (deg)",
             "scatter": "scatter of the field turned to NED (mG)"}
    for k, label in names.items():
        lines.append(f"| {label} | {before[k]:.2f} | {after['magfit'][k]:.2f} | "
                     f"{after['triaxcal'][k]:.2f} | {after['trunc'][k]:.2f} |")
    lines += ["", "| coefficient (ArduPilot's) | " + ("truth | " if case.truth else "")
              + "MAGFit | triaxcal | triaxcal on int() readings |",
              "|---|" + ("---:|" if case.truth else "") + "---:|---:|---:|"]
    tr = tx.extra["trunc"]
    t = case.truth
    coeffs = [("COMPASS_OFS_X/Y/Z (mG)", lambda r: r.ofs, t and t["COMPASS_OFS"], 1),
              ("COMPASS_DIA_X/Y/Z x SCALE", lambda r: np.diag(r.matrix) * r.scale,
               t and t["COMPASS_DIA"], 3),
              ("COMPASS_ODI_X/Y/Z x SCALE",
               lambda r: np.array([r.matrix[0, 1], r.matrix[0, 2], r.matrix[1, 2]]) * r.scale,
               t and t["COMPASS_ODI"], 3),
              ("COMPASS_MOT_X/Y/Z (mG/A)", lambda r: r.mot, t and t["COMPASS_MOT"], 2)]
    for label, get, truth, d in coeffs:
        cells = ([fmt3(truth, d)] if case.truth else []) + [fmt3(get(mf), d), fmt3(get(tx), d),
                                                             fmt3(get(tr), d)]
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    if case.truth:
        f = np.linalg.norm(case.truth["field_mG"])
        tm = np.asarray(case.truth["COMPASS_MOT"])
        err = [(100 * np.linalg.norm(r.ofs - case.truth["COMPASS_OFS"]) / f,
                100 * np.linalg.norm(r.mot - tm) / np.linalg.norm(tm)) for r in (mf, tx, tr)]
        lines.append("| COMPASS_OFS error (% of the field) / COMPASS_MOT error (%) | | "
                     + " | ".join(f"{a:.2f} / {b:.1f}" for a, b in err) + " |")
    lines += ["", "| time | MAGFit | triaxcal | ratio |", "|---|---:|---:|---:|",
              f"| fit alone, wall (s) | {mf.fit_s:.2f} | {tx.fit_s:.4f} | "
              f"{mf.fit_s / tx.fit_s:,.0f}x |",
              f"| fit alone, CPU (s) | {mf.fit_cpu_s:.2f} | {tx.fit_cpu_s:.4f} | "
              f"{mf.fit_cpu_s / tx.fit_cpu_s:,.0f}x |",
              f"| read the log + fit, wall (s) | {mf.read_fit_s:.2f} | {tx.read_fit_s:.2f} | "
              f"{mf.read_fit_s / tx.read_fit_s:,.1f}x |",
              f"| read the log + fit, CPU (s) | {mf.read_fit_cpu_s:.2f} | "
              f"{tx.read_fit_cpu_s:.2f} | {mf.read_fit_cpu_s / tx.read_fit_cpu_s:,.1f}x |",
              f"| triaxcal's whole fit_flight (read, fit, held-out fit and check), wall / "
              f"CPU (s) | | {tx.extra['whole_s']:.2f} / {tx.extra['whole_cpu_s']:.2f} | |", ""]
    if mf.extra.get("log"):
        lines += ["MAGFit's optimiser: " + "; ".join(s.strip() for s in mf.extra["log"]), ""]
    lines.append("MAGFit's parameters on their bounds: "
                 + (", ".join(mf.extra["on_bound"]) or "none") + ".")
    v = tx.extra["verdict"]
    lines += ["", "triaxcal's validity gate on the whole log (`triaxcal fit`): "
              + ("passed." if v.valid else "refused: " + "; ".join(
                  r.split(":")[0] for r in v.reasons) + "."), ""]
    return lines


HOW = """## How

Each log is split in time at its middle compass reading; both tools fit the first half and
both fits are judged on the second half by the same code, on the same readings (the stored
calibration undone from the logged ``MAG`` with the offsets each record carries), the same
attitude (``ATT``, ``AHRS_TRIM`` put back) and the same battery current. The same field: the
World Magnetic Model's at the same latitude and longitude, given to MAGFit in place of
pymavlink's table field (which differs from it by the amount printed by the benchmark, 4.7 mG
here). The Erle logs have no GPS fix: their place is assumed (Erle Robotics, Vitoria-Gasteiz),
the same for both.

* **MAGFit** (MAVProxy ``MAVProxy/modules/lib/magfit.py``): its own ``magfit()`` (``PARM``,
  then ``GPS``, ``MAG``, ``ATT``, ``BAT`` with pymavlink; the stored calibration undone; the
  SLSQP fit ``fit_WWW`` of ``wmm_error``) with the options of its window: elliptical and CMOT,
  offsets within +-1500 mG, diagonals 0.8..1.2, off-diagonals +-0.2, COMPASS_MOT within
  +-10 mG/A, ``COMPASS_SCALE`` held at 1, every reading (``Reduce`` 1), the log's own
  ``COMPASS_ORIENT``. MAGFit reads the current from ``BAT`` only: the simulated flight logs
  ``BAT`` (and ``CURR``); the 2016 logs log only ``CURR``, which is handed to MAGFit under the
  name ``BAT`` (centiamps to amps, as triaxcal reads them). Its wx GUI modules
  (``wx_processguard``, ``wx_loader``) are replaced by empty modules (wxPython is not
  installed; the fit does not use them) and its plot is not drawn.
* **triaxcal**: ``fit_attitude`` (full soft iron) with the heading rule of ``triaxcal fit
  --method attitude`` (the attitude's yaw only where the log's parameters show it did not come
  from this compass) and the battery current as MAGFit's (its own command takes the throttle
  where the current hardly varies, as on Erle-Brain3).
* **Times**: the fit alone (MAGFit's ``fit_WWW``; ``fit_attitude``, best of 5), reading the log
  and fitting (MAGFit's ``magfit()`` from opening the log to the end of its fit; triaxcal's
  ``flight_source`` + ``fit_attitude``) and triaxcal's whole ``fit_flight`` (what ``triaxcal
  fit LOG --method attitude`` runs). Wall clock and CPU time of the one process.
"""

DIFFERENCES = """## Where they differ, and why

* **What is compared with the field.** MAGFit turns the expected field into the body with the
  logged roll and pitch and the heading the *corrected compass itself* gives (``get_yaw``, plus
  the declination), so only the field's horizontal strength and its vertical component are
  compared: the attitude's yaw is never used. triaxcal does the same (``heading="free"``) when
  the log's yaw came from this compass (both Erle logs: ``COMPASS_USE`` = 1), and uses the
  attitude's yaw, the whole field vector, when the parameters show it came from elsewhere (the
  simulated flight: ``EK3_SRC1_YAW`` = 2, GPS). The heading then determines the horizontal
  hard iron and soft iron better than the horizontal strength alone does.
* **The criterion.** MAGFit minimises the mean *length* of the error vectors (an L1 norm of
  vector lengths, ``wmm_error``); triaxcal the sum of *squared* errors per axis (least squares,
  with one round that drops readings more than 5 robust deviations out). Least squares is the
  maximum-likelihood fit for Gaussian sensor noise; L1 lengths weigh outliers less but are not
  smooth at zero error, which SLSQP's finite-difference gradients handle poorly.
* **The optimiser.** MAGFit runs scipy's SLSQP on a Python loop over the readings (pymavlink
  ``Vector3``/``Matrix3`` per reading and per function evaluation) with gradients by finite
  differences: one fit costs hundreds of passes over the log. triaxcal runs Levenberg-Marquardt
  with analytic derivatives vectorised in numpy: a few dozen passes of array arithmetic.
* **Bounds against what the data determine.** MAGFit holds every parameter inside fixed bounds
  (offsets +-1500 mG, diagonals 0.8..1.2, off-diagonals +-0.2, COMPASS_MOT +-10 mG/A) and
  returns whatever lies inside them, on the bound if the data push there, with no word on what
  the flight did not determine. triaxcal has no bounds: it reads the standard errors at the
  solution, holds soft-iron terms the flight does not determine at their prior and says so
  (``held``), and refuses (the validity gate) offsets, interference or a field the flight does
  not determine, a field that does not hold still, or a fit that does not beat the log's own
  calibration on the held-out half.
* **The scale.** MAGFit holds ``COMPASS_SCALE`` at 1 (``ScaleMin`` = ``ScaleMax`` = 1) and
  fits the diagonals; with a known field triaxcal fits the gains freely, and without one it
  holds their mean at 1 (the data cannot tell the gain from the field's strength).
* **The readings.** MAGFit undoes the stored calibration and then truncates each raw reading
  to a whole milligauss (``int()`` in ``remove_offsets``, towards zero: a bias of up to 1 mG
  that depends on the sign; the last column shows triaxcal's fit on readings truncated the same
  way); triaxcal keeps the readings as they come (floats; real ``MAG`` records hold whole
  milligauss, so this matters where undoing the stored DIA/ODI/SCALE leaves fractions, and in
  the simulated log, which holds floats). MAGFit takes the latest ``ATT`` and ``BAT`` before
  each ``MAG``; triaxcal the nearest attitude and the current
  interpolated to the reading. MAGFit adds ``AHRS_TRIM_X/Y`` to the Euler angles; triaxcal
  composes the trim rotation with the attitude (the same to first order).
* **Interference.** MAGFit fits only a per-amp term from ``BAT`` (not ``CURR``, not the
  throttle); triaxcal fits per amp or per throttle from ``BAT``/``CURR``/``CTUN`` (here: per
  amp for both).
* **The field.** MAGFit's own field is pymavlink's interpolated table
  (``mavextra.expected_earth_field_lat_lon``); here both were given the World Magnetic Model's.
* **Reading the log.** MAGFit reads ``PARM`` once and then ``GPS``, ``MAG``, ``ATT`` and ``BAT``
  up to the end of its time range (here the first half), with pymavlink; triaxcal reads the
  whole log (it fits the whole flight and checks on the halves) in two pymavlink passes: the
  sensor reader (``IMU``, ``MAG``, ``PARM``; the IMU only to be thrown away here) and the
  flight reader (``ATT``, ``BAT``/``CURR``, ``CTUN``, ``GPS``). Opening a log with pymavlink
  (its index of every message) costs about 1 s of each pass on the 3.6-3.8 MB Erle logs.

What the numbers say:

* On the simulated flight both reach the noise floor (2 mG per axis and 0.3 deg of attitude).
  triaxcal's COMPASS_OFS is closer to the truth; the difference is MAGFit's ``int()``
  truncation of the raw readings, not its criterion: triaxcal fitted on the same truncated
  readings ("triaxcal on int() readings") lands where MAGFit does. The truncation moves every
  reading towards zero by 0.5 mG on average, a sign-dependent bias the fit turns into offsets.
* On the 2016 logs MAGFit's fit lies on its bounds (every diagonal at 0.8 on both, an
  off-diagonal at +-0.2 on both, two COMPASS_MOT terms at 10 mG/A on PXF): the data ask for
  more than its box allows, and it says nothing.
  On Erle-Brain3 triaxcal holds the soft iron at identity (the level flight does not determine
  it; fitted freely, the gains collapse to 0.09-0.5 and the held-out error grows) and its
  held-out RMS is the lower one on both measures; MAGFit's mean error (its own L1 criterion) is
  the lower one there, as its criterion is exactly that number. The PXF log's compass does not
  follow its own attitude (the logged heading differs from the yaw by 98 deg RMS): both fits
  leave 65-75 mG on the held-out half, and triaxcal's gate refuses the log.
"""


def markdown(cases: list[tuple[Case, Result, Result, dict[str, float],
                               dict[str, dict[str, float]], int]],
             env: dict[str, str], quick: bool) -> str:
    lines = ["# triaxcal beside ArduPilot's MAGFit (flight compass calibration)", "",
             "Generated by `python benches/bench_magfit.py"
             + (" --quick" if quick else "") + "`; do not edit by hand.", ""]
    lines += [f"- {k}: {v}" for k, v in env.items()]
    lines += ["", HOW, "## Summary", "",
              "Held-out field error RMS (mG; second half of each log, first half fitted): "
              "against the field turned by the attitude / by the compass's own heading "
              "(MAGFit's measure). Times: the fit alone and reading the log + fitting "
              "(wall clock).", "",
              "| log | MAGFit | triaxcal | fit: MAGFit / triaxcal | ratio | read + fit: "
              "MAGFit / triaxcal | ratio |", "|---|---:|---:|---:|---:|---:|---:|"]
    for case, mf, tx, _, after, _ in cases:
        a, b = after["magfit"], after["triaxcal"]
        lines.append(
            f"| {case.name} | {a['att']:.2f} / {a['own']:.2f} | {b['att']:.2f} / "
            f"{b['own']:.2f} | {mf.fit_s:.1f} s / {tx.fit_s * 1e3:.1f} ms | "
            f"{mf.fit_s / tx.fit_s:,.0f}x | {mf.read_fit_s:.1f} s / {tx.read_fit_s:.2f} s | "
            f"{mf.read_fit_s / tx.read_fit_s:,.1f}x |")
    lines += ["", "The measure that fits each log: the field turned by the attitude where the "
              "attitude's yaw is independent of the compass (the simulated flight's came from "
              "GPS), by the compass's own heading where the yaw came from this compass (both "
              "Erle logs: COMPASS_USE = 1; there the attitude's yaw is no reference).", "",
              "| log | measure | MAGFit | triaxcal | triaxcal at most MAGFit's | fit >= 10x "
              "faster | read + fit >= 10x faster |", "|---|---|---:|---:|---|---|---|"]
    for case, mf, tx, _, after, _ in cases:
        k = "att" if tx.extra["heading"] == "attitude" else "own"
        a, b = after["magfit"][k], after["triaxcal"][k]
        lines.append(
            f"| {case.name} | {'attitude' if k == 'att' else 'own heading'} | {a:.2f} | "
            f"{b:.2f} | {'yes' if b <= a else 'no'} | "
            f"{'yes' if mf.fit_s >= 10 * tx.fit_s else 'no'} | "
            f"{'yes' if mf.read_fit_s >= 10 * tx.read_fit_s else 'no'} |")
    lines.append("")
    for c in cases:
        lines += case_rows(*c)
    lines.append(DIFFERENCES)
    return "\n".join(lines) + "\n"


def environment(stubbed: bool) -> dict[str, str]:
    blas = [f"{i.get('internal_api')} {i.get('version')} {i.get('architecture')} "
            f"({i.get('num_threads')} thread{'s' if i.get('num_threads') != 1 else ''})"
            for i in threadpoolctl.threadpool_info() if i.get("user_api") == "blas"]
    cpu = platform.processor() or platform.machine()
    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break

    def ver(name: str) -> str:
        try:
            return metadata.version(name)
        except metadata.PackageNotFoundError:
            return "?"

    return {
        "date": datetime.date.today().isoformat(),
        "machine": f"{cpu}, {os.cpu_count()} cores (shared: wall clock varies; CPU time less)",
        "Python": platform.python_version(),
        "versions": f"triaxcal {tc.__version__}, MAVProxy {ver('MAVProxy')} (magfit.py), "
                    f"pymavlink {ver('pymavlink')}, scipy {ver('scipy')}, numpy {ver('numpy')}",
        "BLAS (threadpoolctl)": "; ".join(blas) or "none found",
        "OPENBLAS_CORETYPE / OPENBLAS_L2_SIZE": "unset",
        "wxPython": "not installed: MAGFit's wx_processguard and wx_loader stubbed" if stubbed
        else "installed",
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="every 4th reading (MAGFit's Reduce)")
    ap.add_argument("--markdown", default=None, metavar="FILE",
                    help="also write the tables as Markdown (docs/benchmarks/magfit.md)")
    ap.add_argument("--rounds", type=int, default=5, help="triaxcal fit repeats (best of)")
    args = ap.parse_args()
    reduce = 4 if args.quick else 1
    threadpoolctl.threadpool_limits(1)
    magfit, stubbed = import_magfit()
    env = environment(stubbed)
    for k, v in env.items():
        print(f"{k}: {v}")
    from pymavlink import mavextra

    tmp = Path(tempfile.mkdtemp(prefix="bench_magfit_"))
    sim_field = np.array(tc.expected_field(*ZURICH).vector_ned_ut()) * 10.0
    sim = write_flight(tmp, sim_field)
    cases = [Case("simulated flight (600 s, DataFlash)", sim["log"], ZURICH,
                  "Zurich, 47.37 N 8.54 E (the log's GPS)", json.loads(sim["truth"].read_text()))]
    for name in ("PXFv2.0b+Rpi.BIN", "Erle-Brain3.BIN"):
        if (REAL / name).is_file():
            cases.append(Case(name, REAL / name, VITORIA,
                              "assumed 42.85 N 2.67 W (no GPS fix in the log; Erle Robotics, "
                              "Vitoria-Gasteiz)"))
    out = []
    for case in cases:
        lat, lon, alt = case.location
        b = np.array(tc.expected_field(lat, lon, alt).vector_ned_ut()) * 10.0
        table = mavextra.expected_earth_field_lat_lon(lat, lon)
        diff = np.linalg.norm(b - [table.x, table.y, table.z])
        print(f"\n== {case.name}: World Magnetic Model field {fmt3(b)} mG (|B| "
              f"{np.linalg.norm(b):.1f}); pymavlink's table differs by {diff:.1f} mG")
        src0 = flight_source(case.path, _request(case))
        first, second, split_ts = split(case, src0)
        params = src0.recording.params
        orient = int(float(params.get("COMPASS_ORIENT", 0)))
        fmts = _log_types(case.path)
        tx, src = run_triaxcal(case, b, first, reduce, args.rounds)
        print(f"  triaxcal: fit {tx.fit_s * 1e3:.1f} ms (CPU {tx.fit_cpu_s * 1e3:.1f} ms), "
              f"read+fit {tx.read_fit_s:.2f} s, whole fit_flight {tx.extra['whole_s']:.2f} s")
        mf = run_magfit(magfit, case, b, split_ts, reduce, orient, "BAT" not in fmts)
        print(f"  MAGFit:   fit {mf.fit_s:.1f} s (CPU {mf.fit_cpu_s:.1f} s), read+fit "
              f"{mf.read_fit_s:.1f} s, {mf.n} readings")
        cur = _current(src)
        decl = math.degrees(math.atan2(b[1], b[0]))
        raw, dcm = src.raw[second], src.dcm[second]
        before = judge(src.logged[second] @ src.to_body.T, dcm, b, decl)
        after = {"magfit": judge(mf.apply(raw, cur[second]), dcm, b, decl),
                 "triaxcal": judge(tx.apply(raw, cur[second]), dcm, b, decl),
                 "trunc": judge(tx.extra["trunc"].apply(raw, cur[second]), dcm, b, decl)}
        for who in ("magfit", "triaxcal"):
            a = after[who]
            print(f"  held-out {who:8s}: field error {a['att']:.2f} mG (attitude) / "
                  f"{a['own']:.2f} mG (own heading), heading {a['heading']:.2f} deg")
        out.append((case, mf, tx, before, after, len(second)))
    text = markdown(out, env, args.quick)
    print("\n" + text)
    if args.markdown:
        Path(args.markdown).parent.mkdir(parents=True, exist_ok=True)
        Path(args.markdown).write_text(text)
        print(f"written: {args.markdown}")


def _log_types(path: Path) -> set[str]:
    from pymavlink import mavutil

    with contextlib.redirect_stdout(io.StringIO()):
        mlog = mavutil.mavlink_connection(str(path))
    return {name for name, i in mlog.name_to_id.items() if mlog.counts[i] > 0}


if __name__ == "__main__":
    main()
