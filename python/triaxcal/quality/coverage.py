"""How much of the sphere of directions a set of readings covers: one measure for every tool.

``triaxcal capture`` (its status line), ``triaxcal demo`` (its summary), ``triaxcal fit`` (its
warning) and ``triaxcal report`` all say "coverage N %" with this measure, so that the same
session gives the same number everywhere.

The measure is the share of :data:`N_CELLS` equal-area cells of the unit sphere that hold at
least one reading's direction. The cells are the *recursive zonal equal area* partition
(Leopardi, "A partition of the unit sphere into regions of equal area and small diameter",
ETNA 25, 2006): a round cap at each pole and collars in between, each collar cut into equal
longitude sectors. By Archimedes' hat-box theorem a collar ``z_lo < z < z_hi`` has area
``2 pi (z_hi - z_lo)``, so every cell is a rectangle of the same area in the cylindrical
equal-area projection (longitude, z) that the report figure draws. The default 24 cells are
about 41 degrees across: the globe scheme (7 latitudes x 12 twists) hits all of them,
six faces of a cube hit 6 (25 %), a level turn (yaw only) hits the 10 cells of the equator's
collar (42 %).

Directions are taken from ``center`` (the origin by default): raw accelerometer counts (whose
offset is small next to 1 g) during a capture, calibrated readings after a fit.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._checks.arrays import as_points
from ..errors import CalibrationError
from .bounds import LOW_COVERAGE_PCT

__all__ = [
    "N_CELLS",
    "Coverage",
    "SphereCells",
    "coverage",
    "coverage_warning",
    "sphere_cells",
    "suggest_turn",
]

#: Number of equal-area cells of the shared coverage measure.
N_CELLS = 24

@dataclass(frozen=True)
class SphereCells:
    """An equal-area partition of the unit sphere into polar caps and collars.

    Attributes
    ----------
    n : int
        Number of cells.
    z_edges : ndarray, shape (C + 1,)
        Heights of the collar boundaries, from ``+1`` (north pole) down to ``-1``.
    sectors : ndarray of int, shape (C,)
        Cells per collar (1 for each polar cap).
    lon0 : ndarray, shape (C,)
        Longitude (radians, from +X towards +Y) where sector 0 of each collar starts; the
        sectors are shifted so that no boundary lies on the +-X or +-Y axis.
    first : ndarray of int, shape (C,)
        Index of sector 0 of each collar; cells are numbered from the north pole down.
    """

    n: int
    z_edges: np.ndarray
    sectors: np.ndarray
    lon0: np.ndarray
    first: np.ndarray

    def index(self, directions: Any) -> np.ndarray:
        """Cell index (0 .. n-1) of each direction (N, 3); the length does not matter."""
        d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
        norm = np.linalg.norm(d, axis=1)
        u = d / np.where(norm > 0, norm, 1.0)[:, None]
        # collar: the first whose lower edge is at or below z
        lower = self.z_edges[1:]
        k = np.searchsorted(-lower, -u[:, 2], side="left")
        k = np.minimum(k, len(self.sectors) - 1)
        m = self.sectors[k]
        lon = np.mod(np.arctan2(u[:, 1], u[:, 0]) - self.lon0[k], 2.0 * math.pi)
        s = np.minimum((lon * m / (2.0 * math.pi)).astype(np.int64), m - 1)
        return self.first[k] + s

    def centres(self) -> np.ndarray:
        """Unit vectors (n, 3) at the centre of each cell (equal-area mid height, mid sector)."""
        out = np.empty((self.n, 3))
        for c, m in enumerate(self.sectors.tolist()):
            z_hi, z_lo = float(self.z_edges[c]), float(self.z_edges[c + 1])
            if m == 1 and (z_hi == 1.0 or z_lo == -1.0):  # a polar cap: its pole
                out[self.first[c]] = (0.0, 0.0, 1.0 if z_hi == 1.0 else -1.0)
                continue
            z = 0.5 * (z_hi + z_lo)
            r = math.sqrt(max(0.0, 1.0 - z * z))
            lon = self.lon0[c] + (np.arange(m) + 0.5) * 2.0 * math.pi / m
            out[self.first[c]:self.first[c] + m] = np.column_stack(
                [r * np.cos(lon), r * np.sin(lon), np.full(m, z)])
        return out

    def rectangles(self) -> list[tuple[float, float, float, float]]:
        """Each cell as ``(lon_lo_deg, lon_hi_deg, z_lo, z_hi)`` in the cylindrical equal-area
        projection, longitudes in -180..180+ degrees (a cell may run past 180); for plots."""
        out = []
        for c, m in enumerate(self.sectors.tolist()):
            for s in range(m):
                lo = math.degrees(float(self.lon0[c])) + 360.0 * s / m
                lo = (lo + 180.0) % 360.0 - 180.0
                out.append((lo, lo + 360.0 / m, float(self.z_edges[c + 1]),
                            float(self.z_edges[c])))
        return out


@functools.lru_cache(maxsize=16)
def sphere_cells(n_cells: int = N_CELLS) -> SphereCells:
    """The equal-area partition of the sphere into ``n_cells`` cells (Leopardi's algorithm).

    Examples
    --------
    >>> cells = sphere_cells(24)
    >>> cells.sectors.tolist()
    [1, 6, 10, 6, 1]
    >>> [round(float(z), 4) for z in cells.z_edges]
    [1.0, 0.9167, 0.4167, -0.4167, -0.9167, -1.0]
    """
    if isinstance(n_cells, bool) or not isinstance(n_cells, (int, np.integer)) or not (
        2 <= n_cells <= 100_000
    ):
        raise CalibrationError(f"n_cells must be a whole number from 2 to 100000, got {n_cells!r}")
    n = int(n_cells)
    if n == 2:
        counts = [1, 1]
    else:
        area = 4.0 * math.pi / n
        cap = 2.0 * math.asin(math.sqrt(1.0 / n))  # polar cap colatitude
        ideal = math.sqrt(area)
        n_collars = max(1, round((math.pi - 2.0 * cap) / ideal))
        fitting = (math.pi - 2.0 * cap) / n_collars
        counts = [1]
        carry = 0.0
        for i in range(n_collars):
            t1, t2 = cap + i * fitting, cap + (i + 1) * fitting
            ideal_cells = 2.0 * math.pi * (math.cos(t1) - math.cos(t2)) / area
            m = round(ideal_cells + carry)
            carry += ideal_cells - m
            counts.append(m)
        counts.append(1)
    cum = np.cumsum(counts)
    z = np.concatenate([[1.0], 1.0 - 2.0 * cum / n])
    z[-1] = -1.0
    sectors = np.array(counts, dtype=np.int64)
    # shift each collar by a quarter sector so that the axes do not lie on a boundary
    lon0 = np.where(sectors > 1, -0.25 * 2.0 * math.pi / np.maximum(sectors, 1), 0.0)
    first = np.concatenate([[0], cum[:-1]]).astype(np.int64)
    for a in (z, sectors, lon0, first):
        a.setflags(write=False)
    return SphereCells(n=n, z_edges=z, sectors=sectors, lon0=lon0, first=first)


@dataclass(frozen=True)
class Coverage:
    """The share of the sphere's equal-area cells hit by a set of directions.

    Attributes
    ----------
    counts : ndarray of int, shape (n_cells,)
        Readings per cell (cells numbered as :class:`SphereCells`).
    cells_hit : int
        Cells with at least one reading.
    n_cells : int
        Number of cells.
    """

    counts: np.ndarray
    cells_hit: int
    n_cells: int

    @property
    def fraction(self) -> float:
        """Share of the cells hit, 0..1."""
        return self.cells_hit / self.n_cells

    @property
    def percent(self) -> float:
        """Share of the cells hit, in %."""
        return 100.0 * self.cells_hit / self.n_cells

    @property
    def empty(self) -> np.ndarray:
        """Indices of the cells without a reading."""
        return np.flatnonzero(self.counts == 0)

    def text(self) -> str:
        """``"coverage 96 % (23 of 24 equal-area cells)"``."""
        return (f"coverage {self.percent:.0f} % ({self.cells_hit} of {self.n_cells} "
                "equal-area cells)")


def coverage(points: Any, *, center: Any = None, n_cells: int = N_CELLS) -> Coverage:
    """Which equal-area cells of the sphere the directions of ``points`` hit.

    Parameters
    ----------
    points : array_like, shape (N, 3)
        Readings (pose means, or calibrated readings); only their directions from ``center``
        matter. Zero vectors count for no cell.
    center : array_like (3,), optional
        Where the directions are measured from (default: the origin).
    n_cells : int
        Number of cells (default :data:`N_CELLS`; change it only to compare with other tools).

    Returns
    -------
    Coverage

    Examples
    --------
    >>> import numpy as np
    >>> faces = np.vstack([np.eye(3), -np.eye(3)])
    >>> cov = coverage(faces)
    >>> cov.cells_hit, cov.n_cells, round(cov.percent)
    (6, 24, 25)
    """
    pts = as_points(points, name="points")
    if not np.isfinite(pts).all():
        raise CalibrationError("points must be finite (no NaN or inf) to measure coverage")
    if center is not None:
        c = np.asarray(center, dtype=np.float64).reshape(-1)
        if c.shape != (3,) or not np.isfinite(c).all():
            raise CalibrationError(f"center must be 3 finite numbers, got {center!r}")
        pts = pts - c
    cells = sphere_cells(n_cells)
    counts = np.zeros(cells.n, dtype=np.int64)
    keep = np.linalg.norm(pts, axis=1) > 0
    if keep.any():
        np.add.at(counts, cells.index(pts[keep]), 1)
    counts.setflags(write=False)
    return Coverage(counts=counts, cells_hit=int(np.count_nonzero(counts)), n_cells=cells.n)


def coverage_warning(cov: Coverage, sensor: str | None = None) -> str | None:
    """The plain-language warning for poor coverage (below :data:`LOW_COVERAGE_PCT`), or None."""
    if cov.percent >= LOW_COVERAGE_PCT:
        return None
    what = {
        "accel": "hold the board still in many more orientations (all six faces up and the "
                 "corners in between)",
        "mag": "turn the board through many more orientations (all six faces towards the field "
               "and the corners in between)",
        "gyro": "add rotations about more axes, both ways",
    }.get(sensor or "", "add readings in many more directions")
    return (f"only {cov.percent:.0f} % of the sphere is covered ({cov.cells_hit} of "
            f"{cov.n_cells} equal-area cells): {what}")


_AXES = ("X", "Y", "Z")


def _describe(d: np.ndarray) -> str:
    """Words for 'this body direction points up': '+Z up', '+X and -Z up'."""
    order = np.argsort(-np.abs(d))
    main = [order[0]]
    if abs(d[order[1]]) > 0.5 * abs(d[order[0]]):
        main.append(order[1])
    parts = [("+" if d[i] > 0 else "-") + _AXES[i] for i in main]
    return " and ".join(parts) + " up"


def suggest_turn(points: Any, current: Any = None, *, n_cells: int = N_CELLS) -> str:
    """Which way to turn the board next, in words, towards the emptiest part of the sphere.

    Parameters
    ----------
    points : array_like (N, 3)
        Accelerometer readings of the poses so far (any units; the direction matters).
    current : array_like (3,), optional
        The accelerometer reading now (default: the last point).
    n_cells : int
        Cells of the coverage measure.

    Returns
    -------
    str
        E.g. ``"turn it upside down (-Z up)"``, ``"tilt the +X side up (+X up)"``, or
        ``"every direction covered: ..."``.

    Examples
    --------
    >>> suggest_turn([[0, 0, 1.0]])
    'turn it upside down (-Z up)'
    >>> suggest_turn([[0, 0, 1.0], [0, 0, -1.0]], [0, 0, 1.0])
    'tilt the +X side up (+X up)'
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    cells = sphere_cells(n_cells)
    cen = cells.centres()
    if len(pts):
        hit = set(np.unique(cells.index(pts)).tolist())
        u = pts / np.maximum(np.linalg.norm(pts, axis=1, keepdims=True), 1e-300)
        empty = [i for i in range(cells.n) if i not in hit]
        if not empty:
            return "every direction covered: add poses anywhere or stop"
        cand = cen[empty]
        gap = (cand @ u.T).max(axis=1)
        target = cand[int(np.argmin(gap))]  # the empty cell farthest from every pose
    else:
        target = np.array([0.0, 0.0, 1.0])
    now = np.asarray(current, dtype=np.float64) if current is not None else (
        pts[-1] if len(pts) else np.array([0.0, 0.0, 1.0])
    )
    now = now / max(float(np.linalg.norm(now)), 1e-300)
    aim = _describe(target)
    if not len(pts):
        return "hold it still to register the first pose"
    if float(now @ target) > 0.9:
        return f"hold it still here ({aim})"
    if float(now @ target) < -0.7:
        return f"turn it upside down ({aim})"
    push = target - now * float(now @ target)  # the side that must rise
    i = int(np.argmax(np.abs(push)))
    if abs(push[i]) < 1e-9:
        return f"turn it to {aim}"
    if push[i] > 0:
        return f"tilt the +{_AXES[i]} side up ({aim})"
    return f"tilt the +{_AXES[i]} side down ({aim})"
