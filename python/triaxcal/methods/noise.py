"""Noise figures of an inertial sensor from its Allan deviation, for filters and for Kalibr.

Noise model (IEEE Std 952-1997 annex C, Std 1554-2005): the Allan variance of a sensor at rest
is a sum of independent terms with known slopes,

    sigma^2(tau) = 3 Q^2 / tau^2 + N^2 / tau + (2 ln 2 / pi) B^2 + K^2 tau / 3 + R^2 tau^2 / 2,

with, for a gyroscope reading in deg/s (an accelerometer: velocity for angle, m/s^2 for deg/s):

* ``N`` **angle (velocity) random walk**, the white rate noise density, unit/sqrt(Hz)
  (= deg/sqrt(s); times 60: deg/sqrt(h)). Slope -1/2; ``sigma(1 s) = N``. In discrete time the
  per-sample standard deviation at rate ``f`` is ``N sqrt(f)``.
* ``B`` **bias instability** (flicker floor), unit (deg/s; times 3600: deg/h). Slope 0; the
  floor is ``0.664 B``, reached at the time the report names.
* ``K`` **rate (acceleration) random walk**, unit/sqrt(s) (= deg/s^2/sqrt(Hz)). Slope +1/2;
  ``sigma(3 s) = K``. In discrete time the bias steps by ``K / sqrt(f)`` per sample.
* ``Q`` quantization (unit*s, slope -1) and ``R`` rate ramp (unit/s, slope +1), fitted so that
  they do not leak into the others, reported as extras.

The coefficients ``Q^2 .. R^2`` enter linearly, so they are fitted together by non-negative
weighted least squares on the Allan variance (weights from the approximate degrees of freedom
of each point, reweighted with the model twice), which uses every averaging time instead of
reading single points off straight lines. A figure is *resolved* when its term makes at least
half of the fitted variance at some averaging time with enough independent clusters and its
relative uncertainty is below 25 %; otherwise :attr:`NoiseFigures.warnings` says the log is
too short (or the term too small) and :attr:`AxisNoise.upper` holds an upper bound.

Kalibr (ethz-asl/kalibr, ``kalibr_common/ConfigReader.py`` ``ImuParameters``) reads
``gyroscope_noise_density`` (rad/s/sqrt(Hz)), ``gyroscope_random_walk`` (rad/s^2/sqrt(Hz)),
``accelerometer_noise_density`` (m/s^2/sqrt(Hz)) and ``accelerometer_random_walk``
(m/s^3/sqrt(Hz)) -- the continuous-time ``N`` and ``K`` above in SI units -- and discretises
them itself with ``update_rate`` (``sigma_d = N / sqrt(1 / update_rate)``). It refuses values
<= 0 and uses one value for all three axes: :func:`kalibr_noise` writes the largest axis.
"""

from __future__ import annotations

import importlib.util
import io
import itertools
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .._checks import options
from .._checks.spelling import opt
from ..conventions.units import UNITS, unit_factor
from ..errors import CalibrationError
from ..io.files import write_file
from ..quality.bounds import SAMPLE_RATE_HZ
from .allan import AllanDeviation, allan

__all__ = [
    "TERMS",
    "AxisNoise",
    "NoiseFigures",
    "kalibr_noise",
    "noise_figures",
    "plot_allan",
]

#: Allan deviation floor of flicker noise per unit of bias instability, sqrt(2 ln 2 / pi).
FLICKER_FLOOR = math.sqrt(2.0 * math.log(2.0) / math.pi)
#: The terms of the model, in order: quantization, white, bias instability, random walk, ramp.
TERMS = ("quantization", "white", "bias_instability", "random_walk", "ramp")
#: A term must make this share of the fitted variance somewhere to count as resolved.
RESOLVED_SHARE = 0.5
#: ... with a relative (1-sigma) uncertainty below this.
RESOLVED_REL_ERR = 0.25
#: Averaging times with fewer equivalent degrees of freedom than this do not resolve a term.
MIN_EDF = 4.0


def _basis(tau: np.ndarray) -> np.ndarray:
    t = np.asarray(tau, dtype=np.float64)
    return np.column_stack(
        [3.0 / t**2, 1.0 / t, np.full_like(t, FLICKER_FLOOR**2), t / 3.0, t**2 / 2.0]
    )


def _nnls(a: np.ndarray, b: np.ndarray, cols: list[int]) -> tuple[np.ndarray, list[int]]:
    """Non-negative least squares ``min |a c - b|, c >= 0`` over the columns ``cols`` (few:
    every subset is tried, which is exact). Returns (c over all columns, active columns)."""
    norms = np.linalg.norm(a, axis=0)
    norms[norms == 0] = 1.0
    an = a / norms
    best: tuple[float, np.ndarray, list[int]] | None = None
    for r in range(1, len(cols) + 1):
        for sub in itertools.combinations(cols, r):
            s = list(sub)
            sol, *_ = np.linalg.lstsq(an[:, s], b, rcond=None)
            if (sol < 0).any():
                continue
            cost = float(np.sum((an[:, s] @ sol - b) ** 2))
            if best is None or cost < best[0] - 1e-15 * abs(cost):
                c = np.zeros(a.shape[1])
                c[s] = sol / norms[s]
                best = (cost, c, s)
    if best is None:  # cannot happen: a single column always has a non-negative solution
        raise CalibrationError("the Allan deviation could not be fitted")
    return best[1], best[2]


@dataclass(frozen=True)
class AxisNoise:
    """Noise figures of one axis (units: see :class:`NoiseFigures`; ``u`` = its ``unit``).

    Attributes
    ----------
    axis : str
    white : float
        N, white rate noise density (angle / velocity random walk), u/sqrt(Hz).
    bias_instability : float
        B, bias instability (flicker floor / 0.664), u.
    bias_tau_s : float
        Averaging time in s where the fitted Allan deviation is lowest (where the bias
        instability shows).
    adev_min : float
        The lowest measured Allan deviation, u, and ...
    adev_min_tau_s : float
        ... its averaging time, s.
    random_walk : float
        K, rate / acceleration random walk, u/sqrt(s) (= u/s/sqrt(Hz)).
    quantization : float
        Q, u*s.
    ramp : float
        R, rate ramp, u/s.
    rel_err : dict
        Approximate 1-sigma relative uncertainty of each figure (``inf`` where it is 0).
    resolved : dict
        Whether the log resolves each figure (see the module docstring).
    upper : dict
        An upper bound for each figure from the measured deviation alone (for the ones that
        are not resolved).
    """

    axis: str
    white: float
    bias_instability: float
    bias_tau_s: float
    adev_min: float
    adev_min_tau_s: float
    random_walk: float
    quantization: float
    ramp: float
    rel_err: dict[str, float] = field(default_factory=dict)
    resolved: dict[str, bool] = field(default_factory=dict)
    upper: dict[str, float] = field(default_factory=dict)

    def value(self, term: str) -> float:
        """The figure called ``term`` (one of :data:`TERMS`)."""
        if term not in TERMS:
            raise CalibrationError(f"unknown noise term {term!r}: use one of {TERMS}")
        return float(getattr(self, term))

    def model_adev(self, tau: Any) -> np.ndarray:
        """The fitted Allan deviation at ``tau`` seconds, u."""
        c = np.array([self.value(t) ** 2 for t in TERMS])
        return np.sqrt(_basis(np.atleast_1d(np.asarray(tau, dtype=np.float64))) @ c)


@dataclass(frozen=True)
class NoiseFigures:
    """Noise figures per axis, fitted to the Allan deviation (see the module docstring).

    Attributes
    ----------
    sensor : str or None
        ``"gyro"`` or ``"accel"``: names the figures (angle vs velocity random walk...).
    unit : str
        Unit of the readings, e.g. ``"deg/s"``; figures are in unit/sqrt(Hz) (N), unit (B),
        unit/sqrt(s) (K), unit*s (Q), unit/s (R).
    rate_hz : float
        Sample rate, Hz (for the per-sample, discrete-time equivalents).
    duration_s : float
        Length of the log, s.
    axes : tuple of AxisNoise
    allan : AllanDeviation
        The Allan deviation the figures were fitted to.
    warnings : tuple of str
        Plain-language warnings: figures the log is too short for, and what to do.
    motion : str or None
        Set when the figures were computed although the readings were not at rest (what the
        at-rest test found, :mod:`triaxcal.methods.rest`): they describe the motion as much as
        the sensor, and every output says so.
    """

    sensor: str | None
    unit: str
    rate_hz: float
    duration_s: float
    axes: tuple[AxisNoise, ...]
    allan: AllanDeviation
    warnings: tuple[str, ...] = ()
    motion: str | None = None

    def worst(self, term: str) -> float:
        """The largest value of ``term`` over the axes (what a filter should assume)."""
        return max(a.value(term) for a in self.axes)

    def per_sample(self, term: str, axis: int | str = 0) -> float:
        """Discrete-time equivalent at :attr:`rate_hz`: the per-sample standard deviation of
        the white noise (``N sqrt(f)``, unit) or of the bias step (``K / sqrt(f)``, unit)."""
        ax = self._axis(axis)
        if term == "white":
            return ax.white * math.sqrt(self.rate_hz)
        if term == "random_walk":
            return ax.random_walk / math.sqrt(self.rate_hz)
        raise CalibrationError("per-sample values exist for 'white' and 'random_walk'")

    def _axis(self, axis: int | str) -> AxisNoise:
        if isinstance(axis, str):
            for a in self.axes:
                if a.axis == axis:
                    return a
            raise CalibrationError(f"no axis {axis!r}: axes are {[a.axis for a in self.axes]}")
        return self.axes[axis]

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON values (the figures per axis, in :attr:`unit`). A value that is not a
        finite number -- the relative uncertainty of a term the fit left at zero -- is None
        (JSON null), and ``"null"`` says so."""
        d = {
            "sensor": self.sensor,
            "unit": self.unit,
            "rate_hz": self.rate_hz,
            "duration_s": self.duration_s,
            "at_rest": self.motion is None,
            "motion": self.motion,
            "axes": {
                a.axis: {
                    **{t: a.value(t) for t in TERMS},
                    "white_per_sample": a.white * math.sqrt(self.rate_hz),
                    "random_walk_per_sample": a.random_walk / math.sqrt(self.rate_hz),
                    "bias_tau_s": a.bias_tau_s,
                    "adev_min": a.adev_min,
                    "adev_min_tau_s": a.adev_min_tau_s,
                    "rel_err": dict(a.rel_err),
                    "resolved": dict(a.resolved),
                    "upper": dict(a.upper),
                }
                for a in self.axes
            },
            "warnings": list(self.warnings),
            "null": "a value that is not a finite number: a relative uncertainty (rel_err) of a "
                    "term the fit left at zero has none",
        }
        return _finite(d)

    def text(self) -> str:
        """The figures as console text, both conventions side by side."""
        return _text(self)


def _finite(v: Any) -> Any:
    """``v`` with every float that is not finite replaced by None (JSON null)."""
    if isinstance(v, float):
        return v if math.isfinite(v) else None
    if isinstance(v, dict):
        return {k: _finite(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_finite(x) for x in v]
    return v


def noise_figures(
    data: Any,
    rate_hz: float | None = None,
    *,
    sensor: str | None = "gyro",
    unit: str | None = None,
    taus: Any = "log",
    terms: tuple[str, ...] = TERMS,
) -> NoiseFigures:
    """Fit the noise figures (angle / velocity random walk, bias instability, rate /
    acceleration random walk) to the Allan deviation of a sensor at rest.

    Parameters
    ----------
    data : AllanDeviation, or readings (N, K) / (N,), or an iterable of chunks
        An Allan deviation from :func:`triaxcal.allan`, or readings at rest (then ``rate_hz``
        is needed and the deviation is computed with ``taus``).
    rate_hz : float, optional
        Sample rate in Hz, for readings.
    sensor : {"gyro", "accel", None}
        Names the figures in the text and the Kalibr keys.
    unit : str, optional
        Unit of the readings (``"deg/s"``, ``"rad/s"``, ``"m/s^2"``, ``"g"``, ``"counts"``).
        Default: the Allan deviation's unit, or ``"counts"``.
    taus : {"log", "octave"} or array_like
        Averaging times for readings (default about 10 per decade).
    terms : tuple of str
        The terms fitted (default all of :data:`TERMS`; the rest are fixed at 0).

    Returns
    -------
    NoiseFigures

    Examples
    --------
    >>> import numpy as np, triaxcal as tc
    >>> from triaxcal.sim import NoiseTruth, simulate_noise
    >>> truth = NoiseTruth(white=0.01, random_walk=0.001)        # deg/s/sqrt(Hz), deg/s/sqrt(s)
    >>> gyro = simulate_noise(truth, 200_000, 50.0, seed=2)       # 4000 s at 50 Hz, deg/s
    >>> nf = tc.noise_figures(gyro, 50.0, unit="deg/s")
    >>> round(nf.axes[0].white, 3), round(nf.per_sample("white"), 2)  # density, per sample
    (0.01, 0.07)
    """
    if isinstance(data, AllanDeviation):
        ad = data
        if unit is not None and unit != ad.unit:
            raise CalibrationError(
                f"unit {unit!r} differs from the Allan deviation's unit {ad.unit!r}"
            )
    else:
        if rate_hz is None:
            raise CalibrationError("rate_hz is needed to compute noise figures from readings")
        ad = allan(data, rate_hz, taus=taus, unit=unit or "counts")
    if sensor not in ("gyro", "accel", None):
        raise CalibrationError(f"sensor must be 'gyro', 'accel' or None, got {sensor!r}")
    if isinstance(terms, (str, bytes)) or not isinstance(terms, (tuple, list)) or not all(
            isinstance(t, str) for t in terms):
        raise CalibrationError(f"terms must be a non-empty subset of {TERMS}, got {terms!r:.80}")
    bad = set(terms) - set(TERMS)
    if bad or not terms:
        raise CalibrationError(f"terms must be a non-empty subset of {TERMS}, got {terms!r}")
    cols = [TERMS.index(t) for t in terms]
    if len(ad.taus) < 3:
        raise CalibrationError(
            f"the Allan deviation has only {len(ad.taus)} averaging times: the log is too short "
            "for noise figures (record at least a few minutes at rest)"
        )
    if not np.isfinite(ad.adev).all():
        raise CalibrationError(
            "the Allan deviation overflows a double: readings this large are not a sensor's "
            "(a wrong column, unit or scale?)"
        )
    lo, hi = SAMPLE_RATE_HZ
    if not (lo <= ad.rate_hz <= hi and np.isfinite(_basis(ad.taus)).all()):
        raise CalibrationError(
            f"a sample rate of {ad.rate_hz:g} Hz puts the averaging times at {ad.taus[0]:.3g} .. "
            f"{ad.taus[-1]:.3g} s, beyond what the noise model can hold: give the rate in Hz "
            f"({opt('rate_hz')}: {lo:g} to {hi:g})"
        )
    try:
        axes = tuple(_fit_axis(ad, k, cols) for k in range(len(ad.axes)))
    except np.linalg.LinAlgError as exc:
        raise CalibrationError(f"the Allan deviation could not be fitted ({exc}): is the log at "
                               "rest and its rate right?") from None
    warnings = _warnings(ad, axes, sensor)
    return NoiseFigures(sensor=sensor, unit=ad.unit, rate_hz=ad.rate_hz,
                        duration_s=ad.duration_s, axes=axes, allan=ad,
                        warnings=tuple(warnings))


def _edf(n_samples: int, m: np.ndarray) -> np.ndarray:
    """Equivalent degrees of freedom of the overlapping Allan variance for each noise type of
    :data:`TERMS` (columns), by the simple fits of Howe, Allan and Barnes (1981) as tabulated
    in NIST SP 1065 (N phase points, cluster m): white PM, white FM, flicker FM, random-walk
    FM (also used for the ramp)."""
    n = float(n_samples + 1)
    m = m.astype(np.float64)
    with np.errstate(all="ignore"):
        white_pm = (n + 1) * (n - 2 * m) / (2 * (n - m))
        white_fm = (3 * (n - 1) / (2 * m) - 2 * (n - 2) / n) * 4 * m**2 / (4 * m**2 + 5)
        flicker_fm = np.where(m == 1, 2 * (n - 2) ** 2 / (2.3 * n - 4.9),
                              5 * n**2 / (4 * m * (n + 3 * m)))
        rw_fm = (n - 2) / m * ((n - 1) ** 2 - 3 * m * (n - 1) + 4 * m**2) / (n - 3) ** 2
    e = np.column_stack([white_pm, white_fm, flicker_fm, rw_fm, rw_fm])
    return np.maximum(np.nan_to_num(e, nan=1.0), 1.0)


def _fit_axis(ad: AllanDeviation, k: int, cols: list[int]) -> AxisNoise:
    tau = ad.taus
    y = ad.avar[:, k]
    edf_type = _edf(ad.n, ad.m)
    f = _basis(tau)
    if not (y > 0).all():
        raise CalibrationError(
            f"axis {ad.axes[k]} has a zero Allan deviation: the readings do not change (a "
            "stuck or saturated sensor?)"
        )
    # neighbouring overlapping estimates share data: count about one independent point per
    # two octaves of tau when turning the weighted fit's covariance into uncertainties (checked
    # against the spread over simulated logs: tests/test_noise.py)
    per_octave = 2.0 * len(tau) / max(math.log2(tau[-1] / tau[0]), 1.0)
    ref = y.copy()
    edf = edf_type[:, 1]
    c = np.zeros(len(TERMS))
    active: list[int] = []
    for _ in range(4):
        # the variance of an Allan variance is 2 var^2 / edf
        sw = np.sqrt(edf / 2.0) / ref
        c, active = _nnls(f * sw[:, None], y * sw, cols)
        model = f @ c
        ref = np.where(model > 0, model, y)
        # edf of the mixture: the noise types weighted by their share of the variance
        share = (f * c) / ref[:, None]
        edf = 1.0 / np.maximum(np.sum(share / edf_type, axis=1), 1e-12)
    # covariance of the active coefficients (weights are inverse variances)
    sw = np.sqrt(edf / 2.0) / ref
    a = f[:, active] * sw[:, None]
    try:
        cov = np.linalg.inv(a.T @ a) * max(per_octave, 1.0)
    except np.linalg.LinAlgError:
        cov = np.full((len(active), len(active)), np.inf)
    model = f @ c
    share = (f * c) / model[:, None]
    usable = edf >= MIN_EDF
    rel_adev = 1.0 / np.sqrt(2.0 * edf)
    rel_err: dict[str, float] = {}
    resolved: dict[str, bool] = {}
    upper: dict[str, float] = {}
    for j, name in enumerate(TERMS):
        if j in active:
            var_c = cov[active.index(j), active.index(j)]
            rel_err[name] = float(0.5 * math.sqrt(max(var_c, 0.0)) / c[j]) if c[j] > 0 else math.inf
        else:
            rel_err[name] = math.inf
        dominant = bool(((share[:, j] >= RESOLVED_SHARE) & usable).any())
        resolved[name] = bool(c[j] > 0 and dominant and rel_err[name] < RESOLVED_REL_ERR)
        bound = y * (1.0 + 2.0 * rel_adev) ** 2 / f[:, j]
        upper[name] = float(math.sqrt(np.min(bound[usable] if usable.any() else bound)))
    fine = np.logspace(math.log10(tau[0]), math.log10(tau[-1]), 400)
    fit_adev = np.sqrt(_basis(fine) @ c)
    # the lowest measured point among those with enough clusters (the last few are noisy)
    i_min = int(np.argmin(np.where(usable, ad.adev[:, k], np.inf))) if usable.any() else 0
    vals = np.sqrt(c)
    return AxisNoise(
        axis=ad.axes[k],
        quantization=float(vals[0]),
        white=float(vals[1]),
        bias_instability=float(vals[2]),
        random_walk=float(vals[3]),
        ramp=float(vals[4]),
        bias_tau_s=float(fine[int(np.argmin(fit_adev))]),
        adev_min=float(ad.adev[i_min, k]),
        adev_min_tau_s=float(tau[i_min]),
        rel_err=rel_err,
        resolved=resolved,
        upper=upper,
    )


_NAMES = {
    "gyro": {"white": "angle random walk", "bias_instability": "bias instability",
             "random_walk": "rate random walk"},
    "accel": {"white": "velocity random walk", "bias_instability": "bias instability",
              "random_walk": "acceleration random walk"},
    None: {"white": "white noise density", "bias_instability": "bias instability",
           "random_walk": "bias random walk"},
}


def _hours(seconds: float) -> str:
    if seconds >= 3600:
        return f"{seconds / 3600:.3g} h"
    if seconds >= 60:
        return f"{seconds / 60:.3g} min"
    return f"{seconds:.3g} s"


def _warnings(ad: AllanDeviation, axes: tuple[AxisNoise, ...], sensor: str | None) -> list[str]:
    names = _NAMES[sensor]
    out: list[str] = []
    dur = _hours(ad.duration_s)
    for term in ("white", "bias_instability", "random_walk"):
        bad = [a for a in axes if not a.resolved[term]]
        if not bad:
            continue
        which = ", ".join(a.axis for a in bad)
        bound = max(a.upper[term] for a in bad)
        if term == "white":
            out.append(
                f"{names[term]} is not resolved on axis {which}: the shortest averaging times "
                "do not fall as 1/sqrt(tau) (quantization, or the sensor's filter at this "
                f"rate?); take it as at most {bound:.3g} {_unit(ad.unit, term)}"
            )
        elif term == "bias_instability":
            out.append(
                f"{names[term]} is not resolved on axis {which}: the {dur} log shows no flat "
                f"floor of the Allan deviation; it is at most {bound:.3g} "
                f"{_unit(ad.unit, term)}; record a longer log at rest at a steady temperature"
            )
        else:
            out.append(
                f"the {dur} log is too short to measure {names[term]} on axis {which} (the "
                "Allan deviation does not yet rise as sqrt(tau) with enough clusters): it is "
                f"at most {bound:.3g} {_unit(ad.unit, term)}; record a log several times "
                "longer (hours at rest, steady temperature)"
            )
    return out


def _unit(u: str, term: str) -> str:
    return {
        "white": f"{u}/sqrt(Hz)",
        "bias_instability": u,
        "random_walk": f"{u}/sqrt(s)",
        "quantization": f"{u}*s",
        "ramp": f"{u}/s",
    }[term]


def _extra(u: str, term: str, v: float) -> str:
    """The conventional datasheet unit, where the unit allows it."""
    if u in UNITS and UNITS[u][0] == "gyro":
        d = v * unit_factor(u, "deg/s")
        return {"white": f"{d * 60:.3g} deg/sqrt(h)", "bias_instability": f"{d * 3600:.3g} deg/h",
                "random_walk": f"{d * 216000:.3g} deg/h/sqrt(h)"}.get(term, "")
    if u in UNITS and UNITS[u][0] == "accel":
        ms2 = v * unit_factor(u, "m/s^2")
        ug = ms2 / 9.80665e-6
        return {"white": f"{ug:.3g} ug/sqrt(Hz) = {ms2 * 60:.3g} m/s/sqrt(h)",
                "bias_instability": f"{ug:.3g} ug",
                "random_walk": f"{ug:.3g} ug/sqrt(s)"}.get(term, "")
    return ""


def _text(nf: NoiseFigures) -> str:
    u, f = nf.unit, nf.rate_hz
    names = _NAMES[nf.sensor]
    lines = [
        f"{nf.sensor or 'sensor'} noise figures: {nf.allan.n} samples at {f:g} Hz "
        f"({_hours(nf.duration_s)}), unit {u}"
        + ("  -- NOT AT REST: computed anyway, see warnings" if nf.motion else ""),
        f"  {'':28}{'continuous time':<58}discrete time (per sample at {f:g} Hz)",
    ]
    for a in nf.axes:
        lines.append(f"  axis {a.axis}")
        for term in ("white", "bias_instability", "random_walk"):
            v = a.value(term)
            mark = "" if a.resolved[term] else "  (not resolved: see warnings)"
            err = a.rel_err[term]
            pm = f" +-{100 * err:.2g}%" if math.isfinite(err) else ""
            ex = _extra(u, term, v)
            cont = f"{v:.4g} {_unit(u, term)}{pm}" + (f" ({ex})" if ex else "")
            if term == "white":
                disc = f"sigma {v * math.sqrt(f):.4g} {u}"
            elif term == "random_walk":
                disc = f"bias step sigma {v / math.sqrt(f):.4g} {u}"
            else:
                disc = (f"floor 0.664 B = {FLICKER_FLOOR * v:.4g} {u}, lowest at tau "
                        f"{a.bias_tau_s:.3g} s")
            lines.append(f"    {names[term]:<26}{cont:<58}{disc}{mark}")
        lines.append(f"    {'lowest Allan deviation':<26}{a.adev_min:.4g} {u} at tau "
                     f"{a.adev_min_tau_s:.3g} s; quantization {a.quantization:.3g} {u}*s, "
                     f"rate ramp {a.ramp:.3g} {u}/s")
    if nf.warnings:
        lines.append("  warnings")
        lines += [f"    - {w}" for w in nf.warnings]
    return "\n".join(lines)


# --------------------------------------------------------------------------------------------
# Kalibr


def kalibr_noise(
    gyro: NoiseFigures | None = None,
    accel: NoiseFigures | None = None,
    *,
    upper_if_unresolved: bool = True,
) -> dict[str, float]:
    """Kalibr's four IMU noise keys from gyroscope and / or accelerometer figures.

    ``gyroscope_noise_density`` rad/s/sqrt(Hz), ``gyroscope_random_walk`` rad/s^2/sqrt(Hz),
    ``accelerometer_noise_density`` m/s^2/sqrt(Hz), ``accelerometer_random_walk``
    m/s^3/sqrt(Hz): the continuous-time white density N and random walk K of the worst axis,
    converted to SI. Kalibr refuses values <= 0, so a random walk the log does not resolve is
    written as its upper bound (``upper_if_unresolved``) -- a conservative choice for a filter.

    Raises
    ------
    CalibrationError
        When the readings' unit cannot be converted (raw counts: calibrate them first, or pass
        the unit).
    """
    out: dict[str, float] = {}
    for prefix, nf, si in (("gyroscope", gyro, "rad/s"), ("accelerometer", accel, "m/s^2")):
        if nf is None:
            continue
        options.instance(nf, NoiseFigures, "gyro" if prefix == "gyroscope" else "accel",
                      "NoiseFigures (from noise_figures) or None")
        want = "gyro" if prefix == "gyroscope" else "accel"
        if nf.unit not in UNITS or UNITS[nf.unit][0] != want:
            raise CalibrationError(
                f"the {want} figures are in {nf.unit!r}, which cannot be converted to {si}: "
                f"give readings in {si} or a convertible unit (calibrate raw counts first, "
                "e.g. triaxcal noise --cal CAL.json, or pass --unit)"
            )
        k = unit_factor(nf.unit, si)
        for term, key in (("white", "noise_density"), ("random_walk", "random_walk")):
            vals = []
            for a in nf.axes:
                v = a.value(term)
                if upper_if_unresolved and (not a.resolved[term] or v <= 0):
                    v = max(v, a.upper[term])
                vals.append(v)
            v = max(vals) * k
            if not (v > 0 and math.isfinite(v)):
                raise CalibrationError(f"{prefix}_{key} came out {v}: Kalibr needs a value > 0")
            out[f"{prefix}_{key}"] = v
    if not out:
        raise CalibrationError("give gyroscope and / or accelerometer noise figures")
    return out


def _yaml_float(v: float) -> str:
    """A float as YAML 1.1 reads a float (``yaml.safe_load``, which Kalibr's config reader
    uses): with a decimal point and a signed exponent (``2.000000e-05``, never ``2e-05``, which
    it reads as a string).

    >>> _yaml_float(2e-05), _yaml_float(50.0), _yaml_float(204.8)
    ('2.000000e-05', '50.0', '204.8')
    """
    f = float(v)
    text = repr(f)
    if "e" in text or "E" in text or "." not in text:
        text = f"{f:.6e}"
    return text


def kalibr_yaml(
    gyro: NoiseFigures | None = None,
    accel: NoiseFigures | None = None,
    *,
    ros_topic: str = "/imu0",
    update_rate: float | None = None,
    rostopic: str | None = None,
) -> str:
    """The noise block of a Kalibr ``imu.yaml`` (with ``rostopic`` and ``update_rate``).

    Comments give the units and say which values are upper bounds, and that the figures are
    of readings that were not at rest when they are (:attr:`NoiseFigures.motion`). Every number
    is written so that ``yaml.safe_load`` reads a float. ``rostopic`` is the old name of
    ``ros_topic``.
    """
    if rostopic is not None:
        import warnings

        warnings.warn("kalibr_yaml(rostopic=) is now ros_topic=; the old name goes in the next "
                      "release", DeprecationWarning, stacklevel=2)
        ros_topic = rostopic
    keys = kalibr_noise(gyro, accel)
    rate = update_rate or (gyro or accel).rate_hz  # type: ignore[union-attr]
    if not (isinstance(ros_topic, str) and ros_topic.startswith("/")
            and all(ch.isalnum() or ch in "/_" for ch in ros_topic)):
        raise CalibrationError(f"{opt('ros_topic')} must look like /imu0 (letters, digits, _ "
                               f"and /), got {ros_topic!r}")
    units = {"gyroscope_noise_density": "rad/s/sqrt(Hz)",
             "gyroscope_random_walk": "rad/s^2/sqrt(Hz)",
             "accelerometer_noise_density": "m/s^2/sqrt(Hz)",
             "accelerometer_random_walk": "m/s^3/sqrt(Hz)"}
    lines = ["# IMU noise (continuous time, worst axis) measured by triaxcal from the Allan "
             "deviation"]
    for prefix, nf in (("accelerometer", accel), ("gyroscope", gyro)):
        if nf is None:
            lines.append(f"# {prefix}_noise_density, {prefix}_random_walk: not measured")
            continue
        if nf.motion:
            lines.append(f"# NOT AT REST: the {prefix} figures were computed from readings that "
                         "moved; they describe the motion as much as the sensor")
        for key in ("noise_density", "random_walk"):
            term = "white" if key == "noise_density" else "random_walk"
            note = "" if all(a.resolved[term] for a in nf.axes) else (
                "; an upper bound: the log does not resolve it")
            name = f"{prefix}_{key}"
            lines.append(f"{name}: {_yaml_float(keys[name])}  # {units[name]}{note}")
    lines.append(f"rostopic: {ros_topic}")
    lines.append(f"update_rate: {_yaml_float(rate)}  # Hz")
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------------------------
# Figure


def plot_allan(nf: NoiseFigures, path: str | Path, *, title: str | None = None,
               dpi: int = 90) -> Path:
    """Save the Allan deviation with the fitted model and its slopes as a PNG.

    One panel per axis (log-log): the measured deviation with its approximate 1-sigma band,
    the fitted sum, and the three slopes -1/2 (white: marked at tau = 1 s, the value N),
    0 (bias instability floor 0.664 B, marked at its tau) and +1/2 (random walk: marked at
    tau = 3 s, the value K).

    Raises
    ------
    CalibrationError
        If matplotlib (the ``plot`` extra) is not installed.
    """
    options.instance(nf, NoiseFigures, "nf", "NoiseFigures (from noise_figures)")
    options.path(path, "path")
    dpi = options.integer(dpi, "dpi", ge=20, le=600, hint="dots per inch of the PNG")
    if title is not None and not isinstance(title, str):
        raise CalibrationError(f"title must be text or None, got {title!r:.60}")
    if importlib.util.find_spec("matplotlib") is None:
        raise CalibrationError(
            "the Allan deviation figure needs matplotlib: pip install 'triaxcal[plot]'"
        )
    import matplotlib

    matplotlib.use("Agg", force=False)
    from matplotlib.figure import Figure

    ad = nf.allan
    u = nf.unit
    names = _NAMES[nf.sensor]
    nax = len(nf.axes)
    fig = Figure(figsize=(5.4 * nax, 6.2), dpi=dpi, layout="constrained")
    fig.suptitle(title or f"{nf.sensor or 'sensor'} Allan deviation: {ad.n} samples at "
                 f"{nf.rate_hz:g} Hz ({_hours(nf.duration_s)})", fontsize=12)
    tau = ad.taus
    fine = np.logspace(math.log10(tau[0]), math.log10(tau[-1]), 300)
    first = None
    for k, a in enumerate(nf.axes):
        ax = fig.add_subplot(1, nax, k + 1, sharey=first)
        first = first or ax
        y = ad.adev[:, k]
        err = ad.rel_error
        ax.fill_between(tau, y * (1 - err), y * (1 + err), color="#1f77b4", alpha=0.2, lw=0)
        ax.loglog(tau, y, "o", ms=3.5, color="#1f77b4", label="measured (overlapping)")
        ax.loglog(fine, a.model_adev(fine), "-", color="k", lw=1.4, label="fitted model")
        if a.white > 0:
            ax.loglog(fine, a.white / np.sqrt(fine), "--", color="#d62728", lw=1,
                      label=f"{names['white']}: N = {a.white:.3g} {u}/sqrt(Hz)")
            if fine[0] <= 1.0 <= fine[-1]:
                ax.plot([1.0], [a.white], "s", color="#d62728", ms=6)
        if a.bias_instability > 0:
            floor = FLICKER_FLOOR * a.bias_instability
            ax.loglog(fine, np.full_like(fine, floor), "--", color="#2ca02c", lw=1,
                      label=f"{names['bias_instability']}: B = {a.bias_instability:.3g} {u} "
                            f"(floor 0.664 B, lowest at {a.bias_tau_s:.3g} s)")
            ax.plot([a.bias_tau_s], [a.model_adev(a.bias_tau_s)[0]], "v", color="#2ca02c", ms=8)
        if a.random_walk > 0:
            ax.loglog(fine, a.random_walk * np.sqrt(fine / 3.0), "--", color="#9467bd", lw=1,
                      label=f"{names['random_walk']}: K = {a.random_walk:.3g} {u}/sqrt(s)")
            if fine[0] <= 3.0 <= fine[-1]:
                ax.plot([3.0], [a.random_walk], "D", color="#9467bd", ms=5)
        if a.quantization > 0:
            ax.loglog(fine, math.sqrt(3.0) * a.quantization / fine, ":", color="#8c564b", lw=1,
                      label=f"quantization: Q = {a.quantization:.3g} {u}*s")
        if a.ramp > 0:
            ax.loglog(fine, a.ramp * fine / math.sqrt(2.0), ":", color="#e377c2", lw=1,
                      label=f"rate ramp: R = {a.ramp:.3g} {u}/s")
        lo = np.nanmin(y) / 3
        hi = np.nanmax(y) * 3
        ax.set_ylim(lo, hi)
        ax.set_xlabel("averaging time tau (s)")
        ax.set_ylabel(f"Allan deviation ({u})")
        flags = [names[t] for t in ("white", "bias_instability", "random_walk")
                 if not a.resolved[t]]
        ax.set_title(f"axis {a.axis}" + (f" (not resolved: {', '.join(flags)})" if flags else ""),
                     fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7.5, loc="upper center", bbox_to_anchor=(0.5, -0.14), frameon=False)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    return write_file(path, buf.getvalue(), what="figure")  # atomic: no half-written figure
