"""Temperature compensation: offsets (and gains) as polynomials in the temperature change.

Error model: at die temperature ``T`` (degC) a raw reading ``r`` (counts) of a true vector ``v``
(calibrated units) is

    r = offset(T) + S(T) @ v,        offset(T) = sum_k offset_coef[k] * dT**k,
                                     S(T)      = sum_k sens_coef[k]   * dT**k,   dT = T - T_ref,

with ``S`` the sensitivity (counts per unit: the inverse of the calibration matrix), so that

    calibrated = matrix(T) @ (raw - offset(T)),        matrix(T) = inv(S(T)).

Degree 1 is the linear trend line of the turn-integration method (
``x = (raw - (tempcomp * dT + offset)) / gain``); degrees 2 and 3 are the autopilots' thermal
calibration. All coefficients come from one linear least-squares solve per axis.

* Offsets only (``truth=None``): readings of a zero quantity (a gyro at rest) while the sensor
  warms or cools; ``matrix(T)`` is the constant ``matrix`` given (default identity).
* Gains too (``truth`` given): readings with known true values (a simulator, a rate table, or
  poses whose gravity direction is known), ``gain="diag"`` (per-axis sensitivity) or ``"full"``
  (3x3 sensitivity).

Applying a model outside the temperatures it was fitted on warns with
:class:`TemperatureRangeWarning`: polynomials extrapolate badly.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._checks import options as opt
from .._checks.arrays import as_samples
from ..errors import CalibrationError
from ..quality.bounds import DIE_TEMPERATURE_C

__all__ = ["TemperatureModel", "TemperatureRangeWarning", "fit_temperature"]


class TemperatureRangeWarning(UserWarning):
    """A temperature model was applied outside the range of temperatures it was fitted on."""


def _ro(a: Any) -> np.ndarray:
    arr = np.array(a, dtype=np.float64)
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True)
class TemperatureModel:
    """Offsets and sensitivities as polynomials in ``dT = T - reference_degC``.

    Attributes
    ----------
    reference_degC : float
        Reference temperature, degC.
    degree : int
        Polynomial degree (1..3).
    offset_coef : ndarray (degree + 1, 3)
        Offset polynomial coefficients, counts / degC**k (row k multiplies dT**k).
    sens_coef : ndarray (degree + 1, 3, 3)
        Sensitivity polynomial coefficients, counts per calibrated unit / degC**k. Constant
        (``inv(matrix)`` in row 0, zeros above) when gains were not fitted.
    gain : str
        ``"none"``, ``"diag"`` or ``"full"``: what the sensitivity fit covered.
    t_min_degC, t_max_degC : float
        Temperature range of the fit.
    rms : ndarray (3,)
        RMS residual per axis, counts.
    n : int
        Samples fitted.
    """

    reference_degC: float
    degree: int
    offset_coef: np.ndarray
    sens_coef: np.ndarray
    gain: str
    t_min_degC: float
    t_max_degC: float
    rms: np.ndarray
    n: int

    def _dt(self, temp_degC: Any, warn: bool = True) -> np.ndarray:
        t = _temperatures(temp_degC)
        if not np.isfinite(t).all():
            raise CalibrationError("temperature contains NaN or inf")
        if warn and t.size and (t.min() < self.t_min_degC or t.max() > self.t_max_degC):
            warnings.warn(
                f"temperature {t.min():.2f}..{t.max():.2f} degC is outside the fitted range "
                f"{self.t_min_degC:.2f}..{self.t_max_degC:.2f} degC: the polynomial is "
                "extrapolating; record a calibration over the whole operating range",
                TemperatureRangeWarning,
                stacklevel=3,
            )
        return t - self.reference_degC

    def offset(self, temp_degC: Any) -> np.ndarray:
        """Offset in counts at ``temp_degC`` (scalar -> (3,), (N,) -> (N, 3))."""
        dt = self._dt(temp_degC)
        powers = dt[..., None] ** np.arange(self.degree + 1)
        return powers @ self.offset_coef

    def sensitivity(self, temp_degC: Any) -> np.ndarray:
        """Sensitivity ``S(T)`` in counts per unit ((3, 3), or (N, 3, 3))."""
        dt = self._dt(temp_degC)
        powers = dt[..., None] ** np.arange(self.degree + 1)
        return np.tensordot(powers, self.sens_coef, axes=(-1, 0))

    def matrix(self, temp_degC: Any) -> np.ndarray:
        """Calibration matrix ``inv(S(T))``, units per count, multiplies."""
        return np.linalg.inv(self.sensitivity(temp_degC))

    def apply(self, raw: Any, temp_degC: Any) -> np.ndarray:
        """Calibrated readings ``matrix(T) @ (raw - offset(T))`` for raw (N, 3), T (N,) or
        a scalar. Warns with :class:`TemperatureRangeWarning` outside the fitted range."""
        r = as_samples(raw, "raw", finite=True)
        t = _temperatures(temp_degC)
        if t.ndim > 1 or (t.ndim == 1 and t.shape[0] != r.shape[0]):
            raise CalibrationError(
                f"temp_degC must be one temperature or one per reading ({r.shape[0]}), got "
                f"shape {t.shape}"
            )
        t = np.broadcast_to(t, r.shape[:1])
        dt = self._dt(t)
        powers = dt[:, None] ** np.arange(self.degree + 1)
        off = powers @ self.offset_coef
        sens = np.tensordot(powers, self.sens_coef, axes=(-1, 0))  # (N, 3, 3)
        return np.linalg.solve(sens, (r - off)[..., None])[..., 0]


def _temperatures(temp_degC: Any) -> np.ndarray:
    """Temperatures (degC) as float64, refusing text, booleans and complex numbers, and values
    no sensor die takes (:data:`~triaxcal.quality.bounds.DIE_TEMPERATURE_C`)."""
    try:
        t = np.asarray(temp_degC) if not isinstance(temp_degC, (str, bytes)) else np.asarray(
            [temp_degC])
    except (TypeError, ValueError):  # ragged lists
        raise CalibrationError(f"temp_degC must be one temperature (degrees Celsius) per "
                               f"reading, got {str(temp_degC)[:60]!r}") from None
    if t.dtype.kind not in "iuf":
        raise CalibrationError(
            f"temp_degC must hold real numbers (degrees Celsius), got dtype {t.dtype}"
        )
    t = t.astype(np.float64)
    lo, hi = DIE_TEMPERATURE_C
    out = ~((t >= lo) & (t <= hi)) & np.isfinite(t)
    if out.any():
        raise CalibrationError(
            f"temp_degC holds {float(t[out].flat[0]):.6g} degC, outside {lo:g}..{hi:g} degC "
            "where a sensor works: is that column a temperature, in degrees Celsius?")
    return t


def fit_temperature(
    raw: Any,
    temp_degC: Any,
    *,
    degree: int = 1,
    reference_degC: float | None = None,
    truth: Any = None,
    gain: str | None = None,
    matrix: Any = None,
    min_range_degC: float = 0.1,
) -> TemperatureModel:
    """Fit temperature polynomials of the offset (and sensitivity) by least squares.

    Parameters
    ----------
    raw : array_like (N, 3)
        Raw readings, counts, taken over a range of temperatures.
    temp_degC : array_like (N,)
        Die temperature of each reading, degC.
    degree : int
        1 (linear trend, default), 2 or 3.
    reference_degC : float, optional
        ``T_ref``; default: the temperature of the first reading (the turn-integration method's
        "since start").
    truth : array_like (N, 3), optional
        True values of the readings in calibrated units; ``None``: the true value is zero
        (a gyro at rest), and only offsets are fitted.
    gain : {"none", "diag", "full"}, optional
        Sensitivity model; default ``"diag"`` with ``truth``, ``"none"`` without.
    matrix : array_like (3, 3), optional
        Constant calibration matrix (units per count) for ``gain="none"``; default identity
        (calibrated = raw - offset(T), in counts).
    min_range_degC : float
        Smallest temperature span accepted.

    Returns
    -------
    TemperatureModel

    Examples
    --------
    >>> import numpy as np, triaxcal as tc
    >>> temp = np.linspace(20.0, 40.0, 200)
    >>> gyro_at_rest = np.column_stack([50 + 2.0 * (temp - 20), -30 - 1.5 * (temp - 20),
    ...                                 10 + 0.0 * temp])
    >>> m = tc.fit_temperature(gyro_at_rest, temp)        # reference: 20 degC, the first reading
    >>> m.offset_coef.round(6).tolist()                   # counts, counts per degC
    [[50.0, -30.0, 10.0], [2.0, -1.5, 0.0]]

    Raises
    ------
    CalibrationError
        Wrong shapes, NaN, a degree outside 1..3, a temperature range of (almost) zero or too
        few distinct temperatures for the degree, or true values that do not excite every
        sensitivity term.
    """
    r = as_samples(raw, "raw")
    t = _temperatures(temp_degC).reshape(-1)
    if t.shape[0] != r.shape[0]:
        raise CalibrationError(f"temp_degC has {t.shape[0]} values for {r.shape[0]} readings")
    if not np.isfinite(t).all():
        raise CalibrationError("temp_degC contains NaN or inf; drop those samples first")
    deg = opt.integer(degree, "degree", ge=1, le=3, hint="1 linear, 2, 3")
    ref_given = opt.optional_number(reference_degC, "reference_degC",
                                    hint="degrees Celsius, or None for the first reading")
    min_range = opt.number(min_range_degC, "min_range_degC", ge=0, hint="degrees Celsius")
    if gain is not None:
        opt.choice(gain, "gain", ("none", "diag", "full"))
    if r.shape[0] == 0:
        raise CalibrationError("no readings: record while the sensor warms up or cools down")
    span = float(t.max() - t.min())
    if span < min_range:
        raise CalibrationError(
            f"temperature range of {span:.3g} degC (at {t.min():.2f} degC): a temperature model "
            f"needs readings over a range of temperatures (at least {min_range:g} degC); "
            "record while the sensor warms up or cools down"
        )
    distinct = np.unique(t).size
    if distinct <= deg:
        raise CalibrationError(
            f"only {distinct} distinct temperatures, a degree-{deg} polynomial needs at least "
            f"{deg + 1}"
        )
    degree = deg
    if gain is None:
        gain = "none" if truth is None else "diag"
    if gain not in ("none", "diag", "full"):
        raise CalibrationError(f"gain must be 'none', 'diag' or 'full', got {gain!r}")
    if gain != "none" and truth is None:
        raise CalibrationError(f"gain={gain!r} needs the true values: pass truth=(N, 3)")
    t_ref = float(t[0]) if ref_given is None else ref_given
    dt = t - t_ref
    s = max(float(np.abs(dt).max()), 1e-12)  # scale dT for conditioning
    p = (dt / s)[:, None] ** np.arange(degree + 1)  # (N, d+1)
    unscale = s ** -np.arange(degree + 1.0)
    nd = degree + 1
    if truth is None:
        v = np.zeros_like(r)
    else:
        v = as_samples(truth, "truth", finite=True)
        if v.shape != r.shape:
            raise CalibrationError(f"truth must have the shape of raw {r.shape}, got {v.shape}")
    if gain == "none":
        m = np.eye(3) if matrix is None else as_samples(matrix, "matrix", finite=True)
        if m.shape != (3, 3):
            raise CalibrationError(f"matrix must be a (3, 3) array, got shape {m.shape}")
        if abs(np.linalg.det(m)) <= 1e-12 * np.abs(m).max() ** 3:
            raise CalibrationError("matrix is singular: give an invertible (3, 3) matrix")
        sens0 = np.linalg.inv(m)
        target = r - v @ sens0.T
        coef, *_ = np.linalg.lstsq(p, target, rcond=None)  # (d+1, 3)
        off = coef * unscale[:, None]
        sens = np.zeros((nd, 3, 3))
        sens[0] = sens0
        resid = target - p @ coef
    else:
        off = np.zeros((nd, 3))
        sens = np.zeros((nd, 3, 3))
        resid = np.zeros_like(r)
        for i in range(3):
            cols = [p]
            srcs = [i] if gain == "diag" else [0, 1, 2]
            for j in srcs:
                cols.append(p * v[:, j : j + 1])
            design = np.hstack(cols)
            norms = np.linalg.norm(design, axis=0)
            if np.any(norms == 0):
                raise CalibrationError(
                    f"the true values never excite axis {'xyz'[i]}: the {gain!r} gain model "
                    "needs readings with that axis (and, for 'full', every axis) non-zero"
                )
            sv = np.linalg.svd(design / norms, compute_uv=False)
            if sv[-1] < 1e-9 * sv[0]:
                raise CalibrationError(
                    f"axis {'xyz'[i]}: offset and gain cannot be told apart (the true values "
                    "do not vary, or vary with temperature): record several orientations at "
                    "each temperature"
                )
            c, *_ = np.linalg.lstsq(design, r[:, i], rcond=None)
            resid[:, i] = r[:, i] - design @ c
            off[:, i] = c[:nd] * unscale
            for kk, j in enumerate(srcs):
                sens[:, i, j] = c[nd * (kk + 1): nd * (kk + 2)] * unscale
    if abs(np.linalg.det(sens[0])) == 0:
        raise CalibrationError("the fitted sensitivity is singular at the reference temperature")
    return TemperatureModel(
        reference_degC=t_ref,
        degree=int(degree),
        offset_coef=_ro(off),
        sens_coef=_ro(sens),
        gain=gain,
        t_min_degC=float(t.min()),
        t_max_degC=float(t.max()),
        rms=_ro(np.sqrt(np.mean(resid**2, axis=0))),
        n=int(r.shape[0]),
    )
