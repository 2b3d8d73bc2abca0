"""Is a sensor at rest? The test ``triaxcal noise`` runs before it computes noise figures.

An Allan deviation describes a sensor at rest: its readings are a bias plus noise. Motion adds
a signal the noise model has no term for -- a turn of the board reads as an enormous rate
random walk, a tilt as an acceleration random walk -- and the figures come out confident and
wrong. So the readings are tested first, streamed chunk by chunk with the Allan deviation
(memory does not grow with the log):

* the readings are averaged over windows of :data:`~triaxcal.quality.bounds.REST_WINDOW_S`
  (at least :data:`~triaxcal.quality.bounds.REST_MIN_WINDOW_SAMPLES`, at most
  :data:`~triaxcal.quality.bounds.REST_MAX_WINDOW_SAMPLES` samples);
* the **noise** of a window mean is estimated from the shortest time scale, where a hand's
  motion hardly shows: the RMS difference of consecutive samples in each window over sqrt(2)
  is the per-sample standard deviation; its median over the windows (robust to the windows in
  motion) over sqrt(samples per window) is the noise of a window mean, per axis; the norm over
  the three axes is the noise of the vector;
* the **change** is the largest difference (the norm of the vector) between a window mean and
  those of the windows up to :data:`~triaxcal.quality.bounds.REST_HORIZON_S` before it: a
  hand turning or tilting the board changes it within seconds, a sensor at rest by far less
  than its noise in that time (its bias drifts with temperature and random walk over minutes
  to hours, so a long log's drift is not taken for motion);
* the sensor is **at rest** when the change stays within
  :data:`~triaxcal.quality.bounds.REST_MAX_CHANGE_SIGMAS` times the noise, or within
  :data:`~triaxcal.quality.bounds.REST_FLOOR` (rad/s, m/s^2) when the unit is known.

Every bound is in :mod:`triaxcal.quality.bounds`, with the values measured on the real
recordings that set it.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._checks import options
from .._checks.arrays import as_samples
from .._checks.spelling import opt
from ..conventions.units import UNITS
from ..errors import CalibrationError, RefusedError
from ..quality.bounds import (
    REST_FLOOR,
    REST_HORIZON_S,
    REST_MAX_CHANGE_SIGMAS,
    REST_MAX_WINDOW_SAMPLES,
    REST_MIN_WINDOW_SAMPLES,
    REST_WHITE_CORRELATION,
    REST_WINDOW_S,
    sample_rate,
)

__all__ = ["NotAtRestError", "RestCheck", "RestMonitor", "check_rest", "not_at_rest"]

# Windows whose noise is summarised by one median (so that the memory stays bounded: a year
# of one-second windows keeps 7,700 medians).
_NOISE_BLOCK = 4096
# Log-spaced bins of the change, to count the windows in motion once the bound is known.
_BINS = np.logspace(-30.0, 30.0, 1201)

_WHAT = {"gyro": ("gyroscope", "rate"), "accel": ("accelerometer", "reading"),
         None: ("sensor", "reading")}


class NotAtRestError(RefusedError):
    """The readings were not at rest: noise figures of them would be wrong (the message names
    the motion found and what to do)."""


def _fmt(x: float) -> str:
    """A change or a bound for a message: 3 digits, no exponent from 0.001 to 99999."""
    a = abs(x)
    if 100 <= a < 1e5:
        return f"{x:.0f}"
    return f"{x:.3g}" if a == 0 or 1e-3 <= a < 100 else f"{x:.2e}"


@dataclass(frozen=True)
class RestCheck:
    """Whether a sensor was at rest (see the module docstring for the test).

    Attributes
    ----------
    sensor : str or None
        ``"gyro"``, ``"accel"`` or None.
    unit : str
        Unit of the readings, of ``change``, ``allowed`` and ``noise``.
    at_rest : bool or None
        True at rest, False moving, None when the log is too short to tell (fewer than two
        windows).
    change : float
        The largest change of a window mean within ``horizon_s``, in ``unit``.
    allowed : float
        The largest change at rest: ``max(sigmas * noise, floor)``, in ``unit``.
    noise : float
        Noise of a window mean (norm over the axes), in ``unit``.
    floor : float or None
        :data:`~triaxcal.quality.bounds.REST_FLOOR` in ``unit`` (None when the unit is not
        known: counts).
    window_s, horizon_s : float
        The window and the horizon, s.
    at_s : float
        When the largest change ended, s from the start of the log.
    moving_s : float
        About how long window means differed from one up to ``horizon_s`` earlier by more than
        ``allowed``, s (a motion, and up to ``horizon_s`` after it).
    duration_s : float
        Length of the log, s.
    """

    sensor: str | None
    unit: str
    at_rest: bool | None
    change: float
    allowed: float
    noise: float
    floor: float | None
    window_s: float
    horizon_s: float
    at_s: float
    moving_s: float
    duration_s: float

    @property
    def message(self) -> str:
        """What was found, in words (with what to do when the sensor moved)."""
        name, what = _WHAT[self.sensor]
        if self.at_rest is None:
            return (f"the {name} log is too short ({self.duration_s:.3g} s) to tell whether it "
                    "was at rest")
        u = self.unit
        rest = (f"at rest it changes by less than {_fmt(self.allowed)} {u}: "
                + (f"{REST_MAX_CHANGE_SIGMAS:g} times its noise"
                   if self.floor is None or self.allowed > self.floor else "the floor for a "
                   "known unit"))
        if self.at_rest:
            return (f"the {name} was at rest: its {self.window_s:.3g} s mean {what} changes by "
                    f"at most {_fmt(self.change)} {u} within {self.horizon_s:.3g} s ({rest})")
        verb = "turns at up to" if self.sensor == "gyro" else "moves: its mean changes by up to"
        return (
            f"the {name} {verb} {_fmt(self.change)} {u} (the change of its {self.window_s:.3g} s "
            f"mean {what} within {self.horizon_s:.3g} s, largest {self.at_s:.4g} s into the "
            f"{self.duration_s:.4g} s log; {rest}): "
            "the noise figures need the sensor at rest: record the board lying still (on a "
            "table, untouched, at a steady temperature), or cut the log to its still part"
        )

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON values (``at_rest`` null when the log is too short to tell)."""
        return {
            "at_rest": self.at_rest, "change": self.change, "allowed": self.allowed,
            "noise": self.noise, "floor": self.floor, "unit": self.unit,
            "window_s": self.window_s, "horizon_s": self.horizon_s, "at_s": self.at_s,
            "moving_s": self.moving_s, "message": self.message,
        }


class RestMonitor:
    """The at-rest test, streamed: :meth:`add` chunks of readings, then :meth:`result`.

    Memory is bounded (a ring of the last windows, one median per 4096 windows, a histogram)
    and the result does not depend on how the readings are chunked.

    Parameters
    ----------
    rate_hz : float
        Sample rate, Hz (sets the window length in samples).
    sensor : {"gyro", "accel", None}
        Names the sensor in the message; with a known ``unit`` it also sets the floor.
    unit : str
        Unit of the readings (``"rad/s"``, ``"deg/s"``, ``"g"``, ``"m/s^2"``, ``"counts"``...).
    axes : int
        Channels per row.

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> still = rng.normal(0.0, 0.01, (6000, 3))              # 60 s at 100 Hz, rad/s
    >>> mon = RestMonitor(100.0, sensor="gyro", unit="rad/s")
    >>> mon.add(still[:2500]); mon.add(still[2500:])
    >>> mon.result().at_rest
    True
    >>> turned = still.copy(); turned[3000:3200, 2] += 0.5    # a 2 s turn at 0.5 rad/s
    >>> check_rest(turned, 100.0, sensor="gyro", unit="rad/s").message[:40]
    'the gyroscope turns at up to 0.502 rad/s'
    """

    def __init__(self, rate_hz: float, *, sensor: str | None = None, unit: str = "counts",
                 axes: int = 3) -> None:
        self.rate_hz = sample_rate(rate_hz)
        if sensor not in ("gyro", "accel", None):
            raise CalibrationError(f"sensor must be 'gyro', 'accel' or None, got {sensor!r}")
        self.sensor = sensor
        if not isinstance(unit, str) or not unit.strip():
            raise CalibrationError(f"unit must name the unit of the readings, got {unit!r}")
        self.unit = unit
        self.axes = options.integer(axes, "axes", ge=1, le=64)
        self.w = int(max(REST_MIN_WINDOW_SAMPLES,
                         min(round(REST_WINDOW_S * self.rate_hz), REST_MAX_WINDOW_SAMPLES)))
        self.window_s = self.w / self.rate_hz
        self.h = max(1, int(round(REST_HORIZON_S / self.window_s)))
        # block lengths (samples) at which the noise is estimated: 1, 2, 4, ... while a window
        # holds at least 8 blocks
        self.levels = [1 << i for i in range(64) if self.w >> i >= 8] or [1]
        self.n = 0
        self._carry = np.zeros((0, self.axes))
        self._ring = np.zeros((0, self.axes))  # the last h window means
        self._windows = 0
        self._pending: list[np.ndarray] = []  # per window: rms and correlation per level, axis
        self._pending_rows = 0
        self._medians: list[np.ndarray] = []
        self._hist = np.zeros(len(_BINS) + 1, dtype=np.int64)
        self._change = 0.0
        self._at = 0

    def add(self, chunk: Any) -> None:
        """Add readings of shape (rows, axes) (finite numbers, in :attr:`unit`)."""
        arr = np.asarray(chunk, dtype=np.float64)
        if arr.ndim == 1 and self.axes == 1:
            arr = arr[:, None]
        if arr.ndim != 2 or arr.shape[1] != self.axes:
            raise CalibrationError(f"chunk must have shape (rows, {self.axes}), got {arr.shape}")
        if not np.isfinite(arr).all():
            raise CalibrationError("the readings hold NaN or inf: drop or repair them first")
        self.n += len(arr)
        if len(self._carry):
            arr = np.concatenate([self._carry, arr])
        nw = len(arr) // self.w
        self._carry = arr[nw * self.w:].copy()
        if nw == 0:
            return
        win = arr[: nw * self.w].reshape(nw, self.w, self.axes)
        with np.errstate(over="ignore", invalid="ignore"):  # readings near the double's end
            self._noise(win)
            self._changes(win.mean(axis=1))

    def _noise(self, win: np.ndarray) -> None:
        """Per window and block length b: the RMS difference of consecutive b-sample means and
        the correlation of consecutive differences (-1/2 for white noise)."""
        nw = len(win)
        out = np.empty((nw, 2, len(self.levels), self.axes))
        for li, b in enumerate(self.levels):
            k = self.w // b
            blk = win if b == 1 else win[:, :k * b].reshape(nw, k, b, self.axes).mean(axis=2)
            d = np.diff(blk, axis=1)
            s2 = np.sum(d * d, axis=1)
            with np.errstate(invalid="ignore", divide="ignore"):
                out[:, 0, li] = np.sqrt(s2 / (k - 1))
                out[:, 1, li] = np.where(s2 > 0, np.sum(d[:, 1:] * d[:, :-1], axis=1) / s2,
                                         np.nan)
        self._pending.append(out)
        self._pending_rows += nw
        if self._pending_rows >= _NOISE_BLOCK:
            allr = np.concatenate(self._pending)
            k = len(allr) // _NOISE_BLOCK
            for b in range(k):
                self._medians.append(_median(allr[b * _NOISE_BLOCK:(b + 1) * _NOISE_BLOCK]))
            rest = allr[k * _NOISE_BLOCK:]
            self._pending = [rest] if len(rest) else []
            self._pending_rows = len(rest)

    def _changes(self, means: np.ndarray) -> None:
        q = np.concatenate([self._ring, means])
        p = len(self._ring)
        change = np.zeros(len(means))
        for j in range(1, self.h + 1):
            lo = max(p, j)  # the later window of the pair is a new one
            if lo >= len(q):
                break
            d = np.sqrt(np.sum((q[lo:] - q[lo - j:len(q) - j]) ** 2, axis=1))
            np.maximum(change[lo - p:], d, out=change[lo - p:])
        if len(change):
            k = int(np.argmax(change))
            if change[k] > self._change:
                self._change = float(change[k])
                self._at = self._windows + k + 1
        self._hist += np.bincount(np.searchsorted(_BINS, change), minlength=len(_BINS) + 1)
        self._windows += len(means)
        self._ring = q[-self.h:].copy()

    def result(self, *, rate_hz: float | None = None) -> RestCheck:
        """The verdict on everything added. ``rate_hz``: the sample rate, when it was found to
        differ from the one the monitor was made with (times are then given at it; the windows
        stay as many samples as they were)."""
        rate = self.rate_hz if rate_hz is None else options.number(rate_hz, "rate_hz", gt=0)
        window_s = self.w / rate
        duration = self.n / rate
        floor = None
        if self.unit in UNITS and self.sensor in REST_FLOOR and UNITS[self.unit][0] == self.sensor:
            floor = REST_FLOOR[self.sensor] / UNITS[self.unit][1]
        if self._windows < 2:
            return RestCheck(self.sensor, self.unit, None, 0.0, math.nan, math.nan, floor,
                             window_s, self.h * window_s, 0.0, 0.0, duration)
        blocks = list(self._medians)
        if self._pending:
            blocks.append(_median(np.concatenate(self._pending)))
        med = _median(np.array(blocks))  # (2, levels, axes)
        # the shortest block length at which consecutive block means look like white noise
        # (a sensor's low-pass filter correlates samples within its time constant); none: the
        # readings move at every scale, and the per-sample estimate is the one motion
        # disturbs least
        white = [li for li in range(len(self.levels))
                 if np.all(med[1, li] <= REST_WHITE_CORRELATION)]
        li = white[0] if white else 0
        per_block = med[0, li] / math.sqrt(2.0)
        with np.errstate(over="ignore"):
            noise = float(np.sqrt(np.sum(np.nan_to_num(per_block, posinf=np.inf) ** 2))
                          * math.sqrt(self.levels[li] / self.w))
        allowed = REST_MAX_CHANGE_SIGMAS * noise
        if floor is not None:
            allowed = max(allowed, floor)
        moving = int(self._hist[np.searchsorted(_BINS, allowed, side="right"):].sum())
        at_rest = bool(self._change <= allowed)
        return RestCheck(
            sensor=self.sensor, unit=self.unit, at_rest=at_rest, change=self._change,
            allowed=allowed, noise=noise, floor=floor, window_s=window_s,
            horizon_s=self.h * window_s, at_s=self._at * window_s,
            moving_s=moving * window_s, duration_s=duration,
        )


def _median(a: np.ndarray) -> np.ndarray:
    """Median over the first axis, NaN (a window of constant readings) left out."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all NaN: stays NaN
        return np.nanmedian(a, axis=0)


def check_rest(readings: Any, rate_hz: float, *, sensor: str | None = None,
               unit: str = "counts") -> RestCheck:
    """The at-rest test (module docstring) on readings of shape (N, 3) at ``rate_hz``.

    Returns
    -------
    RestCheck
        ``at_rest`` and, in :attr:`RestCheck.message`, what was found in words.
    """
    arr = as_samples(readings, "readings", channels="any")
    mon = RestMonitor(rate_hz, sensor=sensor, unit=unit, axes=arr.shape[1])
    mon.add(arr)
    return mon.result()


def not_at_rest(check: RestCheck) -> str:
    """The refusal for a sensor that moved: the finding and how to go on anyway."""
    return f"{check.message}; or pass {opt('force', True)} to compute the figures anyway, marked"
