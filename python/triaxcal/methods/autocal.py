"""Free-living auto-calibration of wearable accelerometers (van Hees et al. 2014).

A worn accelerometer is still for much of a week (sleep, sitting, off the wrist on a table);
when it is still it measures gravity alone, 1 g. The method (van Hees VT, Fang Z, Langford J
et al., "Autocalibration of accelerometer data for free-living physical activity assessment
using local gravity and temperature: an evaluation on four continents", J Appl Physiol
117:738-744, 2014; implemented in GGIR's ``g.calibrate`` and the OxWearables
``accelerometer`` package) finds the still periods and fits the correction that puts them on
the unit sphere:

1. cut the recording into non-overlapping ``window_s`` = 10 s windows; a window is *still*
   when the standard deviation of every axis is below ``sd_threshold_g`` = 13 mg (0.013 g)
   and no axis's mean exceeds ``max_abs_g`` = 2 g in size (GGIR's guard against clipping);
2. the sphere must be populated: at least one still window beyond -``sphere_crit_g`` and one
   beyond +``sphere_crit_g`` (0.3 g) on each axis, else nothing is fitted;
3. iterated closest point: with the current correction, project each still window's mean onto
   the unit sphere; for each axis fit the projected value by weighted least squares on the
   corrected value (and the window's temperature minus the mean temperature); fold the
   per-axis intercept, slope (and temperature slope) into the correction; new weights
   ``min(1 / distance to the sphere, 100)``; stop after ``max_iter`` = 1000 iterations or
   when converged (GGIR: the weighted mean squared residual divided by the sum of weights
   changes by less than ``tol`` = 1e-10 -- a rule that stops too early on long recordings,
   so by default here: no parameter moves by more than ``tol``; ``stop="ggir"`` restores
   GGIR's rule);
4. accept the correction when the calibration error (mean over still windows of
   ``| |a| - 1 |``, in g) fell, is below ``max_error_g`` = 10 mg, the sphere was populated,
   and the recording holds at least ``min_hours`` = 72 hours (GGIR's ``minloadcrit``).

Error model (GGIR's): ``a = (y + d) * s + (T - T0) * m`` per axis, ``y`` the reading in g,
``T`` the temperature in degC, ``T0`` the mean temperature of the still windows. In triaxcal's
convention (:class:`~triaxcal.SensorCalibration`) that is ``a = (y - offset(T)) * gain`` with
``offset = -d`` (g), ``gain = s`` (**multiplies**), ``offset(T) = offset + temp_coef * (T -
temp_ref_c)``, ``temp_coef = -m / s`` (g per degC) and ``temp_ref_c = T0``;
:attr:`AutoCalibration.ggir` gives GGIR's ``scale``, ``offset``, ``tempoffset``,
``meantemp`` back.

Streaming: the window statistics are computed chunk by chunk (vectorised numpy, a few hundred
MB/s), carrying the samples of an unfinished window over to the next chunk, so a recording of
any length is calibrated in memory bounded by the chunk size plus 7 numbers per 10 s window
(a week is 60,480 windows, 3.4 MB). Differences from GGIR: the whole recording is used
(GGIR stops loading 12-hour blocks once a block passes, after at least 72 hours), and the
temperature is used whenever it is given (GGIR drops it for some devices, or when the first
readings exceed 40 degC).
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from .._checks import options as opt
from .._checks.arrays import as_samples
from ..errors import CalibrationError
from ..quality.bounds import sample_rate

__all__ = [
    "AutoCalibration",
    "StillWindows",
    "WindowStats",
    "autocalibrate",
    "autocalibrate_source",
    "fit_still_windows",
]

#: Published defaults (van Hees et al. 2014; GGIR ``g.calibrate``).
WINDOW_S = 10.0
SD_THRESHOLD_G = 0.013
MAX_ABS_G = 2.0
SPHERE_CRIT_G = 0.3
MAX_ERROR_G = 0.01
MAX_ITER = 1000
TOL = 1e-10
MIN_HOURS = 72.0


def _ro(a: Any) -> np.ndarray:
    arr = np.array(a, dtype=np.float64)
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True)
class WindowStats:
    """Statistics of the still windows of a recording (from :class:`StillWindows`).

    ``means`` (M, 3) g and ``sds`` (M, 3) g of the still windows; ``temps`` (M,) degC or
    ``None``; ``n_windows`` windows seen in all (still or not); ``window_samples`` samples per
    window; ``rate_hz``; ``hours`` = ``n_windows * window_s / 3600``.
    """

    means: np.ndarray
    sds: np.ndarray
    temps: np.ndarray | None
    n_windows: int
    window_samples: int
    rate_hz: float
    window_s: float

    @property
    def hours(self) -> float:
        return self.n_windows * self.window_s / 3600.0


class StillWindows:
    """Streaming window statistics: feed chunks with :meth:`update`, then :meth:`result`.

    Parameters
    ----------
    rate_hz : float
        Samples per second.
    window_s : float
        Window length in seconds (windows hold ``round(window_s * rate_hz)`` samples).
    sd_threshold_g : float
        A window is still when every axis's standard deviation (ddof=1) is below this, in g.
    max_abs_g : float
        ... and no axis's mean is this large (g).

    Examples
    --------
    >>> import numpy as np
    >>> sw = StillWindows(10.0)
    >>> rng = np.random.default_rng(0)
    >>> for _ in range(3):  # 3 chunks of 25 s: 7 whole windows, the rest carried over
    ...     sw.update(rng.normal([0, 0, 1], 0.005, (250, 3)))
    >>> r = sw.result()
    >>> r.n_windows, r.means.shape
    (7, (7, 3))
    """

    def __init__(
        self,
        rate_hz: float,
        *,
        window_s: float = WINDOW_S,
        sd_threshold_g: float = SD_THRESHOLD_G,
        max_abs_g: float = MAX_ABS_G,
    ) -> None:
        self.rate_hz = sample_rate(rate_hz)
        self.window_s = opt.number(window_s, "window_s", gt=0, hint="seconds")
        sd_threshold_g = opt.magnitude(sd_threshold_g, "sd_threshold_g", hint="g")
        max_abs_g = opt.magnitude(max_abs_g, "max_abs_g", hint="g")
        self.wlen = opt.samples(self.window_s, self.rate_hz, "window_s")
        if self.wlen < 2:
            raise CalibrationError(
                f"a {window_s:g} s window at {rate_hz:g} Hz holds {self.wlen} sample(s): need "
                "at least 2")
        self.sd_threshold_g = float(sd_threshold_g)
        self.max_abs_g = float(max_abs_g)
        self._rest = np.zeros((0, 3))
        self._rest_t: np.ndarray | None = None
        self._temp: bool | None = None
        self._means: list[np.ndarray] = []
        self._sds: list[np.ndarray] = []
        self._temps: list[np.ndarray] = []
        self.n_windows = 0
        self.n_samples = 0

    def update(self, acc: Any, temp_c: Any = None) -> None:
        """Add the next ``(n, 3)`` samples in g (and their ``(n,)`` temperatures in degC)."""
        a = as_samples(acc, "acc", finite=False)  # a NaN sample leaves its window out
        if a.size and (np.isinf(a).any()
                       or np.nanmax(np.abs(a), initial=0.0) > opt.MAGNITUDE[1]):
            as_samples(a[~np.isnan(a).any(axis=1)], "acc")  # refused, naming the reading
        has_t = temp_c is not None
        if self._temp is None:
            self._temp = has_t
        elif self._temp != has_t:
            raise CalibrationError("give the temperature with every chunk or with none")
        t = None
        if has_t:
            t = _temperatures(temp_c)
            if len(t) != len(a):
                raise CalibrationError(
                    f"{len(t)} temperatures for {len(a)} samples: give one per sample")
        self.n_samples += len(a)
        if len(self._rest):
            a = np.concatenate([self._rest, a])
            if t is not None and self._rest_t is not None:
                t = np.concatenate([self._rest_t, t])
        nw = len(a) // self.wlen
        used = nw * self.wlen
        self._rest = a[used:].copy()
        self._rest_t = None if t is None else t[used:].copy()
        if nw == 0:
            return
        # axis-major copy: the window sums run along contiguous memory (3-4x faster)
        y = np.ascontiguousarray(a[:used].T).reshape(3, nw, self.wlen)
        s1 = y.sum(axis=2)
        ss = np.einsum("ijk,ijk->ij", y, y) - s1 * s1 / self.wlen  # squared deviations
        mean = (s1 / self.wlen).T
        sd = np.sqrt(np.maximum(ss, 0.0) / (self.wlen - 1)).T
        with np.errstate(invalid="ignore"):
            still = (np.all(sd < self.sd_threshold_g, axis=1)
                     & np.all(np.abs(mean) < self.max_abs_g, axis=1))
        if t is not None:
            tm = t[:used].reshape(nw, self.wlen).mean(axis=1)
            still &= np.isfinite(tm)
            self._temps.append(tm[still])
        self._means.append(mean[still])
        self._sds.append(sd[still])
        self.n_windows += nw

    def result(self) -> WindowStats:
        """The still windows so far (an unfinished last window is left out, as GGIR does)."""
        means = np.concatenate(self._means) if self._means else np.zeros((0, 3))
        sds = np.concatenate(self._sds) if self._sds else np.zeros((0, 3))
        temps = (np.concatenate(self._temps) if self._temps else np.zeros(0)) if (
            self._temp) else None
        return WindowStats(means=_ro(means), sds=_ro(sds),
                           temps=None if temps is None else _ro(temps),
                           n_windows=self.n_windows, window_samples=self.wlen,
                           rate_hz=self.rate_hz, window_s=self.window_s)


@dataclass(frozen=True)
class AutoCalibration:
    """The result of :func:`autocalibrate` (see the module notes for the model).

    Attributes
    ----------
    offset : ndarray (3,)
        Offset in g at ``temp_ref_c``, subtracted: ``a = (y - offset(T)) * gain``.
    gain : ndarray (3,)
        Per-axis gain, dimensionless, **multiplies**.
    temp_coef : ndarray (3,)
        Offset drift in g per degC (zeros without temperature).
    temp_ref_c : float or None
        Mean temperature (degC) of the still windows: where ``offset`` holds.
    accepted : bool
        The published acceptance rule held (error fell, below ``max_error_g``, sphere
        populated, at least ``min_hours``); use the correction only then.
    status : str
        What happened, in words (GGIR's QC message, or why not).
    error_before_g, error_after_g : float
        Calibration error, mean ``| |a| - 1 |`` over the still windows, before and after (g).
    n_windows, n_still : int
        Windows in the recording; still ones used.
    hours : float
        Length of the recording used, hours (whole windows).
    sphere_g : ndarray (3, 2)
        Lowest and highest still-window mean per axis (g), before correction.
    sphere_populated : bool
    iterations : int
    temp_range_c : tuple of float or None
        Lowest and highest still-window temperature.
    settings : dict
        The options used.
    """

    offset: np.ndarray
    gain: np.ndarray
    temp_coef: np.ndarray
    temp_ref_c: float | None
    accepted: bool
    status: str
    error_before_g: float
    error_after_g: float
    n_windows: int
    n_still: int
    hours: float
    sphere_g: np.ndarray
    sphere_populated: bool
    iterations: int
    temp_range_c: tuple[float, float] | None = None
    settings: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def failed(cls, status: str, **settings: Any) -> AutoCalibration:
        """A result for a recording that could not be processed at all."""
        nan = float("nan")
        return cls(offset=_ro(np.zeros(3)), gain=_ro(np.ones(3)), temp_coef=_ro(np.zeros(3)),
                   temp_ref_c=None, accepted=False, status=status, error_before_g=nan,
                   error_after_g=nan, n_windows=0, n_still=0, hours=0.0,
                   sphere_g=_ro(np.full((3, 2), nan)), sphere_populated=False, iterations=0,
                   settings=dict(settings))

    @property
    def ggir(self) -> dict[str, Any]:
        """The same correction in GGIR's terms: ``a = (y + offset) * scale + (T - meantemp) *
        tempoffset`` (``g.calibrate``'s ``scale``, ``offset``, ``tempoffset``, and
        ``meantempcal``)."""
        return {
            "scale": self.gain.copy(),
            "offset": -self.offset,
            "tempoffset": -self.temp_coef * self.gain,
            "meantemp": self.temp_ref_c,
        }

    def apply(self, acc: Any, temp_c: Any = None) -> np.ndarray:
        """Corrected acceleration ``(acc - offset(T)) * gain`` in g, shape (N, 3).

        ``temp_c`` (scalar or (N,), degC) is needed when the correction has temperature terms.
        """
        a = np.asarray(acc, dtype=np.float64)
        if a.ndim != 2 or a.shape[1] != 3:
            raise CalibrationError(f"acc must have shape (N, 3), got {a.shape}")
        off = np.broadcast_to(self.offset, a.shape)
        if self.temp_ref_c is not None and np.any(self.temp_coef != 0):
            if temp_c is None:
                raise CalibrationError(
                    "this correction has temperature terms: pass temp_c (degC), or "
                    f"temp_c={self.temp_ref_c} to leave the temperature out")
            t = np.broadcast_to(np.asarray(temp_c, dtype=np.float64).reshape(-1, 1),
                                (len(a), 1))
            off = off + (t - self.temp_ref_c) * self.temp_coef
        return (a - off) * self.gain

    def __repr__(self) -> str:
        off = ", ".join(f"{1000 * v:+.2f}" for v in self.offset)
        gain = ", ".join(f"{v:.5f}" for v in self.gain)
        return (f"AutoCalibration(accepted={self.accepted}, offset_mg=[{off}], gain=[{gain}], "
                f"error {1000 * self.error_before_g:.2f} -> {1000 * self.error_after_g:.2f} mg,"
                f" {self.n_still} still windows, {self.hours:.1f} h)")


def _error(means: np.ndarray) -> float:
    return float(np.mean(np.abs(np.linalg.norm(means, axis=1) - 1.0))) if len(means) else float(
        "nan")


def fit_still_windows(
    stats: WindowStats,
    *,
    use_temperature: bool = True,
    sphere_crit_g: float = SPHERE_CRIT_G,
    max_error_g: float = MAX_ERROR_G,
    max_iter: int = MAX_ITER,
    tol: float = TOL,
    min_hours: float = MIN_HOURS,
    stop: str = "parameters",
) -> AutoCalibration:
    """Fit the van Hees correction to the still windows of :class:`StillWindows`.

    See :func:`autocalibrate` for the options; this is its second half, for window statistics
    gathered elsewhere (e.g. merged from several files of one recording).
    """
    opt.choice(stop, "stop", ("parameters", "ggir"))
    use_temperature = opt.flag(use_temperature, "use_temperature")
    sphere_crit_g = opt.number(sphere_crit_g, "sphere_crit_g", ge=0, le=2, hint="g")
    max_error_g = opt.number(max_error_g, "max_error_g", gt=0, hint="g")
    max_iter = opt.integer(max_iter, "max_iter", ge=1, le=1_000_000)
    tol = opt.number(tol, "tol", gt=0)
    min_hours = opt.number(min_hours, "min_hours", ge=0, hint="hours")
    means = np.asarray(stats.means, dtype=np.float64)
    temps = stats.temps if (use_temperature and stats.temps is not None) else None
    settings = {"window_s": stats.window_s, "use_temperature": temps is not None,
                "sphere_crit_g": sphere_crit_g, "max_error_g": max_error_g,
                "max_iter": max_iter, "tol": tol, "min_hours": min_hours, "stop": stop}
    n = len(means)
    base: dict[str, Any] = dict(n_windows=stats.n_windows, n_still=n, hours=stats.hours,
                                settings=settings)
    if n < 2:
        r = AutoCalibration.failed(
            f"recalibration not done: {n} still {stats.window_s:g} s window(s) in "
            f"{stats.hours:.2f} h (need days of wear with periods of rest)", **settings)
        return replace(r, **base)
    before = _error(means)
    lo, hi = means.min(axis=0), means.max(axis=0)
    sphere = _ro(np.column_stack([lo, hi]))
    populated = bool(np.all(lo < -sphere_crit_g) and np.all(hi > sphere_crit_g))
    if not populated:
        short = [a for a, lo_a, hi_a in zip("xyz", lo, hi)
                 if not (lo_a < -sphere_crit_g and hi_a > sphere_crit_g)]
        return AutoCalibration(
            offset=_ro(np.zeros(3)), gain=_ro(np.ones(3)), temp_coef=_ro(np.zeros(3)),
            temp_ref_c=None, accepted=False,
            status=("recalibration not done because not enough points on all sides of the "
                    f"sphere: axis {', '.join(short)} has no still window beyond "
                    f"+-{sphere_crit_g:g} g"),
            error_before_g=before, error_after_g=before, sphere_g=sphere,
            sphere_populated=False, iterations=0, **base)

    if temps is not None:
        t0 = float(np.mean(temps))
        dt = np.asarray(temps, dtype=np.float64) - t0
    else:
        t0, dt = None, np.zeros(n)
    offset = np.zeros(3)  # GGIR's d: a = (y + d) * s + dt * m
    scale = np.ones(3)
    tempoffset = np.zeros(3)
    weights = np.ones(n)
    res_prev = math.inf
    it = 0
    for it in range(1, int(max_iter) + 1):  # noqa: B007 - the count is reported
        curr = (means + offset) * scale + dt[:, None] * tempoffset
        closest = curr / np.linalg.norm(curr, axis=1, keepdims=True)
        offsetch, scalech, toffch = np.zeros(3), np.ones(3), np.zeros(3)
        for k in range(3):
            cols = [np.ones(n), curr[:, k]] + ([dt] if temps is not None else [])
            x = np.column_stack(cols)
            xw = x * weights[:, None]
            coef = np.linalg.solve(xw.T @ x, xw.T @ closest[:, k])
            offsetch[k], scalech[k] = coef[0], coef[1]
            if temps is not None:
                toffch[k] = coef[2]
            curr[:, k] = x @ coef
        offset = offset + offsetch / (scale * scalech)
        if temps is not None:
            tempoffset = tempoffset * scalech + toffch
        step = max(float(np.max(np.abs(offsetch / (scale * scalech)))),
                   float(np.max(np.abs(scalech - 1.0))),
                   10.0 * float(np.max(np.abs(tempoffset * (scalech - 1.0) + toffch))))
        scale = scale * scalech
        diff = curr - closest
        res = 3.0 * float(np.mean(weights[:, None] * diff**2 / weights.sum()))
        weights = np.minimum(1.0 / np.maximum(np.linalg.norm(diff, axis=1), 1e-300), 100.0)
        if (abs(res - res_prev) < tol) if stop == "ggir" else (step < tol):
            break
        res_prev = res
    after_pts = (means + offset) * scale + dt[:, None] * tempoffset
    after = _error(after_pts)
    reasons = []
    if not after < before:
        reasons.append(f"the error did not fall ({1000 * before:.2f} -> {1000 * after:.2f} mg)")
    if not after < max_error_g:
        reasons.append(f"the error after, {1000 * after:.2f} mg, is not below "
                       f"{1000 * max_error_g:g} mg")
    if stats.hours < min_hours:
        reasons.append(f"{stats.hours:.1f} h of data, fewer than {min_hours:g} h")
    accepted = not reasons
    status = "recalibration done, no problems detected" if accepted else (
        "recalibration not accepted: " + "; ".join(reasons))
    trange = None if temps is None else (float(np.min(temps)), float(np.max(temps)))
    return AutoCalibration(
        offset=_ro(-offset), gain=_ro(scale),
        temp_coef=_ro(-tempoffset / scale), temp_ref_c=t0, accepted=accepted, status=status,
        error_before_g=before, error_after_g=after, sphere_g=sphere, sphere_populated=True,
        iterations=it, temp_range_c=trange, **base)


def _temperatures(temp_c: Any) -> np.ndarray:
    """One temperature (degC) per sample, as float64 (NaN allowed: its window is left out)."""
    try:
        t = np.asarray(temp_c)
    except (TypeError, ValueError):
        t = np.zeros(0, dtype=object)
    if t.dtype.kind not in "iuf" or t.ndim > 2:
        raise CalibrationError(
            f"temp_c must hold one temperature (degC) per sample as real numbers, got "
            f"{str(temp_c)[:60]!r}")
    return t.astype(np.float64).reshape(-1)


def _chunks(acc: Any, temp_c: Any, step: int) -> Iterator[tuple[Any, Any]]:
    """(acc chunk, temp chunk) pairs from arrays (sliced) or from an iterable of chunks."""
    if isinstance(acc, (str, bytes, os.PathLike, Mapping)):
        raise CalibrationError(
            f"acc must be the readings, an (N, 3) array in g or an iterable of chunks, got "
            f"{type(acc).__name__} {str(acc)[:60]!r}: read a file first (read_wearable, "
            "read_table), or give a file to triaxcal.dask.autocalibrate_many")
    if isinstance(acc, list):  # rows, or a list of chunks
        try:
            arr = np.asarray(acc, dtype=np.float64)
        except (ValueError, TypeError):
            arr = None
        if arr is not None and arr.ndim == 2:
            acc = arr
    if temp_c is not None and (not hasattr(temp_c, "__getitem__") or not hasattr(temp_c, "__len__")
                               or isinstance(temp_c, (str, bytes, Mapping))):
        raise CalibrationError("temp_c must be an array of one temperature (degC) per sample")
    if hasattr(acc, "shape") and hasattr(acc, "__getitem__"):
        shape = tuple(acc.shape)
        if len(shape) != 2 or shape[1] != 3:
            raise CalibrationError(f"acc must have shape (N, 3) in g, got {shape}")
        if temp_c is not None and len(temp_c) != shape[0]:
            raise CalibrationError(
                f"{len(temp_c)} temperatures for {shape[0]} samples: give one per sample")
        for i in range(0, shape[0], step):
            yield acc[i:i + step], None if temp_c is None else temp_c[i:i + step]
        return
    if temp_c is not None:
        raise CalibrationError(
            "with acc given as chunks, give each chunk's temperature in the chunk: "
            "(acc_chunk, temp_chunk) pairs")
    if not isinstance(acc, Iterable):
        raise CalibrationError(
            f"acc must be an (N, 3) array or an iterable of chunks, got {type(acc).__name__}")
    for item in acc:
        if isinstance(item, tuple) and len(item) == 2:
            yield item[0], item[1]
        else:
            yield item, None


def autocalibrate(
    acc: Any,
    rate_hz: float,
    temp_c: Any = None,
    *,
    window_s: float = WINDOW_S,
    sd_threshold_g: float = SD_THRESHOLD_G,
    max_abs_g: float = MAX_ABS_G,
    sphere_crit_g: float = SPHERE_CRIT_G,
    max_error_g: float = MAX_ERROR_G,
    max_iter: int = MAX_ITER,
    tol: float = TOL,
    min_hours: float = MIN_HOURS,
    stop: str = "parameters",
    use_temperature: bool = True,
    chunk_s: float = 3600.0,
    progress: TextIO | None = None,
) -> AutoCalibration:
    """Auto-calibrate a free-living accelerometer recording (van Hees et al. 2014).

    Parameters
    ----------
    acc : array_like (N, 3) in g, or an iterable of chunks
        The recording: a numpy array, ``np.memmap``, HDF5 / zarr dataset or dask array
        (sliced ``chunk_s`` at a time, so it need not fit in memory), or an iterable yielding
        ``(n, 3)`` chunks or ``(acc_chunk, temp_chunk)`` pairs in time order.
    rate_hz : float
        Samples per second.
    temp_c : array_like (N,), optional
        Sensor temperature in degC, one per sample (with array ``acc``); fits the linear
        temperature terms.
    window_s, sd_threshold_g, max_abs_g
        Still windows: ``window_s`` = 10 s, every axis's standard deviation below
        ``sd_threshold_g`` = 0.013 g, every axis's mean below ``max_abs_g`` = 2 g in size.
    sphere_crit_g : float
        Needs a still window below ``-sphere_crit_g`` and one above ``+sphere_crit_g`` on
        each axis (0.3 g).
    max_error_g : float
        Accept only if the calibration error after is below this (0.01 g).
    max_iter, tol, stop
        The closest-point fit runs at most ``max_iter`` = 1000 iterations. ``stop =
        "parameters"`` (default) ends it when no parameter moves by more than ``tol`` = 1e-10
        in an iteration (offsets in g, gains relative, temperature terms per 10 degC);
        ``stop="ggir"`` uses the published rule instead, a change below ``tol`` of
        ``3 * mean(w * d**2) / sum(w)`` -- which divides by the number of windows twice, so on
        days of data it stops while the offsets still move by milligrams (2.4 mg on one
        simulated day, see the README); use it only to reproduce GGIR.
    min_hours : float
        Accept only with at least this many hours (72, GGIR's ``minloadcrit``).
    use_temperature : bool
        Fit the temperature terms when ``temp_c`` is given.
    chunk_s : float
        Seconds per chunk when slicing an array (default 3600: 1 h, 8.6 MB at 100 Hz).
    progress : text stream, optional
        Prints the hours processed.

    Returns
    -------
    AutoCalibration
        ``accepted`` says whether to use it; ``apply(acc, temp_c)`` corrects readings.

    Examples
    --------
    >>> import numpy as np, triaxcal as tc
    >>> rng = np.random.default_rng(1)
    >>> u = rng.normal(size=(400, 3)); u /= np.linalg.norm(u, axis=1, keepdims=True)
    >>> still = np.repeat(u, 100, axis=0)              # 400 still 10 s windows at 10 Hz
    >>> raw = still / [1.02, 0.99, 1.01] + [0.03, -0.02, 0.01]
    >>> raw += rng.normal(0, 0.003, raw.shape)
    >>> cal = tc.autocalibrate(raw, 10.0, min_hours=0)
    >>> cal.accepted, np.round(cal.offset, 3).tolist(), np.round(cal.gain, 3).tolist()
    (True, [0.03, -0.02, 0.01], [1.02, 0.99, 1.01])
    """
    sw = StillWindows(rate_hz, window_s=window_s, sd_threshold_g=sd_threshold_g,
                      max_abs_g=max_abs_g)
    chunk_s = opt.number(chunk_s, "chunk_s", gt=0, hint="seconds")
    opt.text_stream(progress, "progress")
    step = max(1, round(opt.samples(chunk_s, sw.rate_hz, "chunk_s") / sw.wlen)) * sw.wlen
    last = 0.0
    for a, t in _chunks(acc, temp_c, step):
        sw.update(a, t)
        if progress is not None:
            h = sw.n_samples / sw.rate_hz / 3600.0
            if h - last >= 6.0:
                progress.write(f"\rautocalibrate: {h:.0f} h read, {sum(map(len, sw._means))} "
                               "still windows")
                progress.flush()
                last = h
    if progress is not None:
        progress.write("\n")
    if sw.n_samples == 0:
        raise CalibrationError("the recording is empty")
    return fit_still_windows(sw.result(), use_temperature=use_temperature,
                             sphere_crit_g=sphere_crit_g, max_error_g=max_error_g,
                             max_iter=max_iter, tol=tol, min_hours=min_hours, stop=stop)


def autocalibrate_source(source: Any, rate_hz: float | None, options: dict[str, Any]
                         ) -> AutoCalibration:
    """One recording for :func:`triaxcal.dask.autocalibrate_many`: a file path (read with
    :func:`triaxcal.io.wearables.read_wearable`), an ``(N, 3)`` array, or ``(acc, temp)``.
    A recording that cannot be read gives ``AutoCalibration.failed(reason)``."""
    try:
        if isinstance(source, (str, Path)):
            from ..io.wearables import read_wearable

            rec = read_wearable(source)
            return autocalibrate(rec.acc_g, rec.rate_hz, rec.temp_c, **options)
        if rate_hz is None:
            raise CalibrationError("rate_hz is needed for a recording given as an array")
        if isinstance(source, tuple) and len(source) == 2:
            return autocalibrate(source[0], rate_hz, source[1], **options)
        return autocalibrate(source, rate_hz, **options)
    except CalibrationError as exc:
        return AutoCalibration.failed(f"recalibration not done: {exc}")
