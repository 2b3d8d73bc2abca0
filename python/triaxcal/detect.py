"""Stationary detection: find the still poses in a stream of three-axis readings.

Two detectors, both vectorised over numpy arrays (millions of samples per second):

* :func:`detect_poses` / :class:`PoseDetector` -- the seed method (sphere-center-descent.txt):
  average consecutive windows of ``window`` samples; a window is *steady* when every axis of
  its mean changed by at most ``threshold`` from the previous window's mean. A run of steady
  windows is a candidate pose; its mean is registered as a point unless the candidate is
  rejected as "too short", "too noisy" or "too close to an earlier pose". The offline function
  and the online detector share one state machine, so they register the same poses on the
  same data however the stream is cut into chunks.
* :func:`still_intervals` / :func:`detect_still` -- the variance detector of imu_tk (Tedaldi,
  Pretto, Menegatti, ICRA 2014): the magnitude of the per-axis variance over a sliding window
  of ``window_s`` seconds is compared with ``k`` times the same quantity measured over an
  initial rest period of ``rest_s`` seconds.

Indices are sample indices into the array given (or into the whole stream, online); ``end`` is
exclusive, Python-slice style.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from . import _options as opt
from ._validate import as_samples
from .errors import CalibrationError

__all__ = [
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
        Pose means of the detection channels, ready for :func:`triaxcal.fit_ellipsoid`.
    poses : list of Pose
        The registered poses (means over all channels given).
    rejected : list of Rejection
        Candidates not registered, each with its reason.
    threshold : float
        The steadiness threshold used, in the input's units.
    window : int
        Samples per averaging window.
    """

    points: np.ndarray
    poses: list[Pose]
    rejected: list[Rejection]
    threshold: float
    window: int

    def __len__(self) -> int:
        return len(self.poses)


def _as_samples(samples: Any, name: str = "samples", allow_empty: bool = True) -> np.ndarray:
    arr = as_samples(samples, name, channels="xyz+", finite=True)
    if not allow_empty and arr.shape[0] == 0:
        raise CalibrationError(f"{name} is empty: record some samples first")
    return arr


class _Segmenter:
    """The state machine shared by :func:`detect_poses` and :class:`PoseDetector`.

    Fed per-window statistics (sum and sum of squares of every channel, about a fixed
    reference), it tracks the current run of steady windows and closes it when motion
    resumes (or when it reaches ``max_windows``, or at :meth:`finish`).
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
    ) -> None:
        self.window = window
        self.threshold = threshold
        self.min_windows = min_windows
        self.min_separation = min_separation
        self.max_std = max_std
        self.max_windows = max_windows
        self.columns = columns
        self.ref: np.ndarray | None = None
        self.n_windows = 0  # windows seen so far
        self.prev_mean: np.ndarray | None = None  # detection-channel mean of the last window
        # current run: first window index, window count, accumulated sums
        self.run_first = -1
        self.run_len = 0
        self.run_s1: Any = 0.0
        self.run_s2: Any = 0.0
        self.run_done = False  # registered early (max_windows); ignore until motion
        self.points: list[np.ndarray] = []
        self._pts = np.empty((64, 3))  # the same points as an array, for distance checks
        self.poses: list[Pose] = []
        self.rejected: list[Rejection] = []

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
        means = s1[:, self.columns] / w
        prev = means[:-1]
        if self.prev_mean is not None:
            prev = np.vstack([self.prev_mean[None, :], prev])
            steady = np.abs(means - prev).max(axis=1) <= self.threshold
        else:
            steady = np.empty(nw, dtype=bool)
            steady[0] = False
            steady[1:] = np.abs(means[1:] - prev).max(axis=1) <= self.threshold
        self.prev_mean = means[-1].copy()
        first = self.n_windows
        self.n_windows += nw
        return self._runs(steady, s1, s2, means, first)

    def _runs(
        self, steady: np.ndarray, s1: np.ndarray, s2: np.ndarray, means: np.ndarray, first: int
    ) -> list[Pose]:
        new: list[Pose] = []
        nw = steady.shape[0]
        # boundaries of runs of equal steadiness inside this block (run-length encoding)
        change = np.flatnonzero(np.diff(steady.astype(np.int8))) + 1
        starts = np.concatenate(([0], change))
        ends = np.concatenate((change, [nw]))
        cs1 = np.vstack([np.zeros((1, s1.shape[1])), np.cumsum(s1, axis=0)])
        cs2 = np.vstack([np.zeros((1, s2.shape[1])), np.cumsum(s2, axis=0)])
        for a, b in zip(starts.tolist(), ends.tolist()):
            if not steady[a]:
                # motion: close any open run; window b-1 may open the next run
                if self.run_len:
                    new += self._close()
                # the last moving window is the first window of a possible still run
                self._open(first + b - 1)
                continue
            # steady windows a..b-1 extend the open run (opened by the window before a)
            if self.run_len == 0:  # pragma: no cover - every block opens a run before this
                self._open(first + a - 1)
            if self.run_done:
                self.run_len += b - a
                continue
            if self.max_windows is not None and self.run_len + (b - a) >= self.max_windows:
                take = self.max_windows - self.run_len
                self._extend(cs1[a + take] - cs1[a], cs2[a + take] - cs2[a], take)
                new += self._close(keep_open=True)
                self.run_len += (b - a) - take
            else:
                self._extend(cs1[b] - cs1[a], cs2[b] - cs2[a], b - a)
        return new

    def _open(self, win: int) -> None:
        # the opening window (the last one that differed from its predecessor) may still hold
        # the end of the motion: it counts towards min_windows but not towards the mean
        self.run_first = win
        self.run_len = 1
        self.run_s1 = 0.0
        self.run_s2 = 0.0
        self.run_done = False

    def _extend(self, s1: np.ndarray, s2: np.ndarray, k: int) -> None:
        self.run_s1 = self.run_s1 + s1
        self.run_s2 = self.run_s2 + s2
        self.run_len += k

    def _close(self, keep_open: bool = False) -> list[Pose]:
        """Decide on the open run; register it or record why not."""
        out: list[Pose] = []
        if self.run_done:
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
                dmin = np.inf
                m = len(self.points)
                if m and self.min_separation > 0:
                    d = self._pts[:m] - point
                    dmin = float(np.sqrt(np.min(np.einsum("ij,ij->i", d, d))))
                if dmin < self.min_separation:
                    self.rejected.append(
                        Rejection(start, end, TOO_CLOSE, f"{dmin:.4g} from an earlier pose, "
                                  f"min_separation {self.min_separation:.4g}")
                    )
                else:
                    mean.setflags(write=False)
                    std.setflags(write=False)
                    pose = Pose(start=start, end=end, mean=mean, n=n, std=std)
                    self.points.append(point)
                    if m == self._pts.shape[0]:
                        self._pts = np.vstack([self._pts, np.empty_like(self._pts)])
                    self._pts[m] = point
                    self.poses.append(pose)
                    out.append(pose)
        if keep_open:
            self.run_done = True
        else:
            self.run_len = 0
        return out

    def finish(self) -> list[Pose]:
        if self.run_len:
            return self._close()
        return []


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
    if isinstance(columns, (str, bytes)) or not hasattr(columns, "__len__") or len(columns) != 3:
        raise CalibrationError(f"columns must name 3 channels (x, y, z), got {columns!r}")
    cols = tuple(opt.integer(c, f"columns[{i}]", ge=0) for i, c in enumerate(columns))
    if n_channels is not None and not all(0 <= c < n_channels for c in cols):
        raise CalibrationError(f"columns {cols} out of range for {n_channels} channels")
    return {
        "window": win,
        "threshold": thr,
        "min_windows": min_w,
        "min_separation": sep,
        "max_std": mstd,
        "max_windows": max_w,
        "columns": cols,
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
) -> PoseDetection:
    """Find still poses by the seed's window-average method (offline, vectorised).

    Parameters
    ----------
    samples : array_like, shape (N, K), K >= 3
        Readings, one row per sample; ``columns`` name the three used for detection (the
        accelerometer). Other channels (gyro, magnetometer, temperature) are averaged too and
        appear in :attr:`Pose.mean`.
    window : int
        Samples per averaging window (25 = 0.25 s at 100 Hz).
    threshold : float, optional
        Largest change of any axis of the window mean, from one window to the next, for the
        sensor to count as still, in the input's units. ``None``: ``0.07 * units_per_g``
        (the seed's 0.07 g).
    units_per_g : float
        Input units per g: 1 for g, 9.80665 for m/s^2, 16384 for counts at +-2 g.
    min_separation : float, optional
        Smallest distance (input units, Euclidean) between a new pose and every registered
        one; closer candidates are rejected as "too close to an earlier pose". ``None``:
        ``threshold``; 0 disables the check.
    min_windows : int
        Fewest windows a still run needs (2 = one steady comparison, the seed's rule);
        shorter runs are rejected as "too short".
    max_std : float, optional
        Largest standard deviation of any detection axis about the run's mean (noise plus
        slow drift); noisier runs are rejected as "too noisy". ``None``: ``threshold``.
    max_windows : int, optional
        Register a run as soon as it has this many windows (the seed's beep; the rest of the
        run is ignored until the sensor moves). ``None``: register when the motion resumes,
        averaging the whole run.
    columns : sequence of 3 ints
        Channels used for detection and for :attr:`PoseDetection.points`.

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
    """
    arr = _as_samples(samples)
    opts = _options(window, threshold, units_per_g, min_separation, min_windows, max_std,
                    max_windows, columns, arr.shape[1])
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
    )


class PoseDetector:
    """Online version of :func:`detect_poses`: feed samples as they arrive.

    Takes the same options as :func:`detect_poses`. State (the partial window, the previous
    window mean, the open still run, the registered poses) carries across calls, and the
    poses are the same as :func:`detect_poses` finds on the concatenated samples, however the
    stream is cut.

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
    ) -> None:
        self._opts = _options(window, threshold, units_per_g, min_separation, min_windows,
                              max_std, max_windows, columns)
        self._seg = _Segmenter(**self._opts)
        self._buf: np.ndarray | None = None
        self._n_channels: int | None = None
        self.n_samples = 0

    def update(self, samples: Any) -> list[Pose]:
        """Add samples (shape (n, K), n may be 0); return the poses registered by them."""
        arr = _as_samples(samples)
        if self._n_channels is None and arr.shape[0]:
            self._n_channels = arr.shape[1]
            if not all(0 <= c < arr.shape[1] for c in self._opts["columns"]):
                raise CalibrationError(
                    f"columns {self._opts['columns']} out of range for {arr.shape[1]} channels"
                )
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
        """All poses registered so far."""
        return list(self._seg.poses)

    @property
    def rejected(self) -> list[Rejection]:
        """All rejected candidates so far."""
        return list(self._seg.rejected)

    @property
    def points(self) -> np.ndarray:
        """Pose means of the detection channels so far, shape (M, 3)."""
        return np.asarray(self._seg.points, dtype=np.float64).reshape(-1, 3)

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
