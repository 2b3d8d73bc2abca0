"""Gyroscope calibration: bias at rest, gain by integrating known rotations (turntable fits:
:mod:`triaxcal.methods.turntable`).

Error model (per axis, as the turn-integration method writes it): a raw reading ``w`` (counts)
of a true rate ``r`` (deg/s) is ``w = offset + gain * r``; ``gain`` is in **counts per deg/s**
and **divides**: ``r = (w - offset) / gain``. Its inverse, ``scale = 1 / gain`` in **deg/s per
count**, multiplies. (Readers of the turn-integration method mixed the two up: MPU-6050 at +-2000
deg/s has a
gain of 16.4 counts per deg/s, i.e. a scale of 0.061 deg/s per count.) The full 3x3 model,
``rate = (w - offset) @ matrix.T`` with ``matrix`` in rad/s per count, is fitted by
:func:`triaxcal.calibrate_imu` (rotations between still poses) and
:func:`~triaxcal.methods.turntable.fit_turntable`
(constant-rate plateaus of known magnitude).

Rotation sense: a rotation with a positive integral about +axis is counterclockwise seen from
the tip of that axis (right-hand rule), ``"ccw"``; a negative one is clockwise, ``"cw"``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._checks import options as opt
from .._checks.arrays import as_samples
from .._checks.spelling import opt as flag
from ..detect import Rejection, detect_still
from ..errors import CalibrationError
from ..quality.bounds import GYRO_SATURATION_COUNTS
from ..quality.bounds import sample_rate as check_rate
from .turntable import TurntableFit, _as_rate, _ro, fit_turntable, turntable_plateaus

__all__ = [
    "GyroBias",
    "GyroGains",
    "Rotation",
    "TurntableFit",
    "find_rotations",
    "fit_turntable",
    "gain_warnings",
    "gyro_bias",
    "gyro_gains",
    "integrate_rate",
    "sample_rate",
    "turntable_plateaus",
]

AXES = "xyz"
TOO_SMALL = "rotation too small"
TOO_LARGE = "rotation too large"
NOT_ONE_AXIS = "not about one axis"


def _times(n: int, t: Any, rate_hz: float | None) -> np.ndarray:
    if t is not None:
        return _as_times(t, n)
    if rate_hz is None:
        raise CalibrationError("give the sample time stamps t (s) or the sampling rate rate_hz")
    rate = check_rate(rate_hz)
    return np.arange(n) / rate


def _as_times(t: Any, n: int) -> np.ndarray:
    arr = np.asarray(t) if not isinstance(t, (str, bytes)) else np.asarray([t])
    if arr.dtype.kind not in "iuf":
        raise CalibrationError(f"t must hold real numbers (seconds), got dtype {arr.dtype}")
    tt = arr.astype(np.float64).reshape(-1)
    if tt.shape[0] != n:
        raise CalibrationError(f"t has {tt.shape[0]} time stamps for {n} samples")
    if not np.isfinite(tt).all() or np.any(np.diff(tt) <= 0):
        raise CalibrationError("t must be finite and strictly increasing (seconds)")
    return tt


def _mean_rate(tt: np.ndarray) -> float:
    """Samples per second over the whole recording.

    Not ``1 / median(diff(t))``: a logger that stamps samples when it reads them from the
    sensor's FIFO gives bursts of close stamps (sunsided's MPU-6050 files: median step 2 ms at
    a true 100 Hz), and the median step would make a detector window five times too short.
    """
    return (tt.shape[0] - 1) / float(tt[-1] - tt[0])


def sample_rate(t: Any = None, rate_hz: float | None = None) -> float:
    """The sampling rate, Hz: ``rate_hz`` when given, else the samples per second of the time
    stamps ``t`` over the whole recording (see :func:`find_rotations` on loggers that stamp in
    bursts).

    >>> sample_rate([0.0, 0.01, 0.02, 0.04]), sample_rate(rate_hz=200)
    (75.0, 200.0)
    """
    if rate_hz is not None:
        return check_rate(rate_hz)
    if t is None:
        raise CalibrationError("the recording has no time stamps (a t column): give its "
                               f"sampling rate ({flag('rate_hz')}, Hz)")
    arr = np.asarray(t) if not isinstance(t, (str, bytes)) else np.asarray([t])
    if arr.dtype.kind not in "iuf":
        raise CalibrationError(f"t must hold real numbers (seconds), got dtype {arr.dtype}")
    tt = arr.astype(np.float64).reshape(-1)
    span = float(tt[-1] - tt[0]) if tt.shape[0] > 1 else 0.0
    if not (math.isfinite(span) and span > 0):
        raise CalibrationError("the time stamps do not advance: give the sampling rate "
                               f"({flag('rate_hz')}, Hz)")
    return check_rate((tt.shape[0] - 1) / span, "the sample rate of the time stamps t")


def integrate_rate(rate: Any, t: Any) -> np.ndarray:
    """Cumulative trapezoid integral of ``rate`` (N, 3) over time stamps ``t`` (N,).

    Returns an (N, 3) array starting at zero, in rate units times seconds (counts * s for raw
    readings, deg for deg/s). ``out[b] - out[a]`` is the integral from sample a to sample b.

    Examples
    --------
    >>> import numpy as np
    >>> t = np.linspace(0.0, 1.0, 101)
    >>> rate = np.column_stack([np.full(101, 90.0), np.zeros(101), 180 * t])  # deg/s
    >>> integrate_rate(rate, t)[-1].round(6).tolist()
    [90.0, 0.0, 90.0]
    """
    r = as_samples(rate, "rate", finite=True)
    tt = _as_times(t, r.shape[0])
    out = np.zeros_like(r)
    out[1:] = np.cumsum(0.5 * (r[1:] + r[:-1]) * np.diff(tt)[:, None], axis=0)
    return out


@dataclass(frozen=True)
class GyroBias:
    """Gyro bias from still periods: ``offset`` (3,) and ``std`` (3,) in the input's units
    (counts, or deg/s), over ``n`` samples of ``intervals``."""

    offset: np.ndarray
    std: np.ndarray
    n: int
    intervals: tuple[tuple[int, int], ...]


def gyro_bias(
    gyro: Any,
    *,
    intervals: Sequence[tuple[int, int]] | None = None,
    rate_hz: float | None = None,
    rest_s: float = 3.0,
) -> GyroBias:
    """Gyro offset (bias) as the mean reading while the sensor is still.

    Parameters
    ----------
    gyro : array_like, shape (N, 3)
        Raw gyro readings (counts, or deg/s, rad/s).
    intervals : sequence of (start, end), optional
        Still intervals (sample indices, ``0 <= start < end <= N``, end exclusive; intervals
        outside the recording are refused, not clipped). ``None``: with ``rate_hz`` given,
        they are found by :func:`triaxcal.detect_still` (the first ``rest_s`` seconds must be
        still); without it, the whole recording is taken as still.
    rate_hz : float, optional
        Sampling rate, Hz, for the detection.
    rest_s : float
        Initial rest, s, that teaches the detector the noise floor.

    Returns
    -------
    GyroBias
    """
    g = _as_rate(gyro)
    rest = opt.number(rest_s, "rest_s", gt=0, hint="seconds of initial rest")
    if intervals is None:
        if rate_hz is None:
            iv = [(0, g.shape[0])]
        else:
            rate = check_rate(rate_hz)
            iv = detect_still(
                g, rate_hz=rate, rest_s=rest, window_s=min(1.0, rest)
            ).intervals
    else:
        iv = opt.intervals(intervals, "intervals", g.shape[0])
    if not iv:
        raise CalibrationError(
            "no still period in the gyro recording: leave the sensor at rest for a few seconds "
            "(at the start, to teach the detector its noise) and record again"
        )
    rows = np.concatenate([g[a:b] for a, b in iv])
    return GyroBias(_ro(rows.mean(axis=0)), _ro(rows.std(axis=0)), int(rows.shape[0]), tuple(iv))


@dataclass(frozen=True)
class Rotation:
    """One rotation between two still periods.

    Attributes
    ----------
    start, end : int
        Samples integrated (``end`` exclusive): from the last still sample before the motion to
        the first still sample after it.
    integral : ndarray, shape (3,)
        Integral of ``gyro - offset`` over the rotation, in raw units times seconds (counts*s;
        degrees when the gyro is in deg/s).
    axis : int
        Index (0, 1, 2 = x, y, z) of the dominant component.
    direction : str
        ``"ccw"`` (positive integral about +axis, right-hand rule) or ``"cw"``.
    purity : float
        ``|integral[axis]| / |integral|``: 1 for a rotation about one sensor axis.
    """

    start: int
    end: int
    integral: np.ndarray
    axis: int
    direction: str
    purity: float

    @property
    def label(self) -> str:
        """``"x ccw"``, ``"z cw"``, ..."""
        return f"{AXES[self.axis]} {self.direction}"


def _turn(cum: np.ndarray, a: int, b: int) -> Rotation:
    """The rotation integrated over samples a..b-1 (``cum`` from :func:`integrate_rate`)."""
    integ = cum[b - 1] - cum[a]
    ax = int(np.argmax(np.abs(integ)))
    norm = float(np.linalg.norm(integ))
    purity = abs(float(integ[ax])) / norm if norm > 0 else 0.0
    return Rotation(a, b, _ro(integ), ax, "ccw" if integ[ax] > 0 else "cw", purity)


WHOLE = "whole"


def _still_periods(g: np.ndarray, tt: np.ndarray, intervals: Any, rest_s: float,
                   window_s: float, k: float, min_still_s: float) -> list[tuple[int, int]]:
    if intervals is not None:
        return opt.intervals(intervals, "intervals", g.shape[0])
    return detect_still(g, rate_hz=_mean_rate(tt), window_s=window_s, rest_s=rest_s, k=k,
                        min_duration_s=min_still_s).intervals


def find_rotations(
    gyro: Any,
    *,
    t: Any = None,
    rate_hz: float | None = None,
    offset: Any = None,
    intervals: Sequence[tuple[int, int]] | None = None,
    turns: Sequence[tuple[int, int]] | str | None = None,
    rest_s: float = 3.0,
    window_s: float = 0.5,
    k: float = 4.0,
    min_still_s: float = 0.5,
) -> list[Rotation]:
    """Find the rotations between still periods and integrate each one.

    Still periods come from ``intervals`` or from the variance detector run on the gyro itself
    (the first ``rest_s`` seconds must be still). Every gap between two still periods is a
    rotation; ``gyro - offset`` is integrated over it with the trapezoid rule on the time
    stamps ``t`` (or a uniform ``rate_hz``).

    Parameters
    ----------
    gyro : array_like, shape (N, 3)
        Raw gyro readings.
    t, rate_hz
        Time stamps (s, strictly increasing), or a uniform sampling rate (Hz).
    offset : array_like (3,), optional
        Bias in the gyro's units; ``None``: the mean over the still periods.
    intervals : sequence of (start, end), optional
        Still periods (sample indices, end exclusive); ``None``: detected.
    turns : None, "whole" or sequence of (start, end)
        ``None``: every gap between two still periods is a rotation. ``"whole"``: one rotation
        from the end of the first still period to the start of the last one (a rest at the
        start and at the end, the turns in between without pauses: any slow-down in the
        middle is part of the turn); with ``offset`` given and no ``intervals``, the whole
        recording from its first to its last sample (turns that start and end in motion, the
        bias from a recording at rest; a rest at either end adds only its noise, the offset
        being removed). A sequence: these sample intervals (end exclusive) are the rotations,
        whatever the detector says; give ``offset`` (from a recording at rest,
        :func:`gyro_bias`) if the recording has no still period of its own.
    rest_s, window_s, k, min_still_s
        Options of the still detector (:func:`triaxcal.detect_still`), seconds.

    Returns
    -------
    list of Rotation
    """
    g = _as_rate(gyro)
    tt = _times(g.shape[0], t, rate_hz)
    rest = opt.number(rest_s, "rest_s", gt=0, hint="seconds of initial rest")
    win = opt.number(window_s, "window_s", gt=0, hint="seconds")
    kk = opt.number(k, "k", gt=0, hint="threshold multiplier of the still detector")
    min_still = opt.number(min_still_s, "min_still_s", ge=0, hint="seconds")
    off = None if offset is None else opt.vector3(offset, "offset", hint="gyro bias")
    explicit = None
    if turns is not None and not (isinstance(turns, str) and turns == WHOLE):
        if isinstance(turns, str):
            raise CalibrationError(
                f"turns must be None, {WHOLE!r} or a sequence of (start, end) sample intervals, "
                f"got {turns!r}"
            )
        explicit = opt.intervals(turns, "turns", g.shape[0])
        if not explicit:
            raise CalibrationError("turns is empty: give at least one (start, end) interval")
    if explicit is None and turns == WHOLE and off is not None and intervals is None:
        # the bias is known: the whole recording is the turn (no rest needed at either end)
        explicit = [(0, g.shape[0])]
    if explicit is not None:
        if off is None:
            iv = _still_periods(g, tt, intervals, rest, win, kk, min_still)
            if not iv:
                raise CalibrationError(
                    f"no still period to take the gyro offset from: give it ({flag('offset')}: "
                    "the mean of a recording at rest, triaxcal.gyro_bias)"
                )
            off = gyro_bias(g, intervals=iv).offset
        cum = integrate_rate(g - off, tt)
        return [_turn(cum, a, b) for a, b in explicit if b - a >= 2]
    iv = _still_periods(g, tt, intervals, rest, win, kk, min_still)
    if len(iv) < 2:
        raise CalibrationError(
            f"found {len(iv)} still period(s); rotations are measured between two still periods: "
            "hold the sensor still before and after every rotation (for a recording that turns "
            f"without pausing, pass {flag('turns', WHOLE)} and the bias from a recording at "
            f"rest, {flag('offset')})"
        )
    if off is None:
        off = gyro_bias(g, intervals=iv).offset
    cum = integrate_rate(g - off, tt)
    if turns == WHOLE:
        a, b = max(iv[0][1] - 1, 0), min(iv[-1][0] + 1, g.shape[0])
        return [_turn(cum, a, b)] if b - a >= 2 else []
    out = []
    for (_, e0), (s1, _) in zip(iv[:-1], iv[1:]):
        a, b = max(e0 - 1, 0), min(s1 + 1, g.shape[0])
        if b - a < 2:
            continue
        out.append(_turn(cum, a, b))
    return out


@dataclass(frozen=True)
class GyroGains:
    """Per-axis gyro gains from integrated rotations of a known angle.

    Gains are in **counts per deg/s** and divide: ``rate_dps = (raw - offset) / gain``. The
    ``*_dps_per_count`` fields are the inverses and multiply. Counts means the raw input
    units (if the gyro was already in deg/s, a perfect gain is 1).

    Attributes
    ----------
    offset : ndarray (3,)
        Bias, raw units.
    gain_ccw_counts_per_dps, gain_cw_counts_per_dps : ndarray (3,)
        Mean gain of the counterclockwise / clockwise rotations about each axis (NaN where no
        such rotation was found).
    gain_counts_per_dps : ndarray (3,)
        Mean of the two directions (or the one available).
    scale_dps_per_count : ndarray (3,)
        ``1 / gain_counts_per_dps``.
    asymmetry : ndarray (3,)
        ``(ccw - cw) / mean`` gain, a check on the rotations (NaN if one direction is missing).
    rotations : tuple of Rotation
        Rotations used.
    rejected : tuple of Rejection
        Rotations not used, with the reason (too small, not about one axis).
    missing : tuple of str
        Directions with no rotation, e.g. ``("y cw",)``.
    angle_deg : float
        The known angle of each rotation.
    """

    offset: np.ndarray
    gain_ccw_counts_per_dps: np.ndarray
    gain_cw_counts_per_dps: np.ndarray
    gain_counts_per_dps: np.ndarray
    scale_dps_per_count: np.ndarray
    asymmetry: np.ndarray
    rotations: tuple[Rotation, ...]
    rejected: tuple[Rejection, ...]
    missing: tuple[str, ...]
    angle_deg: float

    def apply(self, raw: Any) -> np.ndarray:
        """Calibrated rates in deg/s: ``(raw - offset) / gain``."""
        return (np.asarray(raw, dtype=np.float64) - self.offset) / self.gain_counts_per_dps


def gyro_gains(
    gyro: Any,
    *,
    angle_deg: float = 90.0,
    t: Any = None,
    rate_hz: float | None = None,
    offset: Any = None,
    intervals: Sequence[tuple[int, int]] | None = None,
    turns: Sequence[tuple[int, int]] | str | None = None,
    rest_s: float = 3.0,
    min_fraction: float = 0.75,
    max_fraction: float = 1.25,
    min_purity: float = 0.9,
    require_both_directions: bool = False,
    nominal_counts_per_dps: float | None = None,
    axes: str = "xyz",
) -> GyroGains:
    """Gyro gain per axis and direction by integrating rotations of a known angle.

    Turn the sensor by ``angle_deg`` (90 on a cube; 360 or more is better) about each of its
    axes, both ways, holding it still before and after each turn. Each rotation is found
    between still periods, integrated with the trapezoid rule over the time stamps, assigned to
    its dominant axis and direction, and gives ``gain = |integral| / angle_deg``.

    Parameters
    ----------
    gyro : array_like, shape (N, 3)
        Raw gyro readings (counts).
    angle_deg : float
        The known angle of every rotation, degrees.
    t, rate_hz
        Time stamps (s), or a uniform sampling rate (Hz).
    offset : array_like (3,), optional
        Bias in counts; ``None``: the mean over the still periods.
    intervals : sequence of (start, end), optional
        Still periods; ``None``: detected from the gyro (the first ``rest_s`` s must be still).
    turns : None, "whole" or sequence of (start, end)
        Which samples are the rotations (see :func:`find_rotations`): ``None``, each gap
        between still periods; ``"whole"``, everything between a rest at the start and a rest
        at the end (continuous turns, e.g. two 360 deg turns in a row with
        ``angle_deg=720``), or with ``offset`` given the whole recording (turns that never
        rest, the bias from a recording at rest); or explicit sample intervals, each one turn
        of ``angle_deg`` (with ``offset`` from a recording at rest when this one never rests).
    rest_s : float
        Initial rest, s, from which the still detector learns the noise.
    min_fraction, max_fraction : float
        Rotations whose angle, at a nominal gain taken from the larger rotations, is below
        ``min_fraction * angle_deg`` or above ``max_fraction * angle_deg`` are rejected as
        "rotation too small" / "rotation too large" (partial turns, face changes).
    min_purity : float
        Rotations with less than this share of the integral on one axis are rejected.
    require_both_directions : bool
        Raise unless every axis was turned both ways (the six turns of the turn-integration method).
    nominal_counts_per_dps : float, optional
        The datasheet gain (131 for an MPU-6050 at +-250 deg/s), used to judge which rotations
        are too small or too large; ``None``: taken from the larger rotations found.
    axes : str
        The axes this recording turns about and must calibrate (``"xyz"``, or e.g. ``"z"``
        for a recording of turns about z only); gains of the other axes are NaN.

    Returns
    -------
    GyroGains

    Raises
    ------
    CalibrationError
        No still periods, no usable rotation, or an axis (with ``require_both_directions``, a
        direction) without a rotation; the message lists the missing ones.

    Examples
    --------
    Two turns of 360 deg about z without a pause, a rest before and after (100 Hz, a gain of
    131 counts per deg/s):

    >>> import numpy as np, triaxcal as tc
    >>> u = np.linspace(0.0, 1.0, 601)  # 6 s at 100 Hz
    >>> rate = np.zeros((1400, 3)); rate[400:1001, 2] = 120 * (1 - np.cos(2 * np.pi * u))
    >>> noise = np.random.default_rng(0).normal(0.0, 0.05, rate.shape)  # deg/s
    >>> counts = 131.0 * (rate + noise) + [12.0, -7.0, 3.0]
    >>> res = tc.gyro_gains(counts, angle_deg=720, rate_hz=100, turns="whole", axes="z")
    >>> res.gain_counts_per_dps.round(1).tolist(), [r.label for r in res.rotations]
    ([nan, nan, 131.0], ['z ccw'])
    """
    ang = opt.magnitude(angle_deg, "angle_deg", hint="90 on a cube, 360 for a full turn")
    g = _as_rate(gyro)
    tt = _times(g.shape[0], t, rate_hz)
    rest = opt.number(rest_s, "rest_s", gt=0, hint="seconds of initial rest")
    min_frac = opt.number(min_fraction, "min_fraction", ge=0, lt=1)
    max_frac = opt.number(max_fraction, "max_fraction", gt=1)
    min_pur = opt.number(min_purity, "min_purity", ge=0, le=1)
    both = opt.flag(require_both_directions, "require_both_directions")
    nominal = None if nominal_counts_per_dps is None else opt.magnitude(
        nominal_counts_per_dps, "nominal_counts_per_dps",
        hint="131 for an MPU-6050 at +-250 deg/s")
    off = None if offset is None else opt.vector3(offset, "offset", hint="gyro bias")
    if not (isinstance(axes, str) and axes and set(axes) <= set(AXES)
            and len(set(axes)) == len(axes)):
        raise CalibrationError(
            f"axes must name the axes to calibrate, each once, from 'xyz' (e.g. 'xyz' or 'z'), "
            f"got {axes!r}"
        )
    need = [AXES.index(c) for c in AXES if c in axes]
    explicit = turns is not None and not isinstance(turns, str)
    iv: list[tuple[int, int]] | None
    if intervals is not None:
        iv = opt.intervals(intervals, "intervals", g.shape[0])
    elif (explicit or turns == WHOLE) and off is not None:
        iv = None  # nothing to detect: the turns and the offset are given
    else:
        iv = detect_still(g, rate_hz=_mean_rate(tt), window_s=0.5, rest_s=rest, k=4.0,
                          min_duration_s=0.5).intervals
    if off is None and iv:
        off = gyro_bias(g, intervals=iv).offset
    rots = find_rotations(g, t=tt, offset=off, intervals=iv, turns=turns)
    rejected: list[Rejection] = []
    pure = []
    for r in rots:
        if r.purity < min_pur:
            rejected.append(Rejection(r.start, r.end, NOT_ONE_AXIS,
                                      f"{r.purity:.2f} of the turn on {AXES[r.axis]}"))
        else:
            pure.append(r)
    mags = np.array([abs(float(r.integral[r.axis])) for r in pure])
    if len(pure) == 0:
        raise CalibrationError(
            "no usable rotation found between still periods: turn the sensor about one of its "
            f"axes by {ang:g} deg, holding it still before and after"
        )
    # nominal gain from the larger turns; smaller ones are partial or accidental moves
    if nominal is None:
        ref = float(np.median(mags[mags >= 0.5 * mags.max()])) / ang
    else:
        ref = nominal
    used = []
    for r, m in zip(pure, mags):
        if m < min_frac * ang * ref:
            rejected.append(Rejection(r.start, r.end, TOO_SMALL,
                                      f"{m / ref:.3g} deg at the nominal gain, need "
                                      f">= {min_frac * ang:g}"))
        elif m > max_frac * ang * ref:
            rejected.append(Rejection(r.start, r.end, TOO_LARGE,
                                      f"{m / ref:.3g} deg at the nominal gain, need "
                                      f"<= {max_frac * ang:g}"))
        else:
            used.append(r)
    gains: dict[tuple[int, str], list[float]] = {
        (ax, d): [] for ax in range(3) for d in ("ccw", "cw")
    }
    for r in used:
        gains[(r.axis, r.direction)].append(abs(float(r.integral[r.axis])) / ang)
    ccw = np.array([np.mean(gains[(a, "ccw")]) if gains[(a, "ccw")] else np.nan for a in range(3)])
    cw = np.array([np.mean(gains[(a, "cw")]) if gains[(a, "cw")] else np.nan for a in range(3)])
    missing = tuple(f"{AXES[a]} {d}" for a in need for d in ("ccw", "cw") if not gains[(a, d)])
    no_axis = [AXES[a] for a in need if np.isnan(ccw[a]) and np.isnan(cw[a])]
    if no_axis:
        why = ", ".join(f"{r.reason} at samples {r.start}-{r.end}" for r in rejected)
        raise CalibrationError(
            f"no rotation of about {ang:g} deg about {', '.join(no_axis)}: rotations are missing "
            f"for {', '.join(no_axis)} (used: {', '.join(r.label for r in used) or 'none'}; "
            f"rejected: {why or 'none'}); turn the sensor about each axis by {ang:g} deg, "
            "both ways, holding it still before and after (turns without a pause: pass "
            f"{flag('turns', WHOLE)}, and {flag('offset')} when the recording does not rest at "
            f"both ends; a recording about one axis: {flag('axes', 'z')})"
        )
    if both and missing:
        raise CalibrationError(
            f"rotations missing: {', '.join(missing)}; turn the sensor about each axis by "
            f"{ang:g} deg clockwise and counterclockwise"
        )
    mean = np.where(np.isnan(ccw), cw, np.where(np.isnan(cw), ccw, 0.5 * (ccw + cw)))
    asym = (ccw - cw) / mean
    assert off is not None  # find_rotations raised if there was no offset and no rest
    return GyroGains(
        offset=_ro(off),
        gain_ccw_counts_per_dps=_ro(ccw),
        gain_cw_counts_per_dps=_ro(cw),
        gain_counts_per_dps=_ro(mean),
        scale_dps_per_count=_ro(1.0 / mean),
        asymmetry=_ro(asym),
        rotations=tuple(used),
        rejected=tuple(rejected),
        missing=missing,
        angle_deg=ang,
    )


def _asymmetry_cause(cw: float, ccw: float, peaks: dict[str, float], angle: float) -> str:
    """The likely reason why an axis's two directions disagree."""
    sat = [d for d, v in peaks.items() if v >= GYRO_SATURATION_COUNTS]
    if sat:
        return (f"the {' and '.join(sat)} turn saturated the gyro (|raw| reached "
                f"{max(peaks.values()):.0f}): turn more slowly or choose a larger range")
    mean = 0.5 * (cw + ccw)
    return (f"the turns were probably not the same angle both ways (at the mean gain the "
            f"clockwise ones measure {angle * cw / mean:.1f} deg, the counter-clockwise ones "
            f"{angle * ccw / mean:.1f}): turn against a fixed stop, e.g. from one face of a cube "
            "to the next on a flat table; a bias that drifted between the turns does this too "
            "(hold still longer, or fit the temperature drift)")


def gain_warnings(gains: GyroGains, gyro: Any, *, max_asymmetry_pct: float = 3.0,
                  raw_unit: str = "counts") -> list[str]:
    """What a person should know about :func:`gyro_gains`' result, in words.

    An axis whose clockwise and counter-clockwise gains differ by more than
    ``max_asymmetry_pct`` percent, with the likely cause (a turn that saturated the gyro --
    :data:`~triaxcal.quality.bounds.GYRO_SATURATION_COUNTS` -- or turns of unequal angle), and
    every direction not turned.

    Parameters
    ----------
    gains : GyroGains
    gyro : array_like (N, 3)
        The readings the gains were found in (for the peaks of each turn).
    max_asymmetry_pct : float
        Largest difference between the two directions' gains, percent, before a warning.
    raw_unit : str
        Unit of the readings, for the messages.
    """
    g = _as_rate(gyro)
    limit = opt.number(max_asymmetry_pct, "max_asymmetry_pct", ge=0)
    out: list[str] = []
    for i, ax in enumerate(AXES):
        cw, ccw = float(gains.gain_cw_counts_per_dps[i]), float(gains.gain_ccw_counts_per_dps[i])
        asym = float(gains.asymmetry[i])
        if not (math.isfinite(asym) and abs(asym) * 100 > limit):
            continue
        peaks: dict[str, float] = {}
        for r in gains.rotations:
            if r.axis == i:
                d = "counter-clockwise" if r.direction == "ccw" else "clockwise"
                peaks[d] = max(peaks.get(d, 0.0), float(np.abs(g[r.start:r.end, i]).max()))
        why = _asymmetry_cause(cw, ccw, peaks, gains.angle_deg)
        out.append(f"{ax}: clockwise {cw:.4g} and counter-clockwise {ccw:.4g} {raw_unit} per "
                   f"deg/s differ by {abs(asym) * 100:.1f} %: {why}")
    for m in gains.missing:
        ax, d = m.split()
        out.append(f"no {'counter-clockwise' if d == 'ccw' else 'clockwise'} turn about "
                   f"{ax}: its gain is from one direction only")
    return out
