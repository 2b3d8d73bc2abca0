"""Stationary detection: find the still poses in a stream of three-axis readings.

Two detectors, both vectorised over numpy arrays (millions of samples per second):

* :func:`detect_poses` / :class:`PoseDetector` -- the seed method (sphere-center-descent.txt),
  extended to every sensor on the board. Consecutive windows of ``window`` samples are
  averaged; a window is *steady* when no sensor says the board moved:

  - accelerometer: every axis of its window mean changed by at most ``threshold`` from the
    previous window's (the seed's rule, 0.07 g);
  - gyroscope (``gyro_columns``): every axis of its window-mean rate is within
    ``gyro_threshold`` of the rate at the last still window (the bias), and changed by at
    most that much from the previous window -- this sees the twists about the vertical that
    leave the accelerometer unchanged;
  - magnetometer (``mag_columns``): every axis of its window mean changed by at most
    ``mag_threshold`` from the previous window's.

  Without explicit thresholds the gyroscope's and magnetometer's are learnt from the sensors'
  own noise (see :data:`NOISE_Z`). A run of steady windows is a candidate pose; its mean is
  registered as a point unless the candidate is rejected as "too short", "too noisy" or "too
  close to an earlier pose" (close in the accelerometer *and* in the magnetometer, when it is
  used). After each registered pose, ``holdoff_samples`` samples are ignored (the seed's
  2-second pause after its beep). The offline function and the online detector share one
  state machine, so they register the same poses on the same data however the stream is cut
  into chunks.
* :func:`still_intervals` / :func:`detect_still` -- the variance detector of imu_tk (Tedaldi,
  Pretto, Menegatti, ICRA 2014): the magnitude of the per-axis variance over a sliding window
  of ``window_s`` seconds is compared with ``k`` times the same quantity measured over an
  initial rest period of ``rest_s`` seconds.

Indices are sample indices into the array given (or into the whole stream, online); ``end`` is
exclusive, Python-slice style.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from . import _options as opt
from ._validate import as_samples
from .errors import CalibrationError

__all__ = [
    "NOISE_WINDOWS",
    "NOISE_Z",
    "Pose",
    "PoseDetection",
    "PoseDetector",
    "Rejection",
    "StillDetection",
    "detect_poses",
    "detect_still",
    "still_intervals",
]

TOO_SHORT = "too short"
TOO_NOISY = "too noisy"
TOO_CLOSE = "too close to an earlier pose"

#: A learnt threshold is this many standard deviations of the change of a window mean between
#: two still windows.
NOISE_Z = 8.0
#: The noise is learnt from the changes between the first this-many windows that the
#: accelerometer calls steady (the board lies still at the start of a capture) ...
NOISE_WINDOWS = 32
#: ... and is used once this many have been seen (before that, only the accelerometer decides).
NOISE_MIN_WINDOWS = 6
#: The standard deviation is estimated from the lower quartile of the absolute changes (robust
#: to the twists among the learning windows): for normal noise that quartile is 0.3186 sigma.
_Q25_HALF_NORMAL = 0.31863936396437514
#: The gyroscope's bias is the median of its means over this many most recent still windows.
BIAS_WINDOWS = 9
#: When the gyroscope stays steady for this many windows at a rate that differs from that bias
#: by less than :data:`REANCHOR_MAX` thresholds (it drifted while the board moved), that rate
#: becomes the new bias; a larger steady rate is a turn at constant speed and stays motion.
REANCHOR_WINDOWS = 8
REANCHOR_MAX = 16.0


@dataclass(frozen=True)
class Pose:
    """A registered still pose.

    Attributes
    ----------
    start, end : int
        Sample indices of the still run (``end`` exclusive).
    mean : ndarray, shape (K,)
        Mean of every channel over the run, in the input's units.
    n : int
        Number of samples averaged (``end - start``).
    std : ndarray, shape (K,)
        Standard deviation of every channel about ``mean`` over the run (noise and drift).
    """

    start: int
    end: int
    mean: np.ndarray
    n: int
    std: np.ndarray = field(default_factory=lambda: np.zeros(0))


@dataclass(frozen=True)
class Rejection:
    """A candidate pose that was not registered, with the reason.

    ``reason`` is one of ``"too short"``, ``"too noisy"``, ``"too close to an earlier pose"``;
    ``detail`` says by how much.
    """

    start: int
    end: int
    reason: str
    detail: str = ""


@dataclass(frozen=True)
class PoseDetection:
    """The result of :func:`detect_poses`.

    Attributes
    ----------
    points : ndarray, shape (M, 3)
        Pose means of the accelerometer channels (``columns``), ready for
        :func:`triaxcal.fit_ellipsoid`.
    poses : list of Pose
        The registered poses (means over all channels given).
    rejected : list of Rejection
        Candidates not registered, each with its reason.
    threshold : float
        The accelerometer's steadiness threshold used, in the input's units.
    window : int
        Samples per averaging window.
    thresholds : dict
        The threshold of every sensor that took part, in the input's units: ``"accel"``
        (window-mean change), ``"gyro"`` (rate away from the bias) and ``"mag"`` (window-mean
        change); ``None`` for a sensor given whose noise could not be learnt (it then took no
        part), absent for a sensor not given.
    """

    points: np.ndarray
    poses: list[Pose]
    rejected: list[Rejection]
    threshold: float
    window: int
    thresholds: dict[str, float | None] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.poses)


def _as_samples(samples: Any, name: str = "samples", allow_empty: bool = True) -> np.ndarray:
    arr = as_samples(samples, name, channels="xyz+", finite=True)
    if not allow_empty and arr.shape[0] == 0:
        raise CalibrationError(f"{name} is empty: record some samples first")
    return arr


class _Sensor:
    """Threshold of one extra sensor (gyroscope or magnetometer): given, or learnt from noise."""

    def __init__(self, columns: tuple[int, int, int], threshold: float | None) -> None:
        self.columns = list(columns)
        self.fixed = threshold is not None
        self.threshold: float | None = threshold
        self.changes: list[np.ndarray] = []  # |change| of the window mean, per learning window
        self.integral = True  # every learning window held whole numbers (counts)

    @property
    def learning(self) -> bool:
        return not self.fixed and len(self.changes) < NOISE_WINDOWS

    def learn(self, change: np.ndarray, integral: bool) -> None:
        self.changes.append(change)
        self.integral &= bool(integral)
        if len(self.changes) >= NOISE_MIN_WINDOWS:
            q = np.quantile(np.vstack(self.changes), 0.25, axis=0)  # per axis
            sigma = float(q.max()) / _Q25_HALF_NORMAL
            # whole-number readings change their window mean in steps of 1/window: never let
            # the noise estimate fall below their rounding noise
            self.threshold = NOISE_Z * max(sigma, self.floor if self.integral else 0.0)

    floor = 0.0  # set per detector: rounding noise of a window-mean change for counts


class _Segmenter:
    """The state machine shared by :func:`detect_poses` and :class:`PoseDetector`.

    Fed whole windows, it computes per-window statistics (sum and sum of squares of every
    channel, about a fixed reference), decides which windows are steady, tracks the current run
    of steady windows and closes it when motion resumes (or when it reaches ``max_windows``,
    or at :meth:`finish`). Every decision depends only on the windows seen so far, so the
    result does not depend on how the stream is cut into blocks.
    """

    def __init__(
        self,
        *,
        window: int,
        threshold: float,
        min_windows: int,
        min_separation: float,
        max_std: float,
        max_windows: int | None,
        columns: tuple[int, int, int],
        gyro_columns: tuple[int, int, int] | None,
        gyro_threshold: float | None,
        mag_columns: tuple[int, int, int] | None,
        mag_threshold: float | None,
        holdoff_samples: int,
    ) -> None:
        self.window = window
        self.threshold = threshold
        self.min_windows = min_windows
        self.min_separation = min_separation
        self.max_std = max_std
        self.max_windows = max_windows
        self.columns = columns
        self.holdoff_windows = -(-holdoff_samples // window)  # ceil
        self.gyro = _Sensor(gyro_columns, gyro_threshold) if gyro_columns else None
        self.mag = _Sensor(mag_columns, mag_threshold) if mag_columns else None
        for s in (self.gyro, self.mag):
            if s is not None:
                s.floor = 0.5 / math.sqrt(window)
        self.ref: np.ndarray | None = None
        self.n_windows = 0  # windows seen so far
        self.prev_mean: np.ndarray | None = None  # all-channel mean of the last window
        # gyro means (about ref) of the most recent still windows: their median is the bias
        self.gyro_hist: deque[np.ndarray] = deque(maxlen=BIAS_WINDOWS)
        self.rate_fail = 0  # windows in a row that failed only the rate test
        self.skip_until = 0  # windows before this index are ignored (hold-off)
        self.fresh = True  # the next window opens a run whatever it reads
        # current run: first window index, window count, accumulated sums
        self.run_first = -1
        self.run_len = 0
        self.run_s1: Any = 0.0
        self.run_s2: Any = 0.0
        self.run_done = False  # decided early (max_windows); averaged on until motion
        self.run_pose: int | None = None  # index of the pose the open run registered early
        self.points: list[np.ndarray] = []
        self._pts = np.empty((64, 3))  # the same points as an array, for distance checks
        self._mag_pts = np.empty((64, 3))  # magnetometer means of the poses
        self.poses: list[Pose] = []
        self.rejected: list[Rejection] = []

    @property
    def thresholds(self) -> dict[str, float | None]:
        out: dict[str, float | None] = {"accel": self.threshold}
        if self.gyro is not None:
            out["gyro"] = self.gyro.threshold
        if self.mag is not None:
            out["mag"] = self.mag.threshold
        return out

    # -- window statistics ------------------------------------------------------------------
    def feed(self, block: np.ndarray) -> list[Pose]:
        """Feed whole windows: ``block`` has a multiple of ``window`` rows."""
        if block.shape[0] == 0:
            return []
        if self.ref is None:
            self.ref = block[0].copy()
        w = self.window
        nw = block.shape[0] // w
        c = (block - self.ref).reshape(nw, w, block.shape[1])
        s1 = c.sum(axis=1)
        s2 = np.einsum("ijk,ijk->ik", c, c)
        means = s1 / w
        prev = np.vstack([self.prev_mean[None, :] if self.prev_mean is not None
                          else np.full((1, means.shape[1]), np.nan), means[:-1]])
        change = np.abs(means - prev)  # NaN for the very first window
        with np.errstate(invalid="ignore"):
            accel_steady = change[:, list(self.columns)].max(axis=1) <= self.threshold
        steady = accel_steady.copy()
        gyro_thr = None
        for sensor in (self.gyro, self.mag):
            if sensor is not None:
                thr = self._thresholds(sensor, change, accel_steady, block, nw)
                with np.errstate(invalid="ignore"):
                    steady &= np.isnan(thr) | (change[:, sensor.columns].max(axis=1) <= thr)
                if sensor is self.gyro:
                    gyro_thr = thr
        self.prev_mean = means[-1].copy()
        first = self.n_windows
        self.n_windows += nw
        return self._runs(steady, s1, s2, means, first, gyro_thr)

    def _thresholds(self, sensor: _Sensor, change: np.ndarray, accel_steady: np.ndarray,
                    block: np.ndarray, nw: int) -> np.ndarray:
        """The threshold of ``sensor`` in force at each window (NaN: not known yet), learning
        it from the changes over the accelerometer's steady windows as they come."""
        cols = sensor.columns
        thr = np.full(nw, np.nan if sensor.threshold is None else sensor.threshold)
        if sensor.learning:
            w = self.window
            vals = block[:, cols].reshape(nw, w, 3)
            for k in np.flatnonzero(accel_steady).tolist():
                if not sensor.learning:
                    break
                sensor.learn(change[k, cols], bool(np.all(vals[k] == np.round(vals[k]))))
                if sensor.threshold is not None:  # in force from this window on
                    thr[k:] = sensor.threshold
        return thr

    def _runs(
        self, steady: np.ndarray, s1: np.ndarray, s2: np.ndarray, means: np.ndarray, first: int,
        gyro_thr: np.ndarray | None,
    ) -> list[Pose]:
        new: list[Pose] = []
        nw = steady.shape[0]
        cs1 = np.vstack([np.zeros((1, s1.shape[1])), np.cumsum(s1, axis=0)])
        cs2 = np.vstack([np.zeros((1, s2.shape[1])), np.cumsum(s2, axis=0)])
        # ends of runs of equal steadiness: next_change[i] is the first index > i whose
        # steadiness differs from window i's (or nw)
        flips = np.flatnonzero(np.diff(steady.astype(np.int8))) + 1
        ends = np.concatenate((flips, [nw]))
        gcols = self.gyro.columns if self.gyro is not None else None
        i = 0
        while i < nw:
            k = first + i
            if k < self.skip_until:  # hold-off after a registered pose
                i = min(nw, self.skip_until - first)
                continue
            j = int(ends[np.searchsorted(ends, i, side="right")])  # end of i's segment
            if self.fresh:  # start of the stream, or the end of a hold-off
                self.fresh = False
                self._open(k)
                self.rate_fail = 0
                i += 1
                continue
            if not steady[i]:
                # motion: close any open run; the last moving window may open the next run
                self.rate_fail = 0
                if self.run_len:
                    new += self._close(k)
                    if self.skip_until > k:
                        i += 1
                        continue
                self._open(first + j - 1)
                i = j
                continue
            if self.run_len == 1 and gyro_thr is not None and self.gyro_hist:
                # the first steady window after motion: is the gyroscope back at its bias?
                g = means[i, gcols]
                bias = np.median(np.array(self.gyro_hist), axis=0)
                away = float(np.abs(g - bias).max())
                if away > gyro_thr[i]:  # False for NaN
                    self.rate_fail += 1
                    if self.rate_fail >= REANCHOR_WINDOWS and away <= REANCHOR_MAX * gyro_thr[i]:
                        # steady for a while, a little off: the bias moved, follow it
                        self.gyro_hist.clear()
                        self.gyro_hist.append(g)
                        self.rate_fail = 0
                    self._open(k)  # still turning: this window opens the run instead
                    i += 1
                    continue
            self.rate_fail = 0
            # steady windows i..j-1 extend the open run (opened by the window before i)
            if self.run_done:
                # decided early (max_windows): a registered pose keeps averaging until motion
                self._extend(cs1[j] - cs1[i], cs2[j] - cs2[i], j - i)
            elif self.max_windows is not None and self.run_len + (j - i) >= self.max_windows:
                take = self.max_windows - self.run_len
                self._extend(cs1[i + take] - cs1[i], cs2[i + take] - cs2[i], take)
                new += self._close(k + take - 1, keep_open=True)
                if gcols is not None:
                    self.gyro_hist.extend(means[max(i, i + take - BIAS_WINDOWS):i + take, gcols])
                if self.skip_until > k + take - 1:
                    i += take
                    continue
                self._extend(cs1[j] - cs1[i + take], cs2[j] - cs2[i + take], (j - i) - take)
            else:
                self._extend(cs1[j] - cs1[i], cs2[j] - cs2[i], j - i)
            if gcols is not None:
                self.gyro_hist.extend(means[max(i, j - BIAS_WINDOWS):j, gcols])
            i = j
        return new

    def _open(self, win: int) -> None:
        # the opening window (the last one that differed from its predecessor) may still hold
        # the end of the motion: it counts towards min_windows but not towards the mean
        if self.run_pose is not None:
            self._finish_early()
        self.run_first = win
        self.run_len = 1
        self.run_s1 = 0.0
        self.run_s2 = 0.0
        self.run_done = False

    def _extend(self, s1: np.ndarray, s2: np.ndarray, k: int) -> None:
        self.run_s1 = self.run_s1 + s1
        self.run_s2 = self.run_s2 + s2
        self.run_len += k

    def _stats(self) -> tuple[int, int, int, np.ndarray, np.ndarray]:
        """start, end, n, mean and std of the open run (without its opening window)."""
        w = self.window
        start = (self.run_first + 1) * w
        end = (self.run_first + self.run_len) * w
        n = end - start
        m = self.run_s1 / n
        std = np.sqrt(np.maximum(self.run_s2 / n - m * m, 0.0))
        assert self.ref is not None
        return start, end, n, m + self.ref, std

    def _finish_early(self) -> None:
        """The run of a pose registered early ended: its mean covers the whole run now."""
        idx = self.run_pose
        self.run_pose = None
        if idx is None:
            return
        start, end, n, mean, std = self._stats()
        mean.setflags(write=False)
        std.setflags(write=False)
        self.poses[idx] = Pose(start=start, end=end, mean=mean, n=n, std=std)
        point = mean[list(self.columns)]
        self.points[idx] = point
        self._pts[idx] = point
        if self.mag is not None:
            self._mag_pts[idx] = mean[self.mag.columns]

    def _close(self, at: int, keep_open: bool = False) -> list[Pose]:
        """Decide on the open run at window ``at``; register it or record why not."""
        out: list[Pose] = []
        if self.run_done:
            self._finish_early()
            self.run_len = 0
            self.run_done = False
            return out
        w = self.window
        start = (self.run_first + 1) * w
        end = (self.run_first + self.run_len) * w
        assert self.ref is not None
        if self.run_len < 2:
            # a single window with motion on both sides is not a candidate at all
            pass
        elif self.run_len < self.min_windows:
            self.rejected.append(
                Rejection(start, end, TOO_SHORT, f"{self.run_len} steady windows, need "
                          f"{self.min_windows}")
            )
        else:
            n = end - start
            m = self.run_s1 / n
            var = np.maximum(self.run_s2 / n - m * m, 0.0)
            std = np.sqrt(var)
            mean = m + self.ref
            point = mean[list(self.columns)]
            noise = float(std[list(self.columns)].max())
            if noise > self.max_std:
                self.rejected.append(
                    Rejection(start, end, TOO_NOISY,
                              f"std {noise:.4g} > max_std {self.max_std:.4g}")
                )
            else:
                close = self._too_close(point, mean)
                if close:
                    self.rejected.append(Rejection(start, end, TOO_CLOSE, close))
                else:
                    mean.setflags(write=False)
                    std.setflags(write=False)
                    pose = Pose(start=start, end=end, mean=mean, n=n, std=std)
                    m = len(self.points)
                    self.points.append(point)
                    if m == self._pts.shape[0]:
                        self._pts = np.vstack([self._pts, np.empty_like(self._pts)])
                        self._mag_pts = np.vstack([self._mag_pts, np.empty_like(self._mag_pts)])
                    self._pts[m] = point
                    if self.mag is not None:
                        self._mag_pts[m] = mean[self.mag.columns]
                    self.poses.append(pose)
                    out.append(pose)
                    if keep_open:
                        self.run_pose = m
                    if self.holdoff_windows:
                        self.run_pose = None  # the hold-off ends the run here
                        self.skip_until = at + 1 + self.holdoff_windows
                        self.fresh = True
                        self.run_len = 0
                        self.run_done = False
                        return out
        if keep_open:
            self.run_done = True
        else:
            self.run_len = 0
        return out

    def _too_close(self, point: np.ndarray, mean: np.ndarray) -> str:
        """Why the candidate repeats an earlier pose ("" when it does not)."""
        m = len(self.points)
        if not m or self.min_separation <= 0:
            return ""
        d = self._pts[:m] - point
        dist = np.sqrt(np.einsum("ij,ij->i", d, d))
        near = dist < self.min_separation
        extra = ""
        if self.mag is not None and self.mag.threshold is not None:
            dm = self._mag_pts[:m] - mean[self.mag.columns]
            dist_m = np.sqrt(np.einsum("ij,ij->i", dm, dm))
            near &= dist_m < self.mag.threshold
            if near.any():
                extra = (f" and {float(dist_m[near].min()):.4g} in the magnetometer (its "
                         f"threshold {self.mag.threshold:.4g})")
        if not near.any():
            return ""
        return (f"{float(dist[near].min()):.4g} from an earlier pose, min_separation "
                f"{self.min_separation:.4g}{extra}")

    def finish(self) -> list[Pose]:
        if self.run_len:
            return self._close(self.n_windows)
        return []


def _columns(value: Any, what: str, n_channels: int | None) -> tuple[int, int, int]:
    bad = CalibrationError(
        f"{what} must name 3 channels (x, y, z) by whole-number index >= 0, got {value!r}"
    )
    if isinstance(value, (str, bytes)) or not hasattr(value, "__len__") or len(value) != 3:
        raise bad
    try:
        a, b, c = (opt.integer(v, what, ge=0) for v in value)
    except CalibrationError:
        raise bad from None
    cols = (a, b, c)
    if n_channels is not None and not all(0 <= k < n_channels for k in cols):
        raise CalibrationError(f"{what} {cols} out of range for {n_channels} channels")
    return cols


def _positive(value: Any, what: str) -> float | None:
    return opt.optional_number(value, what, gt=0, hint="in the sensor's units, or None: learn it")


def _options(
    window: int,
    threshold: float | None,
    units_per_g: float,
    min_separation: float | None,
    min_windows: int,
    max_std: float | None,
    max_windows: int | None,
    columns: Sequence[int],
    n_channels: int | None = None,
    *,
    gyro_columns: Sequence[int] | None = None,
    gyro_threshold: float | None = None,
    mag_columns: Sequence[int] | None = None,
    mag_threshold: float | None = None,
    holdoff_samples: int = 0,
) -> dict:
    win = opt.integer(window, "window", ge=1, hint="samples per averaging window")
    min_w = opt.integer(min_windows, "min_windows", ge=2, hint="two windows to compare")
    max_w = None if max_windows is None else opt.integer(max_windows, "max_windows",
                                                         ge=min_w, hint="or None")
    upg = opt.number(units_per_g, "units_per_g", gt=0, hint="16384 for counts at +-2 g")
    thr = 0.07 * upg if threshold is None else opt.number(
        threshold, "threshold", gt=0, hint="in the sensor's units")
    sep = thr if min_separation is None else opt.number(
        min_separation, "min_separation", ge=0, hint="0 disables it")
    mstd = thr if max_std is None else opt.number(max_std, "max_std", gt=0)
    cols = _columns(columns, "columns", n_channels)
    gcols = None if gyro_columns is None else _columns(gyro_columns, "gyro_columns", n_channels)
    mcols = None if mag_columns is None else _columns(mag_columns, "mag_columns", n_channels)
    used = [c for cs in (cols, gcols, mcols) if cs for c in cs]
    if len(set(used)) != len(used):
        raise CalibrationError(
            f"columns, gyro_columns and mag_columns overlap ({cols}, {gcols}, {mcols}): each "
            "sensor needs its own three channels"
        )
    holdoff = opt.integer(holdoff_samples, "holdoff_samples", ge=0, hint="samples")
    return {
        "window": win,
        "threshold": thr,
        "min_windows": min_w,
        "min_separation": sep,
        "max_std": mstd,
        "max_windows": max_w,
        "columns": cols,
        "gyro_columns": gcols,
        "gyro_threshold": _positive(gyro_threshold, "gyro_threshold"),
        "mag_columns": mcols,
        "mag_threshold": _positive(mag_threshold, "mag_threshold"),
        "holdoff_samples": holdoff,
    }


def detect_poses(
    samples: Any,
    *,
    window: int = 25,
    threshold: float | None = None,
    units_per_g: float = 1.0,
    min_separation: float | None = None,
    min_windows: int = 2,
    max_std: float | None = None,
    max_windows: int | None = None,
    columns: Sequence[int] = (0, 1, 2),
    gyro_columns: Sequence[int] | None = None,
    gyro_threshold: float | None = None,
    mag_columns: Sequence[int] | None = None,
    mag_threshold: float | None = None,
    holdoff_samples: int = 0,
) -> PoseDetection:
    """Find still poses by the seed's window-average method, with every sensor (offline).

    Parameters
    ----------
    samples : array_like, shape (N, K), K >= 3
        Readings, one row per sample; ``columns`` name the accelerometer's three. Other
        channels (gyro, magnetometer, temperature) are averaged too and appear in
        :attr:`Pose.mean`.
    window : int
        Samples per averaging window (25 = 0.25 s at 100 Hz).
    threshold : float, optional
        Largest change of any accelerometer axis of the window mean, from one window to the
        next, for the board to count as still, in the input's units. ``None``:
        ``0.07 * units_per_g`` (the seed's 0.07 g).
    units_per_g : float
        Accelerometer units per g: 1 for g, 9.80665 for m/s^2, 16384 for counts at +-2 g.
    min_separation : float, optional
        Smallest accelerometer distance (input units, Euclidean) between a new pose and every
        registered one; a candidate closer than this to an earlier pose -- and, when
        ``mag_columns`` are given, closer than ``mag_threshold`` to it in the magnetometer --
        is rejected as "too close to an earlier pose". ``None``: ``threshold``; 0 disables
        the check.
    min_windows : int
        Fewest windows a still run needs (2 = one steady comparison, the seed's rule);
        shorter runs are rejected as "too short".
    max_std : float, optional
        Largest standard deviation of any accelerometer axis about the run's mean (noise
        plus slow drift); noisier runs are rejected as "too noisy". ``None``: ``threshold``.
    max_windows : int, optional
        Decide on a run as soon as it has this many windows (the seed's beep: the pose is
        registered, or rejected, on those windows' mean, and :meth:`PoseDetector.update` returns
        it then); a registered pose goes on averaging until the board moves, and
        :attr:`PoseDetection.poses` hold the whole run's mean. ``None``: decide when the motion
        resumes, on the whole run.
    columns : sequence of 3 ints
        The accelerometer's channels, for detection and for :attr:`PoseDetection.points`.
    gyro_columns : sequence of 3 ints, optional
        The gyroscope's channels. A window whose mean rate on any axis is more than
        ``gyro_threshold`` away from the rate of the last still window (the bias), or from the
        previous window's, is motion.
    gyro_threshold : float, optional
        In the gyroscope's input units (counts, deg/s...). ``None``: learnt from its noise,
        ``NOISE_Z`` standard deviations of the change of a window mean between still windows
        (the first ``NOISE_WINDOWS`` windows the accelerometer calls steady).
    mag_columns : sequence of 3 ints, optional
        The magnetometer's channels. A window whose mean changed on any axis by more than
        ``mag_threshold`` from the previous window's is motion.
    mag_threshold : float, optional
        In the magnetometer's input units. ``None``: learnt from its noise, as for the gyro.
    holdoff_samples : int
        Samples ignored after each registered pose before a new run can start (the seed's
        2-second pause after its beep: ``2 * rate_hz``). 0: none.

    Returns
    -------
    PoseDetection

    Examples
    --------
    >>> import numpy as np, triaxcal as tc
    >>> rest = np.tile([[0.0, 0.0, 1.0]], (200, 1))
    >>> move = np.linspace([0, 0, 1], [1, 0, 0], 100)
    >>> side = np.tile([[1.0, 0.0, 0.0]], (200, 1))
    >>> det = tc.detect_poses(np.vstack([rest, move, side]), window=25)
    >>> det.points.round(3).tolist()
    [[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]

    A twist about the vertical (18 deg at 90 deg/s, 100 samples/s) leaves the accelerometer
    unchanged; the gyroscope and the magnetometer see it:

    >>> acc = np.tile([0.0, 0.0, 1.0], (500, 1))
    >>> gyro = np.zeros((500, 3)); gyro[240:260, 2] = 90.0
    >>> yaw = np.radians(np.clip((np.arange(500) - 240) * 0.9, 0, 18))
    >>> mag = np.column_stack([25 * np.cos(yaw), -25 * np.sin(yaw), np.full(500, -40.0)])
    >>> len(tc.detect_poses(acc).poses)
    1
    >>> det = tc.detect_poses(np.hstack([acc, gyro, mag]), gyro_columns=(3, 4, 5),
    ...                       mag_columns=(6, 7, 8), gyro_threshold=1.0, mag_threshold=0.5)
    >>> [(p.start, p.end) for p in det.poses]
    [(25, 225), (300, 500)]
    """
    arr = _as_samples(samples)
    opts = _options(window, threshold, units_per_g, min_separation, min_windows, max_std,
                    max_windows, columns, arr.shape[1], gyro_columns=gyro_columns,
                    gyro_threshold=gyro_threshold, mag_columns=mag_columns,
                    mag_threshold=mag_threshold, holdoff_samples=holdoff_samples)
    seg = _Segmenter(**opts)
    nw = arr.shape[0] // opts["window"]
    seg.feed(arr[: nw * opts["window"]])
    seg.finish()
    return _result(seg)


def _result(seg: _Segmenter) -> PoseDetection:
    pts = np.asarray(seg.points, dtype=np.float64).reshape(-1, 3)
    pts.setflags(write=False)
    return PoseDetection(
        points=pts,
        poses=list(seg.poses),
        rejected=list(seg.rejected),
        threshold=seg.threshold,
        window=seg.window,
        thresholds=seg.thresholds,
    )


class PoseDetector:
    """Online version of :func:`detect_poses`: feed samples as they arrive.

    Takes the same options as :func:`detect_poses`. State (the partial window, the previous
    window mean, the learnt thresholds, the open still run, the registered poses) carries
    across calls, and the poses are the same as :func:`detect_poses` finds on the
    concatenated samples, however the stream is cut.

    Examples
    --------
    >>> import numpy as np, triaxcal as tc
    >>> det = tc.PoseDetector(window=25, max_windows=4)
    >>> det.update(np.tile([[0.0, 0.0, 1.0]], (90, 1)))
    []
    >>> [(p.start, p.end) for p in det.update(np.tile([[0.0, 0.0, 1.0]], (20, 1)))]
    [(25, 100)]
    """

    def __init__(
        self,
        *,
        window: int = 25,
        threshold: float | None = None,
        units_per_g: float = 1.0,
        min_separation: float | None = None,
        min_windows: int = 2,
        max_std: float | None = None,
        max_windows: int | None = None,
        columns: Sequence[int] = (0, 1, 2),
        gyro_columns: Sequence[int] | None = None,
        gyro_threshold: float | None = None,
        mag_columns: Sequence[int] | None = None,
        mag_threshold: float | None = None,
        holdoff_samples: int = 0,
    ) -> None:
        self._opts = _options(window, threshold, units_per_g, min_separation, min_windows,
                              max_std, max_windows, columns, gyro_columns=gyro_columns,
                              gyro_threshold=gyro_threshold, mag_columns=mag_columns,
                              mag_threshold=mag_threshold, holdoff_samples=holdoff_samples)
        self._seg = _Segmenter(**self._opts)
        self._buf: np.ndarray | None = None
        self._n_channels: int | None = None
        self.n_samples = 0

    def update(self, samples: Any) -> list[Pose]:
        """Add samples (shape (n, K), n may be 0); return the poses registered by them."""
        arr = _as_samples(samples)
        if self._n_channels is None and arr.shape[0]:
            used = [c for key in ("columns", "gyro_columns", "mag_columns")
                    for c in (self._opts[key] or ())]
            if not all(0 <= c < arr.shape[1] for c in used):
                raise CalibrationError(
                    f"channels {tuple(used)} out of range for {arr.shape[1]} channels"
                )
            self._n_channels = arr.shape[1]
        elif arr.shape[0] and arr.shape[1] != self._n_channels:
            raise CalibrationError(
                f"samples have {arr.shape[1]} channels, earlier ones had {self._n_channels}"
            )
        if arr.shape[0] == 0:
            return []
        self.n_samples += arr.shape[0]
        if self._buf is not None and self._buf.shape[0]:
            arr = np.vstack([self._buf, arr])
        w = self._opts["window"]
        nw = arr.shape[0] // w
        self._buf = arr[nw * w:].copy()
        return self._seg.feed(arr[: nw * w])

    def finish(self) -> list[Pose]:
        """End of stream: decide on the still run in progress (it may register a pose)."""
        return self._seg.finish()

    @property
    def still(self) -> bool:
        """Whether the sensor is still now (a still run is open)."""
        return self._seg.run_len >= 2

    @property
    def poses(self) -> list[Pose]:
        """All poses registered so far (with ``max_windows``, a pose's mean grows to its whole
        run once the board moves)."""
        return list(self._seg.poses)

    @property
    def rejected(self) -> list[Rejection]:
        """All rejected candidates so far."""
        return list(self._seg.rejected)

    @property
    def points(self) -> np.ndarray:
        """Pose means of the accelerometer channels so far, shape (M, 3)."""
        return np.asarray(self._seg.points, dtype=np.float64).reshape(-1, 3)

    @property
    def thresholds(self) -> dict[str, float | None]:
        """Each sensor's threshold so far (``None`` while a learnt one is not known yet)."""
        return self._seg.thresholds

    def result(self) -> PoseDetection:
        """A :class:`PoseDetection` of everything so far (without finishing the open run)."""
        return _result(self._seg)


# --- variance detector (imu_tk / Tedaldi et al. 2014) ----------------------------------------


@dataclass(frozen=True)
class StillDetection:
    """The result of :func:`detect_still`.

    Attributes
    ----------
    intervals : list of (int, int)
        Still intervals as (start, end) sample indices, end exclusive.
    rejected : list of Rejection
        Still runs shorter than ``min_duration_s`` ("too short").
    rest_level : float
        ``|var|`` over the rest period: the norm of the per-axis variances, in input units^2.
    threshold : float
        ``k * rest_level``: a sample is still when ``|var|`` over its window is below this.
    level : ndarray, shape (N,)
        ``|var|`` over the window centred on each sample.
    """

    intervals: list[tuple[int, int]]
    rejected: list[Rejection]
    rest_level: float
    threshold: float
    level: np.ndarray


def _sliding_var_norm(x: np.ndarray, w: int) -> np.ndarray:
    """Norm of the per-axis variance over a centred window of ``w`` samples, per sample."""
    n = x.shape[0]
    c = x - x.mean(axis=0)
    z = np.zeros((1, x.shape[1]))
    c1 = np.vstack([z, np.cumsum(c, axis=0)])
    c2 = np.vstack([z, np.cumsum(c * c, axis=0)])
    s1 = c1[w:] - c1[:-w]
    s2 = c2[w:] - c2[:-w]
    var = np.maximum(s2 / w - (s1 / w) ** 2, 0.0)  # (n - w + 1, 3): window starting at i
    lv = np.sqrt((var * var).sum(axis=1))
    half = w // 2
    idx = np.clip(np.arange(n) - half, 0, n - w)
    return lv[idx]


def detect_still(
    samples: Any,
    *,
    rate_hz: float,
    window_s: float = 1.0,
    rest_s: float = 3.0,
    k: float = 3.0,
    min_duration_s: float = 1.0,
    rest_level: float | None = None,
) -> StillDetection:
    """Variance detector with a noise floor learned from an initial rest (imu_tk).

    For each sample, ``|var|`` is the norm of the three per-axis variances over a window of
    ``window_s`` seconds centred on it; the rest level is the same norm over the first
    ``rest_s`` seconds (the sensor must lie still there). Samples with ``|var| < k * rest
    level`` are still; runs of still samples of at least ``min_duration_s`` are returned.

    Parameters
    ----------
    samples : array_like, shape (N, 3) (or (N, K): the first three channels are used)
        Accelerometer readings (any units), or gyro readings for constant-rate detection.
    rate_hz : float
        Sampling rate, Hz.
    window_s : float
        Sliding-window length, s (imu_tk: 1-2 s).
    rest_s : float
        Length of the initial rest period, s.
    k : float
        Threshold multiplier (imu_tk sweeps 1..10).
    min_duration_s : float
        Shortest still interval kept, s; shorter ones are rejected as "too short".
    rest_level : float, optional
        Use this noise floor (input units^2) instead of learning it from the first ``rest_s``.

    Returns
    -------
    StillDetection
    """
    arr = _as_samples(samples, allow_empty=False)[:, :3]
    rate = opt.number(rate_hz, "rate_hz", gt=0, hint="the sampling rate in Hz")
    win_s = opt.number(window_s, "window_s", gt=0, hint="seconds, imu_tk uses 1-2")
    rest_len = opt.number(rest_s, "rest_s", gt=0, hint="seconds of initial rest")
    kk = opt.number(k, "k", gt=0, hint="threshold multiplier, imu_tk sweeps 1..10")
    min_dur = opt.number(min_duration_s, "min_duration_s", ge=0, hint="seconds")
    given_rest = opt.optional_number(rest_level, "rest_level", gt=0, hint="input units^2")
    n = arr.shape[0]
    w = round(win_s * rate)
    if w < 2:
        raise CalibrationError(
            f"window_s={win_s:g} s is {win_s * rate:.3g} samples at {rate:g} Hz; a variance "
            "needs a window of at least 2 samples: pass a longer window_s"
        )
    if w > n:
        raise CalibrationError(
            f"only {n} samples, fewer than one {win_s:g} s window ({w} samples); record longer"
        )
    if given_rest is None:
        nr = round(rest_len * rate)
        if nr < w:
            raise CalibrationError(
                f"rest_s={rest_len:g} s ({nr} samples) is shorter than the window ({w} samples); "
                "record a longer initial rest or pass rest_level"
            )
        if nr > n:
            raise CalibrationError(
                f"rest_s={rest_len:g} s needs {nr} samples, only {n} recorded"
            )
        rv = arr[:nr].var(axis=0)
        rest = float(np.sqrt((rv * rv).sum()))
        if not (np.isfinite(rest) and rest > 0):
            rest = np.finfo(float).tiny  # a perfectly constant rest (simulated data)
    else:
        rest = given_rest
    thr = kk * rest
    level = _sliding_var_norm(arr, w)
    still = level < thr
    edges = np.flatnonzero(np.diff(np.concatenate(([0], still.astype(np.int8), [0]))))
    starts, ends = edges[0::2], edges[1::2]
    min_n = round(min_dur * rate)
    intervals: list[tuple[int, int]] = []
    rejected: list[Rejection] = []
    for a, b in zip(starts.tolist(), ends.tolist()):
        if b - a >= max(min_n, 1):
            intervals.append((a, b))
        else:
            rejected.append(
                Rejection(a, b, TOO_SHORT, f"{(b - a) / rate:.3g} s < {min_dur:g} s")
            )
    level.setflags(write=False)
    return StillDetection(intervals, rejected, rest, thr, level)


def still_intervals(
    samples: Any,
    *,
    rate_hz: float,
    window_s: float = 1.0,
    rest_s: float = 3.0,
    k: float = 3.0,
    min_duration_s: float = 1.0,
) -> list[tuple[int, int]]:
    """Still intervals as (start, end) sample indices, end exclusive (see :func:`detect_still`).

    Examples
    --------
    >>> import numpy as np, triaxcal as tc
    >>> rng = np.random.default_rng(1)
    >>> x = rng.normal(0, 0.01, (1000, 3)); x[400:600] += rng.normal(0, 0.5, (200, 3))
    >>> tc.still_intervals(x, rate_hz=100, rest_s=2.0)  # doctest: +SKIP
    [(0, 350), (650, 1000)]
    """
    return detect_still(
        samples, rate_hz=rate_hz, window_s=window_s, rest_s=rest_s, k=k,
        min_duration_s=min_duration_s,
    ).intervals
