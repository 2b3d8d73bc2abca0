"""MotionCal's four quality numbers, and the bounded buffer of well-spread samples.

PJRC MotionCal (``quality.c``, ``gui.cpp``) judges a magnetometer calibration by four numbers
computed on the *calibrated* points of its 650-sample buffer, all in percent:

* **gaps**: the sphere is cut into 100 regions of equal area (a polar cap of 1 region above
  78.52 deg latitude, a temperate zone of 15 regions down to 42.84 deg, a tropical zone of 34
  regions down to the equator, and the same mirrored south); each empty region adds 1, a
  region with one point 0.2, with two points 0.01;
* **variance**: standard deviation of the calibrated magnitudes over their mean, x 100;
* **wobble**: the mean, over the occupied regions, of (centroid of the region's points minus
  the region's ideal centre on a sphere of the mean magnitude), as a length over that
  magnitude, x 100 -- how far the cloud sits off centre;
* **fit error**: the fit's residual, x 100 of the field. MotionCal takes Freescale's
  algebraic residual ``50 sqrt(mean((|c|^2 - B^2)^2)) / B^2``, which to first order is
  ``100 rms(|c| - B) / B``; here it is that geometric form, from the same readings.

MotionCal enables its "Send Cal" button when gaps < 15, variance < 4.5, wobble < 4 and fit
error < 5 (:data:`MOTIONCAL_LIMITS`). Its ideal centres of the southern temperate regions are
taken from the wrong sectors (``i - 1`` for ``i - 84``); this module uses the intended ones,
which gives the same wobble whenever a whole ring of regions is occupied.

:class:`SpreadBuffer` keeps at most ``capacity`` samples of a stream, well spread over the
sphere: a sample is accepted only if it lies farther than ArduPilot's minimum distance
(``CompassCalibrator::accept_sample``: ``2 R sin(theta / 2)`` for the spacing ``theta`` of
``capacity`` points on a sphere of radius ``R``) from every sample kept; once full, it replaces
one of the two closest samples (MotionCal's ``choose_discard_magcal``), or now and then, when
the gaps are small, the sample farthest from the fitted sphere. Memory stays
``capacity x capacity`` distances however long the stream runs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import CalibrationError

__all__ = [
    "MOTIONCAL_LIMITS",
    "biggest_empty_cap",
    "MotionCalQuality",
    "SpreadBuffer",
    "min_sample_distance",
    "motioncal_quality",
    "motioncal_regions",
]

#: MotionCal's limits (``gui.cpp``): every number below its limit means "good".
MOTIONCAL_LIMITS = {"gaps": 15.0, "variance": 4.5, "wobble": 4.0, "fit_error": 5.0}

_LAT_CAP = 1.37046  # 78.52 deg: polar caps of one region
_LAT_TEMPERATE = 0.74776  # 42.84 deg: temperate zones of 15 regions, tropics of 34
_LAT_MID_TEMPERATE = 1.05911  # centre latitudes of the zones (MotionCal's sphereideal)
_LAT_MID_TROPIC = 0.37388


def motioncal_regions(points: Any) -> np.ndarray:
    """MotionCal's region (0..99, equal area) of each direction in ``points`` (N, 3).

    Examples
    --------
    >>> motioncal_regions([[0, 0, 1], [0, 0, -1], [1, 0, 0]]).tolist()
    [0, 99, 33]
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    lon = np.arctan2(y, x) + math.pi  # 0 .. 2 pi
    lat = math.pi / 2 - np.arctan2(np.hypot(x, y), z)  # -pi/2 .. pi/2
    temperate = np.clip(np.floor(lon * 15.0 / (2 * math.pi)), 0, 14).astype(np.int64)
    tropic = np.clip(np.floor(lon * 34.0 / (2 * math.pi)), 0, 33).astype(np.int64)
    region = np.where(lat >= 0.0, tropic + 16, tropic + 50)
    region = np.where(np.abs(lat) > _LAT_TEMPERATE,
                      np.where(lat > 0.0, temperate + 1, temperate + 84), region)
    region = np.where(lat > _LAT_CAP, 0, region)
    return np.where(lat < -_LAT_CAP, 99, region)


def _ideal_centres() -> np.ndarray:
    c = np.zeros((100, 3))
    c[0] = (0.0, 0.0, 1.0)
    c[99] = (0.0, 0.0, -1.0)
    for first, count, lat in ((1, 15, _LAT_MID_TEMPERATE), (16, 34, _LAT_MID_TROPIC),
                              (50, 34, -_LAT_MID_TROPIC), (84, 15, -_LAT_MID_TEMPERATE)):
        lon = (np.arange(count) + 0.5) * 2 * math.pi / count
        # region longitudes run from -X (atan2 + pi), hence the minus signs
        c[first:first + count] = np.column_stack(
            [-np.cos(lon) * math.cos(lat), -np.sin(lon) * math.cos(lat),
             np.full(count, math.sin(lat))])
    return c


_IDEAL = _ideal_centres()


@dataclass(frozen=True)
class MotionCalQuality:
    """MotionCal's four numbers (percent) for calibrated points; see the module docstring.

    ``ok`` maps each name to whether it is below its limit in :data:`MOTIONCAL_LIMITS`;
    ``good`` is True when all four are (MotionCal would enable "Send Cal").
    """

    gaps: float
    variance: float
    wobble: float
    fit_error: float
    n: int

    @property
    def ok(self) -> dict[str, bool]:
        return {k: bool(getattr(self, k) < lim) for k, lim in MOTIONCAL_LIMITS.items()}

    @property
    def good(self) -> bool:
        return all(self.ok.values())


def motioncal_quality(calibrated: Any, radius: float | None = None) -> MotionCalQuality:
    """MotionCal's gaps, variance, wobble and fit error (percent) of calibrated points.

    Parameters
    ----------
    calibrated : array_like (N, 3)
        Calibrated readings (any unit): ``(raw - offset) @ matrix.T``.
    radius : float, optional
        The fitted field magnitude, for the fit error (default: the mean magnitude).

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> u = rng.normal(size=(650, 3)); u /= np.linalg.norm(u, axis=1, keepdims=True)
    >>> q = motioncal_quality(50 * u, 50.0)
    >>> q.gaps < 15, round(q.variance, 3), q.wobble < 4, round(q.fit_error, 3), q.good
    (True, 0.0, True, 0.0, True)
    """
    c = np.asarray(calibrated, dtype=np.float64).reshape(-1, 3)
    n = len(c)
    if n == 0:
        return MotionCalQuality(100.0, 100.0, 100.0, 100.0, 0)
    mag = np.linalg.norm(c, axis=1)
    region = motioncal_regions(c)
    counts = np.bincount(region, minlength=100)
    gaps = float(np.sum(np.where(counts == 0, 1.0, np.where(counts == 1, 0.2,
                                                              np.where(counts == 2, 0.01, 0.0)))))
    mean = float(mag.mean())
    if not mean > 0:
        return MotionCalQuality(gaps, 100.0, 100.0, 100.0, n)
    variance = float(mag.std()) / mean * 100.0
    sums = np.zeros((100, 3))
    np.add.at(sums, region, c)
    occ = counts > 0
    off = (sums[occ] / counts[occ, None] - _IDEAL[occ] * mean).mean(axis=0)
    wobble = float(np.linalg.norm(off)) / mean * 100.0
    r = float(radius) if radius is not None and radius > 0 else mean
    fit_error = float(np.sqrt(np.mean((mag - r) ** 2))) / r * 100.0
    return MotionCalQuality(gaps, variance, wobble, fit_error, n)


def _fibonacci(n: int) -> np.ndarray:
    i = np.arange(n) + 0.5
    z = 1.0 - 2.0 * i / n
    r = np.sqrt(1.0 - z * z)
    phi = i * math.pi * (3.0 - math.sqrt(5.0))
    return np.column_stack([r * np.cos(phi), r * np.sin(phi), z])


_COARSE = _fibonacci(600)


def _cap_around(c: np.ndarray, deg: float, n: int) -> np.ndarray:
    """``n`` directions spread over the cap of angular radius ``deg`` around unit ``c``."""
    i = np.arange(n) + 0.5
    cos_t = 1.0 - (1.0 - math.cos(math.radians(deg))) * i / n
    sin_t = np.sqrt(1.0 - cos_t**2)
    phi = i * math.pi * (3.0 - math.sqrt(5.0))
    a = np.array([1.0, 0.0, 0.0]) if abs(c[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(c, a)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(c, e1)
    return (cos_t[:, None] * c + sin_t[:, None] * (np.cos(phi)[:, None] * e1
                                                   + np.sin(phi)[:, None] * e2))


def biggest_empty_cap(directions: Any) -> tuple[np.ndarray, float] | None:
    """The largest cap of the sphere holding none of ``directions`` (N, 3; any lengths):
    ``(centre unit vector, angular radius in degrees)``, or ``None`` without directions.

    The direction farthest from every reading, as :func:`triaxcal.report.empty_regions`
    finds it, searched on a coarse grid (600 directions, 8 deg apart) and refined twice
    around the best one, to about a degree, at a fifth of the cost (for the live loop).

    Examples
    --------
    >>> import numpy as np
    >>> c, deg = biggest_empty_cap([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, -1]])
    >>> (np.round(c, 2) + 0.0).tolist(), round(deg)
    ([0.0, 0.0, 1.0], 90)
    """
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    n = np.linalg.norm(d, axis=1)
    d = d[n > 0] / n[n > 0, None]
    if not len(d):
        return None
    dt = np.ascontiguousarray(d.T)
    best = _COARSE[int(np.argmin((_COARSE @ dt).max(axis=1)))]
    for radius in (6.0, 1.5):
        cand = np.vstack([best, _cap_around(best, radius, 120)])
        best = cand[int(np.argmin((cand @ dt).max(axis=1)))]
    near = float(np.max(d @ best))
    return best, math.degrees(math.acos(min(1.0, max(-1.0, near))))


def min_sample_distance(radius: float, capacity: int) -> float:
    """ArduPilot's smallest distance between kept samples for ``capacity`` of them on a
    sphere of ``radius``: ``2 R sin(theta / 2)``, ``theta`` the spacing of the vertices of a
    geodesic sphere with ``2 capacity - 4`` faces.

    >>> round(min_sample_distance(1.0, 300), 4), round(min_sample_distance(1.0, 650), 4)
    (0.1099, 0.0747)
    """
    faces = 2 * int(capacity) - 4
    a = 4.0 * math.pi / (3.0 * faces) + math.pi / 3.0
    theta = 0.5 * math.acos(math.cos(a) / (1.0 - math.cos(a)))
    return float(radius) * 2.0 * math.sin(theta / 2.0)


class SpreadBuffer:
    """At most ``capacity`` well-spread samples of a stream of 3-vectors (see the module).

    Parameters
    ----------
    capacity : int
        Most samples kept (MotionCal: 650; ArduPilot: 300).
    seed : int
        Seed of the coin that picks which of the two closest samples goes.

    Examples
    --------
    >>> import numpy as np
    >>> buf = SpreadBuffer(50)
    >>> rng = np.random.default_rng(1)
    >>> for _ in range(40):
    ...     u = rng.normal(size=(100, 3))
    ...     _ = buf.add(500 * u / np.linalg.norm(u, axis=1, keepdims=True))
    >>> len(buf), buf.version > 0
    (50, True)
    """

    def __init__(self, capacity: int = 650, *, seed: int = 0) -> None:
        if isinstance(capacity, bool) or not isinstance(capacity, int) or capacity < 10:
            raise CalibrationError(f"capacity must be a whole number >= 10, got {capacity!r}")
        self.capacity = capacity
        self._p = np.zeros((capacity, 3))
        self._sq = np.zeros(capacity)  # |p|^2 of each slot
        self._d = np.full((capacity, capacity), np.inf)  # pairwise distances
        self._nn = np.full(capacity, np.inf)  # distance to the nearest other sample
        self.n = 0
        self.version = 0  # bumped on every change
        self.radius: float | None = None  # raw-unit radius for the spacing (set by the fit)
        self._fit: tuple[np.ndarray, np.ndarray, float] | None = None
        self._purge_every = 0.0
        self._since_purge = 0
        self._rng = np.random.default_rng([seed, 650])

    def __len__(self) -> int:
        return self.n

    @property
    def points(self) -> np.ndarray:
        """A copy of the samples kept, (n, 3), in the order of their slots."""
        return self._p[: self.n].copy()

    def set_fit(self, offset: Any, matrix: Any, radius: float, gaps: float) -> None:
        """Tell the buffer the current fit: the spacing follows its radius (raw units), and
        while MotionCal's gaps are below 25 every ``10 gaps``-th replacement drops the sample
        farthest from the fitted sphere instead of one of the closest pair."""
        off = np.asarray(offset, dtype=np.float64)
        m = np.asarray(matrix, dtype=np.float64)
        self._fit = (off, m, float(radius))
        if self.n:
            self.radius = float(np.median(np.linalg.norm(self._p[: self.n] - off, axis=1)))
        self._purge_every = 10.0 * max(gaps, 1.0) if gaps < 25.0 else 0.0

    def clear(self) -> None:
        """Forget every sample (the fit's radius is kept)."""
        self.n = 0
        self._d.fill(np.inf)
        self._nn.fill(np.inf)
        self._fit = None
        self._purge_every = 0.0
        self.version += 1

    def _spacing(self, batch: np.ndarray) -> float:
        if self.radius is None:
            # before a fit: the raw magnitude, right in order of size when the offset is
            # smaller than the field (ArduPilot starts from a nominal field in the same way)
            self.radius = float(np.median(np.linalg.norm(batch, axis=1)))
        return min_sample_distance(self.radius, self.capacity)

    def _put(self, slot: int, p: np.ndarray) -> None:
        n = max(self.n, slot + 1)
        self._p[slot] = p
        self._sq[slot] = float(p @ p)
        row = np.sqrt(np.maximum(self._sq[:n] - 2.0 * (self._p[:n] @ p) + self._sq[slot], 0.0))
        row[slot] = np.inf
        old = self._d[slot, :n].copy()
        self._d[slot, :n] = row
        self._d[:n, slot] = row
        self._nn[slot] = row.min() if n > 1 else np.inf
        closer = row < self._nn[:n]
        self._nn[:n][closer] = row[closer]
        # rows whose nearest neighbour was the sample just replaced: look again
        lost = np.flatnonzero(~closer & (old <= self._nn[:n] + 1e-12) & np.isfinite(old))
        for i in lost:
            if i != slot:
                self._nn[i] = self._d[i, :n].min()

    def _victim(self) -> int:
        if self._purge_every and self._fit is not None:
            self._since_purge += 1
            if self._since_purge > self._purge_every:
                self._since_purge = 0
                off, m, r = self._fit
                res = np.abs(np.linalg.norm((self._p - off) @ m.T, axis=1) - r)
                return int(np.argmax(res))
        i = int(np.argmin(self._nn))
        j = int(np.argmin(self._d[i]))
        return i if self._rng.random() < 0.5 else j

    def add(self, points: Any, *, max_accept: int = 32) -> int:
        """Offer samples (n, 3); returns how many were kept (at most ``max_accept``)."""
        batch = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        batch = batch[np.isfinite(batch).all(axis=1)]
        if not len(batch):
            return 0
        dmin = self._spacing(batch)
        if self.n:
            n = self.n
            d2 = ((batch * batch).sum(axis=1)[:, None] + self._sq[None, :n]
                  - 2.0 * (batch @ self._p[:n].T))
            cand = np.flatnonzero(d2.min(axis=1) > dmin * dmin)
        else:
            cand = np.arange(len(batch))
        if not len(cand):
            return 0
        c = batch[cand]
        # greedy thinning of the batch itself: consecutive samples lie close together
        pd2 = ((c[:, None, :] - c[None, :, :]) ** 2).sum(axis=2)
        alive = np.ones(len(c), dtype=bool)
        taken: list[int] = []
        for k in range(len(c)):
            if alive[k]:
                taken.append(k)
                alive &= pd2[k] > dmin * dmin
                if len(taken) >= max_accept:
                    break
        for k in taken:
            if self.n < self.capacity:
                self.n += 1
                self._put(self.n - 1, c[k])
            else:
                self._put(self._victim(), c[k])
        if taken:
            self.version += 1
        return len(taken)
