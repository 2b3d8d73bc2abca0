"""Calibration-file parts from the methods' results.

Each method returns its own small result (:class:`~triaxcal.fit.Descent`,
:class:`~triaxcal.methods.static.TiltRig`, :class:`~triaxcal.methods.gyro.GyroGains`,
:class:`~triaxcal.methods.temperature.TemperatureModel`); the functions here turn one into a
:class:`~triaxcal.calibration.SensorCalibration`, the part a calibration file holds, in the
file's convention ``calibrated = (raw - offset) @ matrix.T`` where the matrix **multiplies**:

==========================  ==========================================================
result                      part
==========================  ==========================================================
sphere centre ``c``, radius  ``offset = c``; ``matrix = (scale_to / R) * I`` (R raw units
``R`` (raw units)            are ``scale_to`` calibrated units), or ``I`` (offset only)
tilt rig                    ``offset``; ``matrix = diag(gain)`` (gain multiplies, g per raw)
gyro gains                  ``offset``; ``matrix = diag(1 / gain_counts_per_dps)`` (the
                            gains divide, so the matrix holds their inverses), deg/s; an
                            axis not turned keeps the existing part's row or the nominal
temperature model           ``offset = offset(T_ref)``, ``offset_poly`` the drift; the
                            matrix of an existing part is kept
Ferraris, Tedaldi (imu)     two parts, ``accel`` and ``gyro``: each triad's offset and
                            matrix (accelerometer in the unit of ``gravity``, gyroscope in
                            rad/s); the gyroscope's g-sensitivity goes into its stats
turntable                   the bias and the symmetric matrix, in the unit of the rates
==========================  ==========================================================

A part holds ``(raw - offset) @ matrix.T`` and nothing else: the g-sensitivity of the
Ferraris and Tedaldi gyroscope models (``K_ga``, raw units per unit of calibrated
acceleration) is recorded in the gyroscope part's ``stats["g_sensitivity"]`` but not applied
by the part or the exports; use the method's own ``apply_gyro`` where it matters.

Every part records the method and its inputs in ``stats`` (``method``, ...), so that a file
says how each number was made, and passes the validity gate (:mod:`triaxcal.calibration.gate`):
a part the gate refuses raises :class:`~triaxcal.calibration.gate.InvalidCalibrationError`
unless ``force=True``, which returns it marked ``valid=False`` with the reasons.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from .._checks import options
from .._checks.arrays import as_matrix3
from .._checks.spelling import opt
from ..conventions.units import UNITS, unit_factor
from ..errors import CalibrationError
from .gate import check_part, judged
from .part import SensorCalibration, TemperatureTerms

__all__ = [
    "part_from_factory",
    "part_from_autocal",
    "part_from_yaw",
    "fold_asa",
    "part_from_center",
    "part_from_ferraris",
    "part_from_gyro_gains",
    "part_from_imu",
    "part_from_temperature",
    "part_from_tilt_rig",
    "part_from_turntable",
]


def _finite3(v: Any, what: str) -> np.ndarray:
    return options.vector3(v, what)


def _result(value: Any, what: str, *names: str) -> Any:
    """A method's result (``what``: "a TiltRig (from tilt_rig)") that has the attributes
    ``names``; anything else is refused saying what to pass."""
    missing = [n for n in names if not hasattr(value, n)]
    if missing:
        raise CalibrationError(f"expected {what}, got {type(value).__name__} (it has no "
                               f"{', '.join(missing)})")
    return value


def _common(stats: Any, force: Any) -> dict[str, Any]:
    """The options every ``part_from_*`` takes: ``stats`` (a mapping) and ``force``."""
    options.flag(force, "force")
    return options.mapping(stats, "stats") or {}


def _base(base: Any) -> SensorCalibration | None:
    return None if base is None else options.instance(
        base, SensorCalibration, "base", "a SensorCalibration (the part already in the file) "
        "or None")


def part_from_center(
    center: Any,
    radius: float,
    *,
    raw_unit: str = "counts",
    unit: str | None = None,
    scale_to: float | None = None,
    method: str = "descent",
    stats: Mapping[str, Any] | None = None,
    source: str | None = None,
    input_sha256: str | None = None,
    force: bool = False,
) -> SensorCalibration:
    """A part from the centre of a sphere of known radius (the sphere-centre zero offset).

    Parameters
    ----------
    center : array_like (3,)
        The centre found (:func:`~triaxcal.descend_center`, :func:`~triaxcal.grid_center`,
        or a fixed-radius sphere fit), raw units.
    radius : float
        The sphere's radius in raw units (16384 counts = 1 g at +-2 g, 16 bit).
    raw_unit : str
        Unit of the readings.
    unit, scale_to : optional
        With ``scale_to`` (what ``radius`` is in ``unit``: 1 for 1 g), the part also scales:
        ``matrix = scale_to / radius * I``. Without it the part corrects the offset only
        (``matrix = I``, ``unit = raw_unit``).
    method : str
        How the centre was found (recorded in ``stats["method"]``).
    stats : mapping, optional
        More statistics to record (the error sum, iterations...).
    source, input_sha256 : str, optional
        Provenance.

    Examples
    --------
    >>> part = part_from_center([120.0, -80.0, 300.0], 16384.0, unit="g", scale_to=1.0)
    >>> part.apply([[120.0, -80.0, 300.0 + 16384.0]]).tolist()
    [[0.0, 0.0, 1.0]]
    """
    stats = _common(stats, force)
    c = _finite3(center, "center")
    r = options.magnitude(radius, "radius", hint="raw units")
    if scale_to is None:
        matrix = np.eye(3)
        out_unit = raw_unit if unit is None else unit
        if out_unit != raw_unit:
            raise CalibrationError(
                f"an offset-only part keeps the raw unit {raw_unit!r}; to calibrate to "
                f"{out_unit!r} say what the radius is in it (scale_to)"
            )
        model = "offset"
    else:
        s = options.magnitude(scale_to, "scale_to", hint="what the radius is in unit")
        if unit is None:
            raise CalibrationError("scale_to needs the unit it is in (unit='g', 'uT'...)")
        matrix = np.eye(3) * (s / r)
        out_unit = unit
        model = "sphere"
    st: dict[str, Any] = {"method": method, "radius_raw": r}
    if stats:
        st.update(stats)
    return gated(SensorCalibration(offset=c, matrix=matrix, raw_unit=raw_unit, unit=out_unit,
                                   radius=None if scale_to is None else s,
                                   model=model, stats=st, source=source,
                                   input_sha256=input_sha256), force=force)


def part_from_tilt_rig(
    rig: Any,
    *,
    raw_unit: str = "counts",
    stats: Mapping[str, Any] | None = None,
    source: str | None = None,
    input_sha256: str | None = None,
    force: bool = False,
) -> SensorCalibration:
    """An accelerometer part from :func:`~triaxcal.tilt_rig`: ``offset`` and the per-axis
    gains (g per raw unit, multiply) on the diagonal; calibrated readings in g.

    The z offset is the one given to the rig (it cannot be measured by tilts alone).

    Examples
    --------
    >>> import numpy as np, triaxcal as tc
    >>> s, c = np.sin(np.radians(10)), np.cos(np.radians(10))
    >>> rig = tc.tilt_rig({"fore_down": [-s + 0.01, 0, c], "aft_down": [s + 0.01, 0, c],
    ...                    "left_down": [0.01, -s, c], "right_down": [0.01, s, c]},
    ...                   angle_deg=10)
    >>> part = part_from_tilt_rig(rig, raw_unit="g")
    >>> part.apply([[0.01, 0.0, 1.0]]).round(6).tolist() == [[0.0, 0.0, 1.0]]
    True
    """
    stats = _common(stats, force)
    _result(rig, "a TiltRig (from tilt_rig)", "gain", "offset", "angle_deg",
            "implied_angle_deg", "gain_z_pairs")
    gain = _finite3(rig.gain, "gain")
    st: dict[str, Any] = {
        "method": "tilt-rig",
        "angle_deg": float(rig.angle_deg),
        "implied_angle_deg": [float(v) for v in rig.implied_angle_deg],
        "gain_z_pairs": [float(v) for v in rig.gain_z_pairs],
        "z_offset_assumed": float(rig.offset[2]),
    }
    if stats:
        st.update(stats)
    return gated(SensorCalibration(offset=_finite3(rig.offset, "offset"), matrix=np.diag(gain),
                                   raw_unit=raw_unit, unit="g", radius=1.0, model="axis",
                                   stats=st, source=source, input_sha256=input_sha256),
                 "accel", force=force)


def part_from_gyro_gains(
    gains: Any,
    base: SensorCalibration | None = None,
    *,
    raw_unit: str = "counts",
    nominal_counts_per_dps: float | None = None,
    stats: Mapping[str, Any] | None = None,
    source: str | None = None,
    input_sha256: str | None = None,
    force: bool = False,
) -> SensorCalibration:
    """A gyroscope part from :func:`~triaxcal.gyro_gains`: calibrated rates in deg/s.

    The gains are counts per deg/s and **divide** (the turn-integration method's ``(raw - offset) /
    gain``); the
    part's matrix **multiplies**, so it holds ``diag(1 / gain)``.

    An axis the recording did not turn about (``gyro_gains(..., axes="z")``: NaN gains) keeps
    its row of ``base`` (the gyroscope part already in the calibration file, from the turns
    about the other axes; same raw unit, any rate unit), or else takes the datasheet gain
    ``nominal_counts_per_dps``; without either the part is refused. ``stats["gain_from"]``
    says which, per axis. The offset is the one measured (every axis's bias is).

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> g = SimpleNamespace(offset=[50.0, -20.0, 5.0], gain_counts_per_dps=[16.4, 16.4, 16.4],
    ...                     gain_cw_counts_per_dps=[16.3, 16.5, 16.4],
    ...                     gain_ccw_counts_per_dps=[16.5, 16.3, 16.4], asymmetry=[0.0] * 3,
    ...                     angle_deg=90.0, rotations=(), missing=())
    >>> part_from_gyro_gains(g).apply([[50.0 + 164.0, -20.0, 5.0]]).round(9).tolist()
    [[10.0, 0.0, 0.0]]
    >>> nan = float("nan")  # turns about z only: x and y at the datasheet's 16.4
    >>> z = SimpleNamespace(**{**vars(g), "gain_counts_per_dps": [nan, nan, 16.0]})
    >>> part = part_from_gyro_gains(z, nominal_counts_per_dps=16.4)
    >>> part.apply([[50.0 + 164.0, -20.0, 5.0 + 160.0]]).round(9).tolist(), part.stats["gain_from"]
    ([[10.0, 0.0, 10.0]], ['nominal', 'nominal', 'turns'])
    """
    stats = _common(stats, force)
    base = _base(base)
    _result(gains, "a GyroGains (from gyro_gains)", "gain_counts_per_dps", "offset",
            "angle_deg", "gain_cw_counts_per_dps", "gain_ccw_counts_per_dps", "asymmetry",
            "rotations", "missing")
    try:
        gain = np.asarray(gains.gain_counts_per_dps, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError, OverflowError):
        gain = np.zeros(0)
    if gain.shape != (3,) or np.isinf(gain).any() or not np.isfinite(gain).any():
        raise CalibrationError(f"gain_counts_per_dps must hold 3 gains (NaN for an axis not "
                               f"turned, at least one finite), got {gain.tolist()}")
    if np.any(gain == 0):
        raise CalibrationError(f"a gyro gain is zero: {gain.tolist()}")
    measured = np.isfinite(gain)
    matrix = np.diag(1.0 / np.where(measured, gain, 1.0))
    gain_from = ["turns" if m else "" for m in measured]
    usable = (base is not None and base.raw_unit == raw_unit
              and UNITS.get(base.unit, ("",))[0] == "gyro")
    nominal = None
    if nominal_counts_per_dps is not None:
        nominal = options.magnitude(nominal_counts_per_dps, "nominal_counts_per_dps",
                                    hint="counts per deg/s")
    for i in np.flatnonzero(~measured):
        if usable:
            assert base is not None
            matrix[i] = np.asarray(base.matrix)[i] * unit_factor(base.unit, "deg/s")
            gain_from[i] = "existing part"
        elif nominal is not None:
            matrix[i] = np.eye(3)[i] / nominal
            gain_from[i] = "nominal"
    lacking = ["xyz"[i] for i in range(3) if not gain_from[i]]
    if lacking:
        turned = ", ".join("xyz"[i] for i in np.flatnonzero(measured))
        raise CalibrationError(
            f"no gain for {', '.join(lacking)}: the turns were about {turned} only. Give the "
            "datasheet gain for "
            f"the others ({opt('nominal_counts_per_dps')}), or calibrate them first into the "
            "same calibration file (its gyroscope part keeps them)"
        )

    def listed(v: Any) -> list[float | None]:
        return [None if not math.isfinite(float(x)) else float(x) for x in v]

    st: dict[str, Any] = {
        "method": "gyro-gains",
        "angle_deg": float(gains.angle_deg),
        "gain_counts_per_dps": listed(gain),
        "gain_cw_counts_per_dps": listed(gains.gain_cw_counts_per_dps),
        "gain_ccw_counts_per_dps": listed(gains.gain_ccw_counts_per_dps),
        "asymmetry": listed(gains.asymmetry),
        "rotations": len(gains.rotations),
        "missing": list(gains.missing),
        "gain_from": gain_from,
    }
    if nominal is not None:
        st["nominal_counts_per_dps"] = nominal
    if stats:
        st.update(stats)
    return gated(SensorCalibration(offset=_finite3(gains.offset, "offset"),
                                   matrix=matrix, raw_unit=raw_unit, unit="deg/s",
                                   model="axis", stats=st, source=source,
                                   input_sha256=input_sha256), "gyro", force=force)


def part_from_temperature(
    model: Any,
    base: SensorCalibration | None = None,
    *,
    raw_unit: str = "counts",
    stats: Mapping[str, Any] | None = None,
    source: str | None = None,
    input_sha256: str | None = None,
    force: bool = False,
) -> SensorCalibration:
    """A part with the temperature terms of ``model`` (:func:`~triaxcal.fit_temperature`).

    With ``base`` (the sensor's part already in the file, e.g. from ``gyro-gains``), its
    matrix, units and radius are kept and its offset is replaced by the model's offset at the
    reference temperature, the drift going into ``offset_poly``: the original method's
    ``(raw - (tempcomp * dT + offset)) / gain``. Without ``base`` the part is
    :meth:`SensorCalibration.from_temperature_model` (counts in, counts out).

    Examples
    --------
    >>> import numpy as np, triaxcal as tc
    >>> temp = np.linspace(20.0, 40.0, 200)
    >>> rest = np.column_stack([50 + 2.0 * (temp - 20), -30 + 0 * temp, 10 + 0 * temp])
    >>> m = tc.fit_temperature(rest, temp, reference_degC=25.0)
    >>> gains = tc.SensorCalibration(offset=[0, 0, 0], matrix=np.eye(3) / 131, unit="deg/s")
    >>> part = part_from_temperature(m, gains)
    >>> bool(np.allclose(part.apply([[80.0, -30.0, 10.0]], temperature=35.0), 0))
    True
    """
    stats = _common(stats, force)
    base = _base(base)
    _result(model, "a TemperatureModel (from fit_temperature)", "degree", "rms", "n",
            "offset_coef", "reference_degC", "t_min_degC", "t_max_degC")
    if getattr(model, "gain", "none") != "none" and base is not None:
        raise CalibrationError(
            "a temperature model with fitted gains replaces the part's matrix: write it "
            "without the existing part (new=True)"
        )
    st: dict[str, Any] = {
        "method": "temperature",
        "temperature_degree": int(model.degree),
        "temperature_rms": [float(v) for v in model.rms],
        "temperature_n": int(model.n),
    }
    if stats:
        st.update(stats)
    if base is None:
        part = SensorCalibration.from_temperature_model(
            model, raw_unit=raw_unit, unit=raw_unit, source=source, input_sha256=input_sha256)
        return gated(SensorCalibration(**{**_fields(part), "stats": {**part.stats, **st}}),
                     force=force)
    oc = np.asarray(model.offset_coef, dtype=np.float64)
    poly = oc.copy()
    poly[0] = 0.0
    terms = TemperatureTerms(temp_ref_c=float(model.reference_degC),
                             temp_range_c=(float(model.t_min_degC), float(model.t_max_degC)),
                             offset_poly=poly)
    return gated(SensorCalibration(**{**_fields(base), "offset": oc[0], "temperature": terms,
                                      "stats": {**base.stats, **st}, "source": source,
                                      "input_sha256": input_sha256}), force=force)


def _triad_parts(accel: Any, gyro: Any, g_sensitivity: Any, *, method: str, gravity: float,
                 unit: str, accel_raw_unit: str, gyro_raw_unit: str,
                 accel_stats: Mapping[str, Any], gyro_stats: Mapping[str, Any],
                 stats: Mapping[str, Any] | None, source: str | None,
                 input_sha256: str | None, force: bool) -> dict[str, SensorCalibration]:
    """The accelerometer and gyroscope parts of a two-triad method, both through the gate."""
    stats = _common(stats, force)
    g = options.magnitude(gravity, "gravity", hint=f"local gravity in {unit}")
    if not isinstance(unit, str) or UNITS.get(unit, ("",))[0] != "accel":
        raise CalibrationError(f"the accelerometer's unit must be one of acceleration (g, "
                               f"m/s^2), got {unit!r}")
    k_ga = np.asarray(g_sensitivity, dtype=np.float64)
    common = dict(stats or {})
    a_st = {"method": method, **common, **accel_stats}
    g_st = {"method": method, **common, **gyro_stats,
            "g_sensitivity": k_ga.tolist(),
            "g_sensitivity_unit": f"{gyro_raw_unit} per {unit} (not applied by the part)"}
    parts = {
        "accel": SensorCalibration(offset=_finite3(accel.offset, "accel offset"),
                                   matrix=as_matrix3(accel.matrix, "accel matrix"),
                                   raw_unit=accel_raw_unit, unit=unit, radius=g, model=method,
                                   stats=a_st, source=source, input_sha256=input_sha256),
        "gyro": SensorCalibration(offset=_finite3(gyro.offset, "gyro offset"),
                                  matrix=as_matrix3(gyro.matrix, "gyro matrix"),
                                  raw_unit=gyro_raw_unit, unit="rad/s", model=method,
                                  stats=g_st, source=source, input_sha256=input_sha256),
    }
    # judge both before returning either: nothing is written unless both pass (or force)
    verdicts = {k: check_part(p, k) for k, p in parts.items()}
    for k, v in verdicts.items():
        if not v.valid and not force:
            judged(parts[k], v)  # raises InvalidCalibrationError, naming the sensor
    return {k: judged(p, verdicts[k], force=force) for k, p in parts.items()}


def part_from_ferraris(
    fer: Any,
    *,
    gravity: float,
    unit: str,
    accel_raw_unit: str = "counts",
    gyro_raw_unit: str = "counts",
    stats: Mapping[str, Any] | None = None,
    source: str | None = None,
    input_sha256: str | None = None,
    force: bool = False,
) -> dict[str, SensorCalibration]:
    """The ``accel`` and ``gyro`` parts of a :func:`~triaxcal.ferraris` calibration.

    Parameters
    ----------
    fer : FerrarisCalibration
    gravity, unit : float, str
        The ``gravity`` given to :func:`~triaxcal.ferraris` and its unit (9.81 and ``"m/s^2"``,
        or 1 and ``"g"``): the accelerometer part's unit and radius.
    accel_raw_unit, gyro_raw_unit : str
        Units of the readings (counts; imucal's continuous session: m/s^2 and deg/s).
    stats, source, input_sha256, force
        As for the other parts; ``stats`` go into both.

    Returns
    -------
    dict
        ``{"accel": part, "gyro": part}``; the gyroscope's in rad/s, its g-sensitivity in its
        stats (see the module notes). Both are judged before either is returned: a refused one
        raises unless ``force``.

    Examples
    --------
    >>> import numpy as np, triaxcal as tc
    >>> off, n = np.array([10.0, -20.0, 30.0]), 200
    >>> still = lambda v: (np.tile(off + 2048 * np.array(v), (n, 1)), np.zeros((n, 3)))
    >>> spin = lambda i: (np.tile(off + 2048 * np.eye(3)[i], (n, 1)),
    ...                   np.tile(16.4 * 180 * np.eye(3)[i], (n, 1)))
    >>> sec = {"x_p": still([1, 0, 0]), "x_a": still([-1, 0, 0]), "y_p": still([0, 1, 0]),
    ...        "y_a": still([0, -1, 0]), "z_p": still([0, 0, 1]), "z_a": still([0, 0, -1]),
    ...        "x_rot": spin(0), "y_rot": spin(1), "z_rot": spin(2)}
    >>> parts = part_from_ferraris(tc.ferraris(sec, rate_hz=100.0, gravity=1.0), gravity=1.0,
    ...                            unit="g")
    >>> parts["accel"].apply([off + [0, 0, 2048]]).round(9).tolist()
    [[0.0, 0.0, 1.0]]
    >>> np.degrees(parts["gyro"].apply([[16.4, 0, 0]])).round(9).tolist()
    [[1.0, 0.0, 0.0]]
    """
    _result(fer, "a FerrarisCalibration (from ferraris)", "accel", "gyro", "g_sensitivity",
            "accel_counts_per_g", "gyro_counts_per_dps", "rotation_sign")
    return _triad_parts(
        fer.accel, fer.gyro, fer.g_sensitivity, method="ferraris", gravity=gravity, unit=unit,
        accel_raw_unit=accel_raw_unit, gyro_raw_unit=gyro_raw_unit,
        accel_stats={"accel_counts_per_g": [float(v) for v in fer.accel_counts_per_g]},
        gyro_stats={"gyro_counts_per_dps": [float(v) for v in fer.gyro_counts_per_dps],
                    "rotation_sign": [float(v) for v in fer.rotation_sign]},
        stats=stats, source=source, input_sha256=input_sha256, force=force)


def part_from_imu(
    imu: Any,
    *,
    gravity: float,
    unit: str,
    accel_raw_unit: str = "counts",
    gyro_raw_unit: str = "counts",
    stats: Mapping[str, Any] | None = None,
    source: str | None = None,
    input_sha256: str | None = None,
    force: bool = False,
) -> dict[str, SensorCalibration]:
    """The ``accel`` and ``gyro`` parts of a :func:`~triaxcal.calibrate_imu` calibration
    (Tedaldi's multi-position method); the arguments and result as for
    :func:`part_from_ferraris`. The stats record the still poses, the threshold the sweep
    chose, the accelerometer's residual and the gyro fit's gravity-direction residual."""
    _result(imu, "an ImuCalibration (from calibrate_imu)", "accel", "gyro",
            "gyro_g_sensitivity", "accel_model", "intervals", "k", "accel_rms", "n_moves",
            "gyro_rms_deg", "gyro_rms_deg_before", "gyro_iterations")
    g = options.magnitude(gravity, "gravity", hint=f"local gravity in {unit}")
    return _triad_parts(
        imu.accel, imu.gyro, imu.gyro_g_sensitivity, method="imu", gravity=g, unit=unit,
        accel_raw_unit=accel_raw_unit, gyro_raw_unit=gyro_raw_unit,
        accel_stats={"accel_model": imu.accel_model, "n_poses": len(imu.intervals),
                     "k": float(imu.k), "rms": float(imu.accel_rms),
                     "rms_pct_of_radius": 100.0 * float(imu.accel_rms) / g},
        gyro_stats={"n_moves": int(imu.n_moves), "gyro_rms_deg": float(imu.gyro_rms_deg),
                    "gyro_rms_deg_before": float(imu.gyro_rms_deg_before),
                    "iterations": int(imu.gyro_iterations)},
        stats=stats, source=source, input_sha256=input_sha256, force=force)


def part_from_turntable(
    fit: Any,
    *,
    unit: str = "rad/s",
    raw_unit: str = "counts",
    scale: float = 1.0,
    stats: Mapping[str, Any] | None = None,
    source: str | None = None,
    input_sha256: str | None = None,
    force: bool = False,
) -> SensorCalibration:
    """A gyroscope part from :func:`~triaxcal.fit_turntable`: the bias and the symmetric matrix
    (it multiplies) times ``scale``, in ``unit``: the unit the table's rates were given in
    times ``scale`` (a fit whose rates were in raw units, where its plateaus are found, times
    ``unit`` per raw unit).

    Examples
    --------
    >>> import numpy as np
    >>> from types import SimpleNamespace
    >>> fit = SimpleNamespace(offset=[0.01, 0, 0], matrix=np.eye(3) * 1.01, rates=[3.49],
    ...                       measured=[3.49], rel_error=[0.0], n_plateaus=(20,), rms_rel=1e-3)
    >>> part_from_turntable(fit, raw_unit="rad/s").apply([[1.01, 0, 0]]).round(9).tolist()
    [[1.01, 0.0, 0.0]]
    """
    stats = _common(stats, force)
    _result(fit, "a TurntableFit (from fit_turntable)", "offset", "matrix", "rates",
            "measured", "rel_error", "n_plateaus", "rms_rel")
    if not isinstance(unit, str) or UNITS.get(unit, ("",))[0] != "gyro":
        raise CalibrationError(f"the turntable's rates must be in a rate unit (rad/s, deg/s), "
                               f"got {unit!r}")
    k = options.magnitude(scale, "scale", hint=f"{unit} per unit of the rates")
    st: dict[str, Any] = {
        "method": "turntable",
        "rates": [float(v) * k for v in fit.rates],
        "measured": [float(v) * k for v in fit.measured],
        "rel_error": [float(v) for v in fit.rel_error],
        "n_plateaus": [int(v) for v in fit.n_plateaus],
        "rms_rel": float(fit.rms_rel),
    }
    if stats:
        st.update(stats)
    return gated(SensorCalibration(offset=_finite3(fit.offset, "offset"),
                                   matrix=as_matrix3(fit.matrix, "matrix") * k,
                                   raw_unit=raw_unit, unit=unit, model="turntable", stats=st,
                                   source=source, input_sha256=input_sha256), "gyro",
                 force=force)


def part_from_yaw(y: Any, *, force: bool = False, **kw: Any) -> SensorCalibration:
    """A :class:`~triaxcal.SensorCalibration` (model ``"yaw"``) from a
    :class:`~triaxcal.methods.yaw.YawCalibration`, through the validity gate (``force``: see
    the module notes); ``kw`` are the part's other fields (``source``, ``input_sha256`` ...),
    ``warnings`` and ``extra_stats`` go into its stats."""
    return gated(yaw_part_unjudged(y, **kw), "mag", force=force)


def yaw_part_unjudged(y: Any, **kw: Any) -> SensorCalibration:
    """:func:`part_from_yaw` before the gate (for a caller that judges it itself, as
    :func:`triaxcal.calibration.session.fit_to_file` does)."""
    from ..methods.yaw import YawCalibration

    options.instance(y, YawCalibration, "y", "a YawCalibration (from fit_yaw)")
    radius = (math.hypot(y.horizontal, y.vertical) if y.vertical is not None
              else y.horizontal)
    stats = {"n": y.n, "model": "yaw", "rms": y.rms_horizontal_pct / 100 *
             y.horizontal, "rms_pct_of_radius": y.rms_horizontal_pct *
             y.horizontal / radius, "radius": radius, "yaw": y.stats(),
             "warnings": list(kw.pop("warnings", []))}
    stats.update(kw.pop("extra_stats", {}) or {})
    return SensorCalibration(offset=y.offset, matrix=y.matrix, raw_unit=y.raw_unit,
                             unit=y.unit, radius=radius, model="yaw", stats=stats, **kw)


def _fields(part: SensorCalibration) -> dict[str, Any]:
    return {k: getattr(part, k) for k in ("offset", "matrix", "raw_unit", "unit", "radius",
                                          "model", "temperature", "stats", "input_sha256",
                                          "source")}


def fold_asa(part: SensorCalibration, asa: Any) -> SensorCalibration:
    """A magnetometer part fitted on ASA-adjusted readings, rewritten for the register counts.

    With ``k`` the factors of :func:`triaxcal.io.akm.asa_factors`, the adjusted reading is
    ``k * raw``, so ``(k * raw - o) @ M.T = (raw - o / k) @ (M @ diag(k)).T``: the part's offset
    becomes ``o / k`` and its matrix ``M @ diag(k)``; ``stats["asa"]`` records the bytes.
    Temperature terms (in adjusted counts) are divided by ``k`` too.

    Examples
    --------
    >>> import numpy as np, triaxcal as tc
    >>> adjusted = tc.SensorCalibration(offset=[50.0, 0, 0], matrix=np.eye(3) * 0.15, unit="uT")
    >>> raw = fold_asa(adjusted, [192, 128, 128])          # k = 1.25, 1, 1
    >>> raw.apply([[40.0 * 1.0, 0, 0]]).round(9).tolist()   # 40 counts read 50 adjusted: 0 uT
    [[0.0, 0.0, 0.0]]
    """
    from ..io.akm import asa_factors

    options.instance(part, SensorCalibration, "part", "a SensorCalibration")
    k = asa_factors(asa)
    if part.stats.get("asa") is not None:
        raise CalibrationError("this part already holds an ASA adjustment")
    terms = part.temperature
    if terms is not None:
        if terms.gain_poly is not None:
            raise CalibrationError("cannot fold ASA into temperature gain terms")
        terms = TemperatureTerms(temp_ref_c=terms.temp_ref_c, temp_range_c=terms.temp_range_c,
                                 offset_poly=np.asarray(terms.offset_poly) / k)
    stats = {**part.stats, "asa": [int(v) for v in np.round((k - 1.0) * 256.0 + 128.0)],
             "asa_factors": [float(v) for v in k]}
    return SensorCalibration(**{**_fields(part), "offset": part.offset / k,
                                "matrix": part.matrix @ np.diag(k), "temperature": terms,
                                "stats": stats})


def _sensor_of(part: SensorCalibration, sensor: str | None) -> str | None:
    if sensor is not None:
        return sensor
    q = UNITS.get(part.unit, (None,))[0]
    return q if q in ("accel", "gyro", "mag") else None


def gated(part: SensorCalibration, sensor: str | None = None, *,
          force: bool = False) -> SensorCalibration:
    """``part`` judged by the validity gate (see the module notes): marked ``valid=True``, or
    refused, or with ``force`` marked ``valid=False``. ``sensor`` defaults to the quantity of
    the part's calibrated unit (none for raw counts: then only the checks that need no sensor
    run)."""
    s = _sensor_of(part, sensor)
    return judged(part, check_part(part, s or "part"), force=force)


def part_from_autocal(cal: Any, *, source: str | None = None, force: bool = False
                      ) -> SensorCalibration:
    """A free-living auto-calibration (:class:`~triaxcal.methods.autocal.AutoCalibration`) as a
    part: g -> g, ``matrix = diag(gain)``, the temperature terms in ``offset_poly``; through
    the validity gate (``force``: see the module notes)."""
    temp = None
    if cal.temp_ref_c is not None and cal.temp_range_c is not None:
        temp = TemperatureTerms(temp_ref_c=cal.temp_ref_c, temp_range_c=cal.temp_range_c,
                                offset_poly=np.vstack([np.zeros(3), cal.temp_coef]))
    stats = {
        "method": "van Hees et al. 2014 (free-living, still 10 s windows)",
        "accepted": cal.accepted,
        "status": cal.status,
        "error_before_g": cal.error_before_g,
        "error_after_g": cal.error_after_g,
        "n_windows": cal.n_windows,
        "n_still": cal.n_still,
        "hours": cal.hours,
        "iterations": cal.iterations,
        "settings": cal.settings,
    }
    part = SensorCalibration(offset=cal.offset, matrix=np.diag(cal.gain), raw_unit="g",
                             unit="g", radius=1.0, model="autocal-vanhees",
                             temperature=temp, stats=stats, source=source)
    return gated(part, "accel", force=force)


def part_from_factory(factory: Any) -> SensorCalibration:
    """A maker's calibration from a file header (:class:`triaxcal.io.wearables.
    FactoryCalibration`) as a part: counts -> g, ``matrix = diag(diag)``. It is the maker's
    own calibration, recorded as it is (model ``"factory"``), not judged by the gate."""
    return SensorCalibration(offset=factory.offset, matrix=np.diag(factory.diag),
                             raw_unit="counts", unit="g", radius=1.0, model="factory",
                             stats={"calibration_date": factory.date}, source=factory.source)
