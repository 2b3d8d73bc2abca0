"""The pose detector's state machine: windows, steady runs, registered poses (one
implementation for :func:`~triaxcal.detect.detect_poses` and
:class:`~triaxcal.detect.PoseDetector`)."""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._checks.arrays import as_samples
from ..errors import CalibrationError

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
#: When the gyroscope stays steady for this many windows in a row at a rate that differs from
#: the bias by less than :data:`REANCHOR_MAX` thresholds (it drifted while the board moved),
#: that rate becomes the new bias; a larger steady rate is a turn at constant speed and stays
#: motion.
#:
#: The first bias is provisional: it is taken from the first windows the accelerometer calls
#: steady, before the gyroscope's threshold is known, and a twist about the vertical at the
#: start of a recording looks steady to the accelerometer. It is confirmed when the board
#: comes back to rest at it after a move. Until then, this many steady windows off it that
#: agree with one another (within the threshold), after at least two different moves, replace
#: it however far they lie from it, and are confirmed: coming back to one rate after different
#: moves is the sign of rest that the provisional bias lacks (turns by hand do not repeat a
#: speed to a few tenths of a degree a second), and windows in a row would need poses longer
#: than a calibration's usual 1 s.
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
        self.moves = 0  # moves seen so far (and hold-offs, in which the board may have moved)
        self.bias_moves = 0  # moves seen when the bias was first taken or last replaced
        self.bias_sure = False  # the board came to rest at the bias again after a move
        # provisional bias only: rates of recent steady windows off it, with the moves seen then
        self.off_bias: deque[tuple[np.ndarray, int]] = deque(maxlen=4 * REANCHOR_WINDOWS)
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
                self.moves += 1
                i += 1
                continue
            if not steady[i]:
                # motion: close any open run; the last moving window may open the next run
                self.rate_fail = 0
                self.moves += 1
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
                    if not self.bias_sure and self._rest_again(g, gyro_thr[i]):
                        pass  # the provisional bias is replaced
                    elif self.rate_fail >= REANCHOR_WINDOWS and \
                            away <= REANCHOR_MAX * gyro_thr[i]:
                        # steady for a while, a little off: the bias moved, follow it
                        self.gyro_hist.clear()
                        self.gyro_hist.append(g)
                        self.rate_fail = 0
                        self.bias_moves = self.moves
                    self._open(k)  # still turning: this window opens the run instead
                    i += 1
                    continue
                if not self.bias_sure and away <= gyro_thr[i] and self.moves > self.bias_moves:
                    self.bias_sure = True  # at rest at the bias again after a move
                    self.off_bias.clear()
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
                    self._keep_rates(means[max(i, i + take - BIAS_WINDOWS):i + take, gcols])
                if self.skip_until > k + take - 1:
                    i += take
                    continue
                self._extend(cs1[j] - cs1[i + take], cs2[j] - cs2[i + take], (j - i) - take)
            else:
                self._extend(cs1[j] - cs1[i], cs2[j] - cs2[i], j - i)
            if gcols is not None:
                self._keep_rates(means[max(i, j - BIAS_WINDOWS):j, gcols])
            i = j
        return new

    def _keep_rates(self, rates: np.ndarray) -> None:
        """The gyroscope's rates over still windows: the bias is their median."""
        if not self.gyro_hist and len(rates):
            self.bias_moves = self.moves  # the first bias, provisional
        self.gyro_hist.extend(rates)

    def _rest_again(self, g: np.ndarray, thr: float) -> bool:
        """A steady window at rate ``g`` is off the provisional bias: when
        :data:`REANCHOR_WINDOWS` such windows, after at least two different moves, agree with
        it, their rate becomes the (confirmed) bias."""
        self.off_bias.append((g.copy(), self.moves))
        near = [(r, m) for r, m in self.off_bias if float(np.abs(r - g).max()) <= thr]
        if len(near) < REANCHOR_WINDOWS or len({m for _, m in near}) < 2:
            return False
        self.gyro_hist.clear()
        self.gyro_hist.extend(r for r, _ in near[-BIAS_WINDOWS:])
        self.rate_fail = 0
        self.bias_moves = self.moves
        self.bias_sure = True
        self.off_bias.clear()
        return True

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
