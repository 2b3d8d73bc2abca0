"""Helpers of the hostile-API corpus (test_hostile_api.py): a valid call of every public function
of ``triaxcal`` (small, fast inputs), the edge values each kind of parameter is given instead,
and the judge of one call's outcome."""

from __future__ import annotations

import dataclasses
import math
import signal
import time
import warnings
from collections.abc import Callable, Mapping
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import triaxcal as tc

# --------------------------------------------------------------------------------------------
# edge values


class _Opaque:
    """An object no function can make sense of."""

    def __repr__(self) -> str:
        return "<opaque>"


#: Values a number, a whole number or a flag is given.
SCALARS: dict[str, Any] = {
    "0": 0, "-1": -1, "-0.0": -0.0, "1e308": 1e308, "-1e308": -1e308, "1e-308": 1e-308,
    "5e-324": 5e-324, "nan": math.nan, "inf": math.inf, "-inf": -math.inf, "2**80": 2**80,
    "-2**80": -(2**80), "10**400": 10**400, "np.nan": np.float64("nan"),
    "np.int64.max": np.int64(2**63 - 1), "True": True, "None": None, "complex": 1 + 1j,
    "str-1": "1", "str-empty": "", "arabic-3": "\u0663", "list": [1.0], "dict": {},
    "opaque": _Opaque(),
}

#: Values a string option is given.
STRINGS: dict[str, Any] = {
    "empty": "", "esc": "\x1b[2J\x1b]0;pwn\x07", "bidi": "\u202egnp.exe", "nul": "a\x00b",
    "long": "x" * 100_000, "nan": "nan", "number": 1.0, "None": None, "bytes": b"x",
    "opaque": _Opaque(),
}


def arrays(base: np.ndarray) -> dict[str, Any]:
    """Values an array of readings shaped like ``base`` is given."""
    n = max(len(base), 2)
    width = base.shape[1] if base.ndim == 2 else 1
    shape = base.shape
    nanned = np.array(base, dtype=np.float64, copy=True)
    nanned.reshape(-1)[len(nanned.reshape(-1)) // 2] = np.nan
    return {
        "nan-one": nanned,
        "nan-all": np.full(shape, np.nan),
        "inf": np.full(shape, np.inf),
        "1e308": np.full(shape, 1e308),
        "alt-1e308": np.where(np.arange(base.size).reshape(shape) % 2, 1e308, -1e308),
        "1e-308": np.full(shape, 1e-308),
        "denormal": np.asarray(base, dtype=np.float64) * 1e-320,
        "huge-scaled": np.asarray(base, dtype=np.float64) * 1e300,
        "zeros": np.zeros(shape),
        "constant": np.ones(shape),
        "empty": np.zeros((0, width) if base.ndim == 2 else (0,)),
        "one-row": np.asarray(base)[:1],
        "two-rows": np.asarray(base)[:2],
        "wrong-width": np.zeros((n, width + 1)) if base.ndim == 2 else np.zeros((n, 2)),
        "3-d": np.zeros((n, width, 2)),
        "scalar": 1.0,
        "object": np.asarray(base).astype(object),
        "object-mixed": np.array([[1, "a", None]] * n, dtype=object),
        "complex": np.asarray(base) + 1j,
        "bool": np.ones(shape, dtype=bool),
        "strings": np.asarray(base).astype(str),
        "ragged": [[1.0, 2.0, 3.0], [1.0]],
        "None": None,
        "path": "session.csv",
        "dict": {"x": 1},
        "int16": np.asarray(base).clip(-32768, 32767).astype(np.int16),
        "uint64-max": np.full(shape, np.iinfo(np.uint64).max, dtype=np.uint64),
        "float16": np.asarray(base).astype(np.float16),
        "masked": np.ma.masked_array(np.asarray(base, dtype=float), mask=True),
        "non-contiguous": np.asfortranarray(np.asarray(base, dtype=np.float64))[::-1],
    }


def _readings(value: Any) -> bool:
    return isinstance(value, np.ndarray) and value.dtype.kind in "iuf" and value.ndim >= 1


def edge_values(value: Any) -> dict[str, Any]:
    """The edge values for a parameter whose valid value is ``value``: a mapping of readings
    (sections, tilts) has each array edge in every entry (and in the first alone)."""
    if isinstance(value, np.ndarray) and value.dtype.kind in "iuf" and value.ndim >= 1:
        return arrays(value)
    if isinstance(value, Mapping) and value and all(
            _readings(v) or (isinstance(v, tuple) and all(_readings(x) for x in v))
            for v in value.values()):
        first = next(iter(value))
        out: dict[str, Any] = {"empty": {}, "None": None, "str": "x", "missing-one":
                               {k: v for k, v in value.items() if k != first}}
        sample = value[first]
        for part in range(len(sample) if isinstance(sample, tuple) else 1):
            base = sample[part] if isinstance(sample, tuple) else sample
            for label, edge in arrays(np.asarray(base)).items():

                def put(v: Any, e: Any = edge, i: int = part) -> Any:
                    if not isinstance(v, tuple):
                        return e
                    return tuple(e if j == i else x for j, x in enumerate(v))

                out[f"all[{part}]-{label}"] = {k: put(v) for k, v in value.items()}
                out[f"first[{part}]-{label}"] = {**value, first: put(value[first])}
        return out
    if isinstance(value, str):
        return STRINGS
    if isinstance(value, (bool, int, float, np.number)) or value is None:
        return SCALARS
    if isinstance(value, (tuple, list)) and value and all(
            isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
        return {**{f"item-{k}": [v] * len(value) for k, v in SCALARS.items()
                   if k in ("nan", "inf", "1e308", "-1", "0", "2**80", "None", "str-1")},
                "empty": [], "one": value[:1], "many": list(value) * 1000, "str": "1,2,3",
                "None": None}
    return {"None": None, "0": 0, "nan": math.nan, "str": "x", "empty-list": [],
            "dict": {}, "opaque": _Opaque()}


# --------------------------------------------------------------------------------------------
# the judge


class Hang(BaseException):
    """A call ran past its time limit."""


def _alarm(signum: int, frame: Any) -> None:
    raise Hang()


#: Results that are legitimately not finite (NaN for "not determined", by design).
_MAY_BE_NAN = {"stderr", "gain_counts_per_dps", "gain_cw_counts_per_dps",
               "gain_ccw_counts_per_dps", "scale_dps_per_count", "asymmetry", "rel_err",
               "heading_gap_deg", "tilt_heading_deg", "dip_std_heldout_before_deg",
               "dip_std_heldout_after_deg", "adev", "terms", "quantization", "ramp",
               "bias_instability", "bias_tau_s", "random_walk", "floor", "vertical",
               "boot_std", "lower", "upper", "rms", "rms_pct", "condition"}

#: Fields of results that must be finite when a result is returned.
_MUST_BE_FINITE = ("offset", "matrix", "gain", "center", "rotation", "radius", "gains",
                   "counts_per_g", "estimate")


def bad_result(result: Any) -> str | None:
    """Why a returned result is wrong (a non-finite coefficient), or None."""
    if isinstance(result, dict):
        items = list(result.items())
    elif dataclasses.is_dataclass(result) and not isinstance(result, type):
        items = [(f.name, getattr(result, f.name, None)) for f in dataclasses.fields(result)]
    elif hasattr(result, "offset") and hasattr(result, "matrix"):
        items = [("offset", result.offset), ("matrix", result.matrix)]
    else:
        return None
    for name, value in items:
        if value is None:
            continue
        if name not in _MUST_BE_FINITE or name in _MAY_BE_NAN:
            if dataclasses.is_dataclass(value) and not isinstance(value, type):
                why = bad_result(value)
                if why:
                    return f"{name}.{why}"
            continue
        try:
            arr = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError):
            continue
        if arr.size and not np.isfinite(arr).all():
            return f"{name} is not finite: {arr.reshape(-1)[:6].tolist()}"
    return None


def outcome(call: Callable[[], Any], *, limit_s: float = 10.0) -> str:
    """Run ``call``: "ok", "refused" (a CalibrationError) or what went wrong (an exception
    other than CalibrationError, a numpy warning, a non-finite result, a hang)."""
    old = signal.signal(signal.SIGALRM, _alarm)
    signal.setitimer(signal.ITIMER_REAL, limit_s)
    t0 = time.monotonic()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", RuntimeWarning)  # numpy's overflow / invalid value
            warnings.simplefilter("ignore", UserWarning)  # the library's own advice
            result = call()
        why = bad_result(result)
        return f"WRONG {why}" if why else "ok"
    except tc.CalibrationError:
        return "refused"
    except Hang:
        return f"HANG past {limit_s:g} s"
    except Exception as exc:  # noqa: BLE001 - the corpus reports every other exception
        return f"{type(exc).__name__}: {str(exc)[:160]}"
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)
        if time.monotonic() - t0 > limit_s:
            pass


# --------------------------------------------------------------------------------------------
# a valid call of every public function


@dataclasses.dataclass
class Call:
    fn: Callable[..., Any]
    args: tuple[Any, ...] = ()
    kwargs: dict[str, Any] = dataclasses.field(default_factory=dict)

    def params(self) -> dict[str, Any]:
        """Every argument by name (positional ones by their parameter's name)."""
        import inspect

        names = list(inspect.signature(self.fn).parameters)
        return {**dict(zip(names, self.args)), **self.kwargs}

    def with_(self, name: str, value: Any) -> Callable[[], Any]:
        import inspect

        names = list(inspect.signature(self.fn).parameters)
        args, kwargs = list(self.args), dict(self.kwargs)
        if name in names[:len(args)]:
            args[names.index(name)] = value
        else:
            kwargs[name] = value
        return lambda: self.fn(*args, **kwargs)


def _unit_dirs(n: int, seed: int) -> np.ndarray:
    u = np.random.default_rng(seed).normal(size=(n, 3))
    return u / np.linalg.norm(u, axis=1, keepdims=True)


def _ellipsoid(n: int = 60, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return _unit_dirs(n, seed) * 16384 / [1.03, 0.98, 1.01] + [412, -230, 97] + rng.normal(
        0, 10, (n, 3))


def _ferraris_sections(n: int = 50) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    off, cpg, cpd = np.array([10.0, -20.0, 30.0]), 2048.0, 16.4
    rng = np.random.default_rng(4)

    def still(v):
        return (np.tile(off + cpg * np.array(v), (n, 1)) + rng.normal(0, 1, (n, 3)),
                rng.normal(0, 1, (n, 3)))

    def spin(i):
        return (np.tile(off + cpg * np.eye(3)[i], (n, 1)) + rng.normal(0, 1, (n, 3)),
                np.tile(cpd * 360 / (n / 100) * np.eye(3)[i], (n, 1)))

    return {"x_p": still([1, 0, 0]), "x_a": still([-1, 0, 0]), "y_p": still([0, 1, 0]),
            "y_a": still([0, -1, 0]), "z_p": still([0, 0, 1]), "z_a": still([0, 0, -1]),
            "x_rot": spin(0), "y_rot": spin(1), "z_rot": spin(2)}


def _calibration() -> tc.Calibration:
    rng = np.random.default_rng(2)
    m = np.eye(3) / 16384 + rng.normal(scale=1e-7, size=(3, 3))
    acc = tc.SensorCalibration(
        offset=[120.0, -40.0, 75.0], matrix=(m + m.T) / 2, unit="g", radius=1.0, model="full",
        stats={"rms": 0.002, "n": 50, "rms_pct_of_radius": 0.2, "coverage_pct": 80.0,
               "stderr": {"offset_x": 2.0, "offset_y": 2.0, "offset_z": 2.0}},
        source="session.csv")
    temp = tc.TemperatureTerms(temp_ref_c=25.0, temp_range_c=(10.0, 40.0),
                               offset_poly=[[0, 0, 0], [1.5, -0.5, 0.2]])
    gyro = tc.SensorCalibration(offset=[10.0, -3.0, 2.0], matrix=np.eye(3) / 131,
                                unit="deg/s", model="bias", temperature=temp)
    mag = tc.SensorCalibration(offset=[12.5, -3.0, 40.0], matrix=np.eye(3) * 0.15,
                               raw_unit="counts", unit="uT", radius=48.0, model="axis",
                               stats={"rms": 0.2, "n": 60, "rms_pct_of_radius": 0.4,
                                      "coverage_pct": 80.0})
    return tc.Calibration(accel=acc, gyro=gyro, mag=mag, sensor_id="board-1")


def _physical() -> tc.Calibration:
    """A calibration in physical units (what every export takes without a scale)."""
    acc = tc.SensorCalibration(offset=[0.1, -0.2, 0.05], matrix=np.eye(3), raw_unit="m/s^2",
                               unit="m/s^2", radius=9.80665, model="axis")
    gyro = tc.SensorCalibration(offset=[0.01, -0.02, 0.0], matrix=np.eye(3),
                                raw_unit="rad/s", unit="rad/s", model="bias")
    mag = tc.SensorCalibration(offset=[12.5, -3.0, 40.0], matrix=np.eye(3) * 1.02,
                               raw_unit="uT", unit="uT", radius=48.0, model="axis")
    return tc.Calibration(accel=acc, gyro=gyro, mag=mag, sensor_id="board-1")


def base_calls(tmp: Path) -> dict[str, Call]:
    """A valid call of each public function (name in ``triaxcal.__all__`` -> Call)."""
    from triaxcal.sim import NoiseTruth, simulate_noise

    pts = _ellipsoid()
    cal = _calibration()
    phys = _physical()
    acc_part = cal.accel
    fit = tc.fit_ellipsoid(pts, model="axis", radius=1.0)
    # a board at rest, then turned to other faces (accelerometer in g, 100 Hz)
    faces = np.repeat(np.array([[0, 0, 1.0], [1, 0, 0], [0, 1, 0], [0, 0, -1], [-1, 0, 0],
                                [0, -1, 0]]), 200, axis=0)
    faces = faces + np.random.default_rng(1).normal(0, 0.002, faces.shape)
    session = np.column_stack([faces, np.random.default_rng(2).normal(0, 1, faces.shape)])
    names = ("ax", "ay", "az", "gx", "gy", "gz")
    noise = simulate_noise(NoiseTruth(white=0.01), 4000, 50.0, seed=1)
    still_csv = tmp / "still.csv"
    np.savetxt(still_csv, np.column_stack([np.arange(len(noise)) / 50.0, noise]),
               delimiter=",", header="t,gx,gy,gz", comments="")
    table_csv = tmp / "table.csv"
    np.savetxt(table_csv, pts, delimiter=",", header="ax,ay,az", comments="")
    table = tc.read_table(table_csv)
    psi = np.linspace(0, 2 * np.pi, 72, endpoint=False)
    ring = np.column_stack([20 * np.cos(psi), -20 * np.sin(psi), np.full(72, -44.0)])
    yaw_raw = ring / [1.05, 0.95, 1.0] + [30.0, -12.0, 8.0]
    rng = np.random.default_rng(3)
    w2b = [tc.sim.rotvec_to_matrix(v) for v in rng.normal(size=(40, 3))]
    al_acc = np.array([w @ [0, 0, 1.0] for w in w2b])
    al_mag = np.array([w @ [20.0, 0.0, -45.0] for w in w2b])
    temp = np.linspace(20.0, 40.0, 200)
    at_rest = np.column_stack([50 + 2.0 * (temp - 20), -30 - 1.5 * (temp - 20), 10 + 0 * temp])
    u = np.linspace(0.0, 1.0, 601)
    rate = np.zeros((1400, 3))
    rate[400:1001, 2] = 120 * (1 - np.cos(2 * np.pi * u))
    counts = 131.0 * (rate + np.random.default_rng(0).normal(0.0, 0.05, rate.shape)) + [
        12.0, -7.0, 3.0]
    s, c = np.sin(np.radians(10)), np.cos(np.radians(10))
    tilts = {"fore_down": np.array([[-s + 0.01, 0.02, c]]),
             "aft_down": np.array([[s + 0.01, 0.02, c]]),
             "left_down": np.array([[0.01, -s + 0.02, c]]),
             "right_down": np.array([[0.01, s + 0.02, c]])}
    six = np.array([[16500, 10, 0], [-16300, 10, 0], [100, 16484, 0], [100, -16284, 0],
                    [100, 10, 16600], [100, 10, -16000]], dtype=float)
    dirs = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 0], [1, 0, 1], [0, 1, 1.0]])
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    plateaus = np.vstack([np.vstack([np.zeros((60, 3)), np.tile(3.49 * 1.01 * d, (200, 1))])
                          for d in dirs] + [np.zeros((60, 3))])
    plateaus += np.random.default_rng(5).normal(0, 1e-3, plateaus.shape)
    auto = np.repeat(_unit_dirs(60, 1), 100, axis=0) / [1.02, 0.99, 1.01] + [0.03, -0.02, 0.01]
    auto += np.random.default_rng(1).normal(0, 0.003, auto.shape)
    sections = _ferraris_sections()
    fer = tc.ferraris(sections, rate_hz=100.0, gravity=9.81)
    rig = tc.tilt_rig({k: v[0] for k, v in tilts.items()}, angle_deg=10)
    temp_model = tc.fit_temperature(at_rest, temp, reference_degC=25.0)
    turntable = tc.fit_turntable([plateaus], [3.49], offset=[0, 0, 0], window=20)
    yaw = tc.fit_yaw(yaw_raw, horizontal=20.0, vertical=-44.0, raw_unit="uT")
    noise_fig = tc.noise_figures(noise, 50.0, unit="deg/s")
    gyro_sim = SimpleNamespace(**{
        "offset": [50.0, -20.0, 5.0], "gain_counts_per_dps": [16.4, 16.4, 16.4],
        "gain_cw_counts_per_dps": [16.3, 16.5, 16.4], "gain_ccw_counts_per_dps":
            [16.5, 16.3, 16.4], "asymmetry": [0.0] * 3, "angle_deg": 90.0, "rotations": (),
        "missing": ()})
    scale = {"accel": (16384.0, "g"), "gyro": (131.0, "deg/s"), "mag": (6.6667, "uT")}
    calls: dict[str, Call] = {
        "read_table": Call(tc.read_table, (table_csv,), {"max_columns": 10,
                                                         "max_line_bytes": 1000,
                                                         "max_values": 10_000}),
        "detect_poses": Call(tc.detect_poses, (faces,), {"window": 25, "threshold": 0.07,
                                                         "min_windows": 2, "max_windows": 4,
                                                         "holdoff_samples": 0}),
        "detect_still": Call(tc.detect_still, (faces,), {"rate_hz": 100.0, "rest_s": 1.0,
                                                         "window_s": 0.5, "k": 3.0,
                                                         "min_duration_s": 0.5}),
        "still_intervals": Call(tc.still_intervals, (faces,), {"rate_hz": 100.0, "rest_s": 1.0,
                                                               "window_s": 0.5, "k": 3.0,
                                                               "min_duration_s": 0.5}),
        "session_poses": Call(tc.session_poses, (names, session, tc.PoseSettings())),
        "descend_center": Call(tc.descend_center, (pts, 16384.0), {"step": 1000.0,
                                                                   "min_step": 0.01,
                                                                   "shrink": 10.0,
                                                                   "max_iter": 100_000}),
        "grid_center": Call(tc.grid_center, (pts, 16384.0), {"lo": 300.0, "hi": 500.0,
                                                             "step": 20.0}),
        "fit_auto": Call(tc.fit_auto, (pts,), {"radius": 1.0}),
        "fit_batch": Call(tc.fit_batch, ([pts, pts[:30]],), {"model": "axis", "radius": 1.0,
                                                              "max_iter": 100, "tol": 1e-10}),
        "fit_ellipsoid": Call(tc.fit_ellipsoid, (pts,), {"model": "full", "radius": 1.0,
                                                          "max_iter": 100, "tol": 1e-10,
                                                          "fixed": {"gain_z": 6.1e-5}}),
        "fit_robust": Call(tc.fit_robust, (pts,), {"radius": 1.0, "sigma": 2.0,
                                                    "max_rounds": 10, "min_keep": 0.5}),
        "fit_sphere": Call(tc.fit_sphere, (pts,), {"radius": 16384.0, "max_iter": 100}),
        "fit_sphere_linear": Call(tc.fit_sphere_linear, (pts,)),
        "information_criterion": Call(tc.information_criterion, (fit, pts)),
        "sphere_center": Call(tc.sphere_center, (pts, 16384.0), {"min_step": 0.01,
                                                                  "shrink": 10.0}),
        "sphere_error": Call(tc.sphere_error, (pts, (412.0, -230.0, 97.0), 16384.0)),
        "autocalibrate": Call(tc.autocalibrate, (auto, 10.0), {"min_hours": 0.0,
                                                               "window_s": 10.0,
                                                               "chunk_s": 3600.0}),
        "allan": Call(tc.allan, (noise, 50.0), {"unit": "deg/s"}),
        "bootstrap": Call(tc.bootstrap, (pts,), {"model": "axis", "radius": 1.0, "n_boot": 40,
                                                  "level": 0.95, "seed": 0}),
        "check_rest": Call(tc.check_rest, (noise, 50.0), {"unit": "deg/s"}),
        "kalibr_noise": Call(tc.kalibr_noise, (noise_fig,)),
        "noise_figures": Call(tc.noise_figures, (noise, 50.0), {"unit": "deg/s"}),
        "noise_from_file": Call(tc.noise_from_file, (tc.NoiseRequest(
            still_csv, unit={"gyro": "deg/s"}),)),
        "fit_yaw": Call(tc.fit_yaw, (yaw_raw,), {"horizontal": 20.0, "vertical": -44.0,
                                                  "raw_unit": "uT"}),
        "align_mag_accel": Call(tc.align_mag_accel, (al_mag, al_acc), {"detect": False,
                                                                       "holdout": 0.25}),
        "axis_heading": Call(tc.axis_heading, (al_acc, al_mag), {"axis": 1}),
        "heading_errors": Call(tc.heading_errors, (al_acc, al_mag, np.array(w2b).transpose(
            0, 2, 1))),
        "ferraris": Call(tc.ferraris, (sections,), {"rate_hz": 100.0, "gravity": 9.81,
                                                    "angle_deg": 360.0}),
        "fit_temperature": Call(tc.fit_temperature, (at_rest, temp), {"degree": 1,
                                                                      "reference_degC": 25.0}),
        "fit_turntable": Call(tc.fit_turntable, ([plateaus], [3.49]), {
            "offset": np.zeros(3), "window": 20, "min_fraction": 0.9}),
        "gyro_bias": Call(tc.gyro_bias, (counts[:400],), {"rate_hz": 100.0, "rest_s": 3.0}),
        "gyro_gains": Call(tc.gyro_gains, (counts,), {"angle_deg": 720.0, "rate_hz": 100.0,
                                                      "turns": "whole", "axes": "z",
                                                      "rest_s": 3.0}),
        "find_rotations": Call(tc.find_rotations, (counts,), {"rate_hz": 100.0, "rest_s": 3.0,
                                                              "window_s": 0.5, "k": 4.0}),
        "six_position": Call(tc.six_position, (six,), {"gravity": 1.0}),
        "tilt_rig": Call(tc.tilt_rig, ({k: v[0] for k, v in tilts.items()},),
                         {"angle_deg": 10.0, "z_offset": 0.0}),
        "check_part": Call(tc.check_part, (acc_part, "accel")),
        "compare": Call(tc.compare, (cal, cal), {"threshold": 3.0, "max_gain_change": 0.05,
                                                 "max_offset_change": 0.25}),
        "fold_asa": Call(tc.fold_asa, (cal.mag, [192, 128, 128])),
        "part_from_center": Call(tc.part_from_center, ([120.0, -80.0, 300.0], 16384.0),
                                 {"unit": "g", "scale_to": 1.0}),
        "part_from_ferraris": Call(tc.part_from_ferraris, (fer,), {"gravity": 9.81,
                                                                   "unit": "m/s^2"}),
        "part_from_gyro_gains": Call(tc.part_from_gyro_gains, (gyro_sim,)),
        "part_from_temperature": Call(tc.part_from_temperature, (temp_model, cal.gyro)),
        "part_from_tilt_rig": Call(tc.part_from_tilt_rig, (rig,), {"raw_unit": "g"}),
        "part_from_turntable": Call(tc.part_from_turntable, (turntable,),
                                    {"raw_unit": "rad/s"}),
        "part_from_yaw": Call(tc.part_from_yaw, (yaw,)),
        "coefficient_table": Call(tc.coefficient_table, (acc_part, "accel")),
        "quality_report": Call(tc.quality_report, (pts, fit), {"sensor": "accel"}),
        "c_header": Call(tc.c_header, (cal,), {"prefix": "imu"}),
        "c_fixed_header": Call(tc.c_fixed_header, (cal,), {"prefix": "imu"}),
        "js_module": Call(tc.js_module, (cal,), {"prefix": "imu", "form": "esm"}),
        "ardupilot_parm": Call(tc.ardupilot_parm, (phys,)),
        "px4_params_file": Call(tc.px4_params_file, (phys,), {"system_id": 1,
                                                              "component_id": 1}),
        "adafruit_calib_json": Call(tc.adafruit_calib_json, (phys,)),
        "kalibr_imu_yaml": Call(tc.kalibr_imu_yaml, (phys,), {"rate_hz": 200.0,
                                                              "topic": "/imu0"}),
        "motioncal_packet": Call(tc.motioncal_packet, (cal,), {"counts_per_unit": scale,
                                                             "offsets_only": True}),
        "encode_motioncal": Call(tc.encode_motioncal, (), {
            "accel_offset": (0.1, 0.2, 0.3), "gyro_offset": (0.0, 0.0, 0.0),
            "mag_offset": (1.0, 2.0, 3.0), "field": 50.0, "soft_iron": np.eye(3)}),
        "decode_motioncal": Call(tc.decode_motioncal, (tc.encode_motioncal(),)),
        "write_outputs": Call(tc.write_outputs, (cal, {"accel": pts}, tmp / "out"),
                              {"plot": False, "counts_per_unit": scale}),
        "expected_field": Call(tc.expected_field, (45.0, 7.0, 300.0), {"date": "2025-06-01"}),
        "fit_session": Call(tc.fit_session, (table,), {"request": tc.FitRequest(radius=1.0)}),
        "fit_to_file": Call(tc.fit_to_file, (table, tc.FitRequest(radius=1.0),
                                             tmp / "fitted.json"), {"new": True}),
        "plot_allan": Call(tc.plot_allan, (noise_fig, tmp / "allan.png"), {"dpi": 20}),
        "plot_report": Call(tc.plot_report, (pts, fit, tmp / "report.png"), {"dpi": 20}),
        # the validated requests and records (their constructors check every field)
        "SensorCalibration": Call(tc.SensorCalibration, (acc_part.offset, acc_part.matrix), {
            "raw_unit": "counts", "unit": "g", "radius": 1.0, "model": "full",
            "stats": {"n": 50}, "source": "s.csv", "input_sha256": "0" * 64}),
        "TemperatureTerms": Call(tc.TemperatureTerms, (25.0, (10.0, 40.0),
                                                       np.array([[0, 0, 0], [1.5, -0.5, 0.2]]))),
        "Calibration": Call(tc.Calibration, (), {"accel": acc_part, "gyro": cal.gyro,
                                                 "sensor_id": "board-1",
                                                 "created_utc": "2025-01-01T00:00:00Z"}),
        "Alignment": Call(tc.Alignment, (np.eye(3),), {"to": "accel"}),
        "FitRequest": Call(tc.FitRequest, (), {"sensor": "accel", "model": "auto",
                                               "radius": 1.0, "sigma": 2.0, "rounds": 10,
                                               "bootstrap": 0, "fixed": {"gain_z": 1.0}}),
        "SourceOptions": Call(tc.SourceOptions, (), {"columns": "ax,ay,az", "instance": 0,
                                                     "topics": ("/imu",)}),
        "FieldOptions": Call(tc.FieldOptions, (), {"location": (45.0, 7.0, 300.0)}),
        "PoseSettings": Call(tc.PoseSettings, (), {"window": 25, "accel_threshold_g": 0.07,
                                                   "counts_per_g": 16384.0, "holdoff_s": 1.0,
                                                   "rate_hz": 100.0, "hold_windows": 4}),
        "PoseDetector": Call(tc.PoseDetector, (), {"window": 25, "threshold": 0.07,
                                                   "units_per_g": 1.0, "max_windows": 4}),
        "AllanAccumulator": Call(tc.AllanAccumulator, (50.0,), {"axes": 3, "max_tau_s": 100.0,
                                                                "exact_up_to": 1024}),
        "NoiseRequest": Call(tc.NoiseRequest, (still_csv,), {"sensor": "gyro", "rate_hz": 50.0,
                                                             "chunk_rows": 1024}),
        "Stream": Call(tc.Stream, (np.arange(len(noise)) / 50.0, noise), {"unit": "deg/s"}),
    }
    imu_rec = _imu_recording()
    imu = tc.calibrate_imu(*imu_rec, rate_hz=50.0, gravity=1.0, rest_s=3.0, k_values=(3,))
    calls["calibrate_imu"] = Call(tc.calibrate_imu, imu_rec, {
        "rate_hz": 50.0, "gravity": 1.0, "rest_s": 3.0, "k_values": (3,), "window_s": 1.0,
        "min_still_s": 1.0, "min_poses": 9, "max_iter": 20})
    calls["part_from_imu"] = Call(tc.part_from_imu, (imu,), {"gravity": 1.0, "unit": "g"})
    return calls


def _imu_recording() -> tuple[np.ndarray, np.ndarray]:
    """Accelerometer and gyroscope of a simulated board turned through 12 poses (50 Hz)."""
    from triaxcal.sim import Script, SimIMU, rotvec_to_matrix

    rng = np.random.default_rng(0)
    poses = [np.eye(3)]
    for _ in range(11):
        rv = rng.normal(size=3)
        rv *= math.radians(rng.uniform(40, 110)) / np.linalg.norm(rv)
        poses.append(poses[-1] @ rotvec_to_matrix(rv))
    script = Script.from_poses(np.array(poses), hold_s=2.0, settle_s=4.0, peak_dps=150)
    rec = SimIMU(0).record(script, rate_hz=50.0)
    return rec.accel, rec.gyro


def mapping_values() -> dict[str, Any]:
    return {"None": None, "empty": {}, "list": [1], "str": "x", "nested-nan":
            {"accel": math.nan}, "opaque": _Opaque()}


def is_mapping(value: Any) -> bool:
    return isinstance(value, Mapping)
