"""A simulated wrist-worn accelerometer recording free-living days, generated in chunks.

Error model (the one :func:`triaxcal.autocalibrate` fits, van Hees et al. 2014): for a true
specific force ``a`` (g, body frame) and temperature ``T`` (degC) the device reports

    y = a / gain + offset + temp_coef * (T - temp_ref_c) + noise,   rounded to ``resolution_g``

so ``(y - offset(T)) * gain`` gives ``a`` back (``gain`` **multiplies**).

The days alternate, at random, between still bouts (sleep, sitting, the device on a table:
gravity alone, in an orientation drawn uniformly on the sphere) and moving bouts (the wrist
turning at 0.2-1.5 rad/s about a random axis plus a 0.5-3 Hz oscillation of 0.05-0.5 g). The
temperature follows a daily cycle (26-33 degC) with slower and faster wobbles. Everything is
drawn from ``seed``; :meth:`FreeLivingSim.chunks` generates any stretch on demand, so a week at
100 Hz (60 million samples, 1.4 GB as float64) never has to be held in memory.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._checks.options import seed as seed_of
from ..errors import CalibrationError

__all__ = ["FreeLivingSim", "WearableTruth"]


@dataclass(frozen=True)
class WearableTruth:
    """The true calibration of a :class:`FreeLivingSim` device.

    ``offset`` (3,) g at ``temp_ref_c``; ``gain`` (3,) multiplies; ``temp_coef`` (3,) g per
    degC; ``noise_g`` white noise per axis (g rms); ``resolution_g`` quantisation step (g).
    """

    offset: np.ndarray
    gain: np.ndarray
    temp_coef: np.ndarray
    temp_ref_c: float
    noise_g: float
    resolution_g: float

    def offset_at(self, temp_c: float) -> np.ndarray:
        """Offset in g at ``temp_c`` degC."""
        return self.offset + self.temp_coef * (float(temp_c) - self.temp_ref_c)

    def apply(self, y: Any, temp_c: Any) -> np.ndarray:
        """The true correction of readings ``y`` (N, 3) g at temperatures ``temp_c`` (N,)."""
        t = np.asarray(temp_c, dtype=np.float64).reshape(-1, 1)
        return (np.asarray(y, dtype=np.float64) - self.offset
                - (t - self.temp_ref_c) * self.temp_coef) * self.gain


class FreeLivingSim:
    """Free-living recordings with known calibration errors, generated chunk by chunk.

    Parameters
    ----------
    seed : int
        Draws the truth (unless given), the day's schedule and the noise.
    days : float
        Length of the recording.
    rate_hz : float
        Samples per second.
    offset, gain, temp_coef : array_like (3,), optional
        The truth; defaults drawn: offsets 5-60 mg, gains 1 +- 3 %, drift 0.3-1.5 mg/degC
        (each with a random sign).
    temp_ref_c : float
        Temperature at which ``offset`` holds.
    noise_g, resolution_g : float
        Noise (g rms, default 4 mg) and quantisation step (default 1/256 g, a 13-bit +-16 g
        or 12-bit +-8 g device).
    still_fraction : float
        Share of the time spent still (default 0.45).

    Examples
    --------
    >>> sim = FreeLivingSim(seed=1, days=0.01, rate_hz=50)
    >>> acc, temp = next(sim.chunks(chunk_s=60))
    >>> acc.shape, temp.shape, sim.n_samples
    ((3000, 3), (3000,), 43200)
    """

    def __init__(
        self,
        seed: int = 0,
        *,
        days: float = 7.0,
        rate_hz: float = 100.0,
        offset: Any = None,
        gain: Any = None,
        temp_coef: Any = None,
        temp_ref_c: float = 29.0,
        noise_g: float = 0.004,
        resolution_g: float = 1.0 / 256.0,
        still_fraction: float = 0.45,
    ) -> None:
        if not (days > 0 and rate_hz > 0 and 0 < still_fraction < 1):
            raise CalibrationError("days and rate_hz must be > 0, still_fraction in (0, 1)")
        self.seed = seed_of(seed)
        self.days = float(days)
        self.rate_hz = float(rate_hz)
        rng = np.random.default_rng([self.seed, 0xA0C])
        sign = rng.choice([-1.0, 1.0], (3, 3))
        draw_off = rng.uniform(0.005, 0.060, 3) * sign[0]
        draw_gain = 1.0 + rng.uniform(-0.03, 0.03, 3)
        draw_tc = rng.uniform(0.0003, 0.0015, 3) * sign[1]
        self.truth = WearableTruth(
            offset=_vec(offset, draw_off, "offset"),
            gain=_vec(gain, draw_gain, "gain"),
            temp_coef=_vec(temp_coef, draw_tc, "temp_coef"),
            temp_ref_c=float(temp_ref_c),
            noise_g=float(noise_g),
            resolution_g=float(resolution_g),
        )
        self.n_samples = int(round(self.days * 86400.0 * self.rate_hz))
        # the schedule: alternating still and moving bouts over the whole recording
        total = self.days * 86400.0
        starts, still, t = [], [], 0.0
        is_still = bool(rng.random() < still_fraction)
        mean_still = 20 * 60.0
        mean_move = mean_still * (1 - still_fraction) / still_fraction
        while t < total:
            starts.append(t)
            still.append(is_still)
            t += max(30.0, rng.exponential(mean_still if is_still else mean_move))
            is_still = not is_still
        k = len(starts)
        up = rng.normal(size=(k, 3))
        self._start = np.array(starts)
        self._still = np.array(still)
        self._up = up / np.linalg.norm(up, axis=1, keepdims=True)
        ax = rng.normal(size=(k, 3))
        self._axis = ax / np.linalg.norm(ax, axis=1, keepdims=True)
        self._omega = rng.uniform(0.2, 1.5, k) * rng.choice([-1.0, 1.0], k)
        osc = rng.normal(size=(k, 3))
        self._osc_dir = osc / np.linalg.norm(osc, axis=1, keepdims=True)
        self._osc_amp = rng.uniform(0.05, 0.5, k)
        self._osc_hz = rng.uniform(0.5, 3.0, k)
        self._phase = rng.uniform(0, 2 * math.pi, (k, 3))

    def temperature(self, t_s: Any) -> np.ndarray:
        """Device temperature (degC) at times ``t_s`` (s from the start)."""
        t = np.asarray(t_s, dtype=np.float64)
        day = 2 * math.pi * t / 86400.0
        return 29.5 + 3.0 * np.sin(day + self._phase[0, 0]) + 0.8 * np.sin(
            2 * math.pi * t / 11_700.0 + self._phase[0, 1])

    def true_acc(self, t_s: Any) -> tuple[np.ndarray, np.ndarray]:
        """True specific force (N, 3) in g and the still mask (N,) at times ``t_s`` (s,
        increasing)."""
        t = np.asarray(t_s, dtype=np.float64)
        a = np.empty((len(t), 3))
        still = np.empty(len(t), dtype=bool)
        if not len(t):
            return a, still
        first, last = np.searchsorted(self._start, [t[0], t[-1]], side="right") - 1
        edges = np.searchsorted(t, self._start[first + 1:last + 1])
        for b, lo, hi in zip(range(first, last + 1), np.r_[0, edges], np.r_[edges, len(t)]):
            still[lo:hi] = self._still[b]
            up = self._up[b]
            if self._still[b]:
                a[lo:hi] = up
                continue
            # moving: the gravity direction turns about the bout's axis, plus an oscillation
            tau = t[lo:hi] - self._start[b]
            theta = self._omega[b] * tau
            c, s = np.cos(theta)[:, None], np.sin(theta)[:, None]
            k = self._axis[b]
            turned = c * up + s * np.cross(k, up) + (1 - c) * (k @ up) * k
            osc = (self._osc_amp[b] * np.sin(2 * math.pi * self._osc_hz[b] * tau))[:, None]
            a[lo:hi] = turned + osc * self._osc_dir[b]
        return a, still

    def chunks(self, chunk_s: float = 3600.0, *, start_s: float = 0.0, stop_s: float | None = None
               ) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        """Yield ``(acc (n, 3) g, temp (n,) degC)`` chunks of the readings, in time order."""
        n0 = int(round(start_s * self.rate_hz))
        n1 = self.n_samples if stop_s is None else min(self.n_samples,
                                                       int(round(stop_s * self.rate_hz)))
        step = max(1, int(round(chunk_s * self.rate_hz)))
        tr = self.truth
        for i in range(n0, n1, step):
            j = min(i + step, n1)
            t = np.arange(i, j) / self.rate_hz
            a, _ = self.true_acc(t)
            temp = self.temperature(t)
            rng = np.random.default_rng([self.seed, 0x5EED, i])
            y = a / tr.gain + tr.offset + (temp - tr.temp_ref_c)[:, None] * tr.temp_coef
            y += rng.standard_normal((j - i, 3), dtype=np.float32) * tr.noise_g
            if tr.resolution_g > 0:
                y = np.rint(y / tr.resolution_g) * tr.resolution_g
            yield y, temp


def _vec(value: Any, default: np.ndarray, name: str) -> np.ndarray:
    v = default if value is None else np.broadcast_to(
        np.asarray(value, dtype=np.float64), (3,)).copy()
    if not np.all(np.isfinite(v)):
        raise CalibrationError(f"{name} must be 3 finite numbers")
    v = np.array(v, dtype=np.float64)
    v.setflags(write=False)
    return v
