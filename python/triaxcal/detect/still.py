"""The variance detector of imu_tk (Tedaldi, Pretto, Menegatti, ICRA 2014): still intervals
of a stream whose per-axis variance stays below ``k`` times that of an initial rest."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .._checks import options as opt
from ..errors import CalibrationError
from ..quality.bounds import sample_rate
from ._segmenter import TOO_SHORT, Rejection, _as_samples


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
    rate = sample_rate(rate_hz)
    win_s = opt.number(window_s, "window_s", gt=0, hint="seconds, imu_tk uses 1-2")
    rest_len = opt.number(rest_s, "rest_s", gt=0, hint="seconds of initial rest")
    kk = opt.number(k, "k", gt=0, hint="threshold multiplier, imu_tk sweeps 1..10")
    min_dur = opt.number(min_duration_s, "min_duration_s", ge=0, hint="seconds")
    given_rest = opt.optional_number(rest_level, "rest_level", gt=0, hint="input units^2")
    n = arr.shape[0]
    w = opt.samples(win_s, rate, "window_s")
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
        nr = opt.samples(rest_len, rate, "rest_s")
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
    min_n = opt.samples(min_dur, rate, "min_duration_s")
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
