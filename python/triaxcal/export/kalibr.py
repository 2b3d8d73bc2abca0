"""Kalibr IMU configuration (``imu.yaml``): topic, rate, noise figures and intrinsics.

Kalibr reads ``rostopic`` and ``update_rate`` and, for its noise model, the four keys
``accelerometer_noise_density`` (m/s^2/sqrt(Hz)), ``accelerometer_random_walk``
(m/s^3/sqrt(Hz)), ``gyroscope_noise_density`` (rad/s/sqrt(Hz)) and
``gyroscope_random_walk`` (rad/s^2/sqrt(Hz)), all required and positive
(``aslam_offline_calibration/kalibr/python/kalibr_common/ConfigReader.py``
``ImuParameters``). They are written when noise figures are given (the Allan-deviation
analysis gives them), else left out with a comment.

Intrinsics, as Kalibr's ``--imu-models`` name them and its results write them
(``kalibr_imu_camera_calibration/IccSensors.py``, ``IccScaledMisalignedImu``):

* ``calibrated``: the data on ``rostopic`` are already calibrated (by this calibration, applied
  upstream); no intrinsics.
* ``scale-misalignment``: Kalibr's measurement model is ::

      accel_measured = M_a @ a_i + b_a
      gyro_measured  = M_g @ (C_gyro_i @ w_i) + A @ a_i + b_g

  with ``M_a``, ``M_g`` lower triangular (Kalibr's design variables) and ``C_gyro_i`` a
  rotation. triaxcal's ``a = matrix_a @ (raw - offset_a)`` gives ``inv(matrix_a) = M_a @ Q``
  (an RQ decomposition); the IMU frame ``i`` of the file is triaxcal's calibrated frame turned
  by ``Q`` (``a_i = Q @ a``, written in a comment), and ``M_g @ C_gyro_i = inv(matrix_g) @
  Q.T``. ``A`` (g-sensitivity) is zero: triaxcal does not model it. Kalibr estimates the
  biases ``b`` itself as random-walk states, so triaxcal's offsets go in the comment block.

Kalibr's IMU model has no magnetometer: a magnetometer part (and its alignment with the
accelerometer) is not written, and the file says so in a comment.

Kalibr reads the file with ``yaml.safe_load`` (``kalibr_common/ConfigReader.py``
``ParametersBase.readYaml``), a YAML 1.1 reader whose float needs a decimal point: ``2e-05``
(Python's ``repr``) would come back as the *string* ``'2e-05'``. Every number is written by
:func:`yaml_float`, the shortest text that reads back to the same double and that YAML 1.1
reads as a float (``2.0e-05``). ``topic`` must be a valid ROS name.

A part the validity gate refuses is written only with ``force``, and the file then says so in
two keys Kalibr ignores: ``valid: false`` and ``invalid_reasons``.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from .._checks import options
from .._checks.spelling import opt
from .._core import __version__
from ..calibration.file import Calibration
from ..errors import CalibrationError
from ..quality.bounds import sample_rate
from ._params import physical, require_no_gain_poly
from ._trust import Scales, mark_lines, prepare

__all__ = ["KALIBR_MODELS", "KALIBR_NOISE_KEYS", "kalibr_imu_yaml", "kalibr_intrinsics",
           "yaml_float"]

FMT = "Kalibr"
KALIBR_MODELS = ("calibrated", "scale-misalignment")
KALIBR_NOISE_KEYS = ("accelerometer_noise_density", "accelerometer_random_walk",
                     "gyroscope_noise_density", "gyroscope_random_walk")
_NOISE_UNITS = ("m/s^2/sqrt(Hz)", "m/s^3/sqrt(Hz)", "rad/s/sqrt(Hz)", "rad/s^2/sqrt(Hz)")
_ROS_NAME = re.compile(r"^[~/]?[A-Za-z][A-Za-z0-9_]*(/[A-Za-z][A-Za-z0-9_]*)*$")


def _lq(a: np.ndarray, what: str) -> tuple[np.ndarray, np.ndarray]:
    """``a = L @ Q``: L lower triangular with positive diagonal, Q a rotation."""
    if np.linalg.det(a) <= 0:
        raise CalibrationError(f"the {what} matrix has a non-positive determinant (a mirrored "
                               "axis): Kalibr's rotation cannot hold it")
    q1, r1 = np.linalg.qr(a.T)
    d = np.sign(np.diag(r1))
    d[d == 0] = 1.0
    lower = np.tril((d[:, None] * r1).T) + 0.0  # exact zeros above the diagonal, no -0.0
    rot = (q1 * d).T + 0.0
    return lower, rot


def yaml_float(v: Any) -> str:
    """``v`` as text that YAML 1.1 (PyYAML's ``safe_load``) reads back as the same float.

    >>> yaml_float(2e-05), yaml_float(1e+20), yaml_float(200.0), yaml_float(-0.5)
    ('2.0e-05', '1.0e+20', '200.0', '-0.5')
    """
    f = float(v)
    if not math.isfinite(f):
        raise CalibrationError(f"cannot write {f} into Kalibr's YAML")
    r = repr(f)
    mant, e, exp = r.partition("e")
    if "." not in mant:
        mant += ".0"
    if e and exp[0] not in "+-":
        exp = "+" + exp
    return mant + (("e" + exp) if e else "")


def kalibr_intrinsics(cal: Calibration, *, counts_per_unit: Mapping[str, Any] | None = None,
                      sensor_model: str | Sequence[str] | None = None
                      ) -> dict[str, np.ndarray]:
    """Kalibr's ``scale-misalignment`` intrinsics of ``cal`` (see the module docstring).

    Returns ``M_accel``, ``M_gyro``, ``C_gyro_i``, ``A_gyro`` (zeros), ``R_i`` (the rotation
    from triaxcal's calibrated frame to Kalibr's IMU frame), ``b_accel`` and ``b_gyro`` (m/s^2,
    rad/s: triaxcal's offsets, which Kalibr estimates as states).
    """
    for s in ("accel", "gyro"):
        if getattr(cal, s) is None:
            raise CalibrationError(
                f"Kalibr's scale-misalignment model needs accelerometer and gyroscope parts; "
                f"this calibration has no {s}: add it, or write "
                f"{opt('model', 'calibrated', flag='--kalibr-model')}"
            )
    scales = Scales(counts_per_unit, sensor_model)
    pa = physical(cal.part("accel"), "accel", "m/s^2", "m/s^2", scales, fmt=FMT)
    pg = physical(cal.part("gyro"), "gyro", "rad/s", "rad/s", scales, fmt=FMT)
    for p in (pa, pg):
        if p.offset_poly is not None:
            require_no_gain_poly(p, FMT)
            raise CalibrationError(
                f"Kalibr's IMU model has no temperature terms; this calibration's {p.sensor} "
                "has them: apply the calibration upstream and write "
                f"{opt('model', 'calibrated', flag='--kalibr-model')}"
            )
    m_a, q = _lq(np.linalg.inv(pa.matrix), "accelerometer")
    m_g, c = _lq(np.linalg.inv(pg.matrix) @ q.T, "gyroscope")
    return {"M_accel": m_a, "M_gyro": m_g, "C_gyro_i": c, "A_gyro": np.zeros((3, 3)),
            "R_i": q, "b_accel": pa.offset, "b_gyro": pg.offset}


def _num(v: Any, name: str, positive: bool = True) -> float:
    return options.number(v, name, gt=0 if positive else None,
                          hint="Kalibr refuses others" if positive else "")


def _mat(m: np.ndarray) -> str:
    return "[" + ", ".join("[" + ", ".join(yaml_float(x) for x in row) + "]" for row in m) + "]"


def kalibr_imu_yaml(
    cal: Calibration | None,
    *,
    topic: str = "/imu0",
    rate_hz: float,
    noise: Mapping[str, float] | None = None,
    model: str = "scale-misalignment",
    counts_per_unit: Mapping[str, Any] | None = None,
    sensor_model: str | Sequence[str] | None = None,
    force: bool = False,
) -> str:
    """Kalibr ``imu.yaml`` text.

    Parameters
    ----------
    cal : Calibration or None
        The IMU calibration (accelerometer and gyroscope parts for ``scale-misalignment``;
        any or None for ``calibrated``).
    topic : str
        The ``sensor_msgs/Imu`` topic Kalibr reads (``rostopic``).
    rate_hz : float
        IMU rate in Hz (``update_rate``; Kalibr discretises the noise densities with it).
    noise : mapping, optional
        ``accelerometer_noise_density``, ``accelerometer_random_walk``,
        ``gyroscope_noise_density``, ``gyroscope_random_walk`` (Kalibr's units, see the module
        docstring), all four, each > 0.
    model : {"scale-misalignment", "calibrated"}
        Kalibr's IMU model (``--imu-models``).
    counts_per_unit : dict, optional
        The driver's scale for parts in raw counts (none is assumed).
    sensor_model : str or list of str, optional
        The part(s) whose datasheet scale converts raw counts.
    force : bool
        Write accelerometer and gyroscope parts the validity gate refuses, marked
        ``valid: false`` with ``invalid_reasons``.

    Examples
    --------
    >>> print(kalibr_imu_yaml(None, topic="/imu0", rate_hz=200, model="calibrated",
    ...                       noise={"accelerometer_noise_density": 1.86e-3,
    ...                              "accelerometer_random_walk": 4.33e-4,
    ...                              "gyroscope_noise_density": 1.87e-4,
    ...                              "gyroscope_random_walk": 2.66e-5}).splitlines()[-4])
    rostopic: /imu0
    """
    if model not in KALIBR_MODELS:
        raise CalibrationError(f"unknown Kalibr IMU model {model!r}: use one of {KALIBR_MODELS}")
    if not isinstance(topic, str) or not _ROS_NAME.match(topic):
        raise CalibrationError(f"topic {topic!r} is not a ROS topic name (e.g. /imu0, "
                               "/imu/data_raw)")
    rate = sample_rate(rate_hz)
    if cal is not None and not isinstance(cal, Calibration):
        raise CalibrationError(f"expected a Calibration or None, got {type(cal).__name__}")
    lines = [f"# Kalibr IMU configuration written by triaxcal {__version__}"]
    marks: list[str] = []
    if cal is not None:
        imu = [s for s in ("accel", "gyro") if getattr(cal, s) is not None]
        prep = prepare(cal, imu, fmt=FMT, force=force)
        cal = prep.cal
        lines += ["# " + _safe(n, 4000) for n in prep.notes]
        if prep.invalid:
            marks = ["valid: false", "invalid_reasons:"] + [
                "  - " + json.dumps(_safe(m, 4000)) for m in mark_lines(prep.invalid)]
    if cal is not None:
        lines.append(f"# calibration of sensor {_safe(cal.sensor_id)!r}, created "
                     f"{_safe(cal.created_utc)}")
        if cal.mag is not None:
            lines.append("# not written: the magnetometer part"
                         + (" and its alignment to the accelerometer" if cal.mag.alignment
                            is not None else "") + " (Kalibr's IMU model has no magnetometer)")
    if noise is not None:
        if not isinstance(noise, Mapping):
            raise CalibrationError("noise must be a mapping of Kalibr's four noise keys")
        unknown = set(noise) - set(KALIBR_NOISE_KEYS)
        missing = set(KALIBR_NOISE_KEYS) - set(noise)
        if unknown or missing:
            raise CalibrationError(
                f"noise needs exactly Kalibr's keys {KALIBR_NOISE_KEYS}"
                + (f"; unknown: {sorted(unknown)}" if unknown else "")
                + (f"; missing: {sorted(missing)}" if missing else "")
            )
        for key, unit in zip(KALIBR_NOISE_KEYS, _NOISE_UNITS):
            lines.append(f"{key}: {yaml_float(_num(noise[key], key))}  # {unit}")
    else:
        lines.append("# noise figures not given: Kalibr needs accelerometer_noise_density, "
                     "accelerometer_random_walk, gyroscope_noise_density, gyroscope_random_walk")
    lines += [f"rostopic: {topic}", f"update_rate: {yaml_float(rate)}  # Hz", f"model: {model}"]
    lines += marks
    if model == "calibrated":
        lines.append("# the readings on rostopic must already be calibrated (calibration "
                     "applied upstream)")
        return "\n".join(lines) + "\n"
    if cal is None:
        raise CalibrationError("model 'scale-misalignment' needs a calibration")
    k = kalibr_intrinsics(cal, counts_per_unit=counts_per_unit, sensor_model=sensor_model)
    lines += [
        "# measured accel = M @ a_i + b;  measured gyro = M @ (C_gyro_i @ w_i) + A @ a_i + b",
        "# frame i = R_i @ (triaxcal's calibrated frame), R_i = " + _mat(k["R_i"]),
        "# biases (Kalibr estimates them as states): triaxcal's offsets b_accel = "
        + _mat(k["b_accel"][None])[1:-1] + " m/s^2, b_gyro = "
        + _mat(k["b_gyro"][None])[1:-1] + " rad/s",
        "accelerometers:",
        f"  M: {_mat(k['M_accel'])}",
        "gyroscopes:",
        f"  A: {_mat(k['A_gyro'])}",
        f"  C_gyro_i: {_mat(k['C_gyro_i'])}",
        f"  M: {_mat(k['M_gyro'])}",
    ]
    return "\n".join(lines) + "\n"


def _safe(text: str, limit: int = 120) -> str:
    return "".join(ch if ch.isprintable() else "?" for ch in str(text))[:limit]
