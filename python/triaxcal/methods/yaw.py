"""Yaw-only magnetometer calibration, for what cannot be tumbled (boats, cars, large rovers).

Error model: the field ``f`` (uT) in the body frame is read as ``raw = offset + inv(matrix) f``
(hard iron ``offset``, soft iron / scale ``matrix``, symmetric; calibrated = ``matrix @ (raw -
offset)``). Turning about the vertical only, the field's horizontal part ``H`` sweeps a circle
and its vertical part ``V`` (up positive: ``V = -Z`` for the World Magnetic Model's downward
``Z``) stays put. With ``u_i`` the up direction in each reading (from the accelerometer, or the
body's z axis when the vehicle is level) and ``c_i = matrix @ (raw_i - offset)``, the fit
minimises

    sum_i (|c_i - (c_i . u_i) u_i| - H)^2 + (c_i . u_i - V)^2

over the offset and the matrix (Levenberg-Marquardt, started from an ellipse fit of the
horizontal components). What such data determine, and what not:

* **determined**: the horizontal offsets and the 2x2 horizontal soft iron (the ellipse), and,
  with ``V`` known, the coupling between the vertical and horizontal axes;
* **not determined**: the vertical axis's gain and its offset separately -- turns about the
  vertical leave the vertical reading constant, one number for two unknowns. The gain is
  taken equal to the mean horizontal gain (sensor axes usually match within a few %); the
  vertical offset then follows from ``V`` (the WMM at the location). Each % of gain mismatch
  moves the vertical offset by 1 % of ``V``; when the vehicle tilts by ``theta`` that error
  turns the heading by about ``0.01 V sin(theta) / H`` rad -- the report says how much;
* without a location (no ``H``, ``V``): the horizontal scale is the data's own and the vertical
  offset is unknown (set to zero, flagged): the calibration serves level headings only.

Headings need only the horizontal ellipse, so a yaw-only calibration gives good headings on a
level vehicle; tilt compensation relies on the vertical offset and is as good as the gain
assumption.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._checks import options as opt
from .._checks.arrays import as_points, as_samples
from ..errors import CalibrationError
from .field import ExpectedField

__all__ = ["YawCalibration", "fit_yaw"]

#: Gain mismatch assumed between the vertical and the horizontal axes when stating limits.
GAIN_MISMATCH = 0.05
#: Tilt at which the heading sensitivity is stated (deg).
TILT_DEG = 10.0


@dataclass(frozen=True)
class YawCalibration:
    """The result of :func:`fit_yaw` (see the module docstring).

    Attributes
    ----------
    offset : ndarray (3,)
        Hard iron, raw units.
    matrix : ndarray (3, 3)
        Symmetric soft iron / scale that **multiplies**, calibrated units per raw unit.
    unit, raw_unit : str
        Calibrated and raw units (``"uT"`` when the field is known).
    horizontal, vertical : float or None
        The ``H`` and ``V`` (up positive) the fit used, calibrated units; ``vertical`` None
        without a location.
    raw_horizontal : float
        The horizontal field the raw readings show (the ellipse's mean radius), raw units.
    rms_horizontal_pct : float
        RMS of the calibrated horizontal magnitude about ``horizontal``, in % of it.
    heading_rms_est_deg : float
        Heading error that residual corresponds to (deg): a misfit of ``e`` (relative) across
        the circle turns a heading by ``e`` rad.
    tilt_heading_deg : float or None
        Heading error at a 10 deg tilt from a 5 % vertical-gain mismatch (deg).
    level_up : ndarray (3,)
        Mean up direction in the body frame (the turn axis).
    tilt_std_deg : float
        Spread of the up direction about it (deg).
    n : int
    determined, assumed, limits : tuple of str
        What the data determine, what was assumed, and what the calibration cannot do.
    heading_gap_deg : float
        The widest arc of headings (deg) that no calibrated, levelled reading points into (the
        validity gate refuses wide gaps: the turns then do not determine the ellipse).
    """

    offset: np.ndarray
    matrix: np.ndarray
    unit: str
    raw_unit: str
    horizontal: float
    vertical: float | None
    raw_horizontal: float
    rms_horizontal_pct: float
    heading_rms_est_deg: float
    tilt_heading_deg: float | None
    level_up: np.ndarray
    tilt_std_deg: float
    n: int
    determined: tuple[str, ...]
    assumed: tuple[str, ...]
    limits: tuple[str, ...]
    heading_gap_deg: float = 0.0

    def apply(self, raw: Any) -> np.ndarray:
        """Calibrate raw readings: ``(raw - offset) @ matrix.T``."""
        return (as_points(raw, name="raw") - self.offset) @ self.matrix.T

    def stats(self) -> dict[str, Any]:
        """Plain JSON for the calibration part's ``stats["yaw"]``."""
        return {
            "horizontal": float(self.horizontal),
            "vertical": None if self.vertical is None else float(self.vertical),
            "raw_horizontal": float(self.raw_horizontal),
            "rms_horizontal_pct": float(self.rms_horizontal_pct),
            "heading_rms_est_deg": float(self.heading_rms_est_deg),
            "tilt_heading_deg": (None if self.tilt_heading_deg is None
                                 else float(self.tilt_heading_deg)),
            "level_up": [float(v) for v in self.level_up],
            "tilt_std_deg": float(self.tilt_std_deg),
            "determined": list(self.determined),
            "assumed": list(self.assumed),
            "limits": list(self.limits),
            "heading_gap_deg": float(self.heading_gap_deg),
        }

    def text(self) -> str:
        """The limits in words, for the console and the report."""
        return yaw_text(self.stats(), self.unit)


def yaw_text(y: dict[str, Any], unit: str) -> str:
    """Console lines of a yaw-only calibration's ``stats["yaw"]``."""
    lines = [
        f"yaw-only calibration (turns about the vertical): horizontal field "
        f"{y['horizontal']:.4g} {unit}"
        + (f", vertical {y['vertical']:.4g} {unit} (up positive)" if y.get("vertical")
           is not None else ", vertical unknown"),
        f"  horizontal residual {y['rms_horizontal_pct']:.3g} % -> heading error about "
        f"{y['heading_rms_est_deg']:.2g} deg rms; turn-axis tilt spread "
        f"{y['tilt_std_deg']:.2g} deg",
        "  determined: " + "; ".join(y["determined"]),
        "  assumed:    " + "; ".join(y["assumed"]),
    ]
    lines += [f"  limit: {t}" for t in y["limits"]]
    return "\n".join(lines)


def _level_rotation(up: np.ndarray) -> np.ndarray:
    """Rotation ``Q`` with ``Q @ up = z``."""
    z = np.array([0.0, 0.0, 1.0])
    u = up / np.linalg.norm(up)
    v = np.cross(u, z)
    s, c = float(np.linalg.norm(v)), float(u @ z)
    if s < 1e-12:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    k = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]]) / s
    ang = math.atan2(s, c)
    return np.eye(3) + math.sin(ang) * k + (1 - math.cos(ang)) * (k @ k)


def _ellipse2d(xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centre (2,) and symmetric A (2, 2) with ``|A (p - c)| = 1`` (algebraic conic fit)."""
    mu = xy.mean(axis=0)
    sc = float(np.std(xy - mu)) or 1.0
    x, y = ((xy - mu) / sc).T
    d = np.column_stack([x * x, x * y, y * y, x, y, np.ones_like(x)])
    _, _, vt = np.linalg.svd(d, full_matrices=False)
    a, b, c_, dd, e, f = vt[-1]
    q = np.array([[a, b / 2], [b / 2, c_]])
    if q[0, 0] < 0:
        q, dd, e, f = -q, -dd, -e, -f
    bad = CalibrationError(
        "the horizontal readings do not trace an ellipse: turn the vehicle through at least "
        "one full circle about the vertical")
    if np.linalg.det(q) <= 0:
        raise bad
    centre = np.linalg.solve(2 * q, -np.array([dd, e]))
    k = float(centre @ q @ centre - f)
    if not k > 0:
        raise bad
    w, v = np.linalg.eigh(q / k)
    return centre * sc + mu, (v @ np.diag(np.sqrt(w)) @ v.T) / sc


def _pack(o: np.ndarray, m: np.ndarray, free_z: bool) -> np.ndarray:
    p = [*o, m[0, 0], m[1, 1], m[0, 1], m[0, 2], m[1, 2]]
    if free_z:
        p.append(m[2, 2])
    return np.array(p)


def _unpack(p: np.ndarray, free_z: bool) -> tuple[np.ndarray, np.ndarray]:
    o = p[:3]
    mzz = p[8] if free_z else 0.5 * (p[3] + p[4])
    m = np.array([[p[3], p[5], p[6]], [p[5], p[4], p[7]], [p[6], p[7], mzz]])
    return o, m


def _residuals(p: np.ndarray, pts: np.ndarray, up: np.ndarray, h: float, v: float | None,
               free_z: bool) -> np.ndarray:
    o, m = _unpack(p, free_z)
    c = (pts - o) @ m.T
    cv = np.einsum("ij,ij->i", c, up)
    ch = np.linalg.norm(c - cv[:, None] * up, axis=1)
    if v is None:
        return ch - h
    return np.concatenate([ch - h, cv - v])


def _lm(p0: np.ndarray, fun: Any, iters: int = 200) -> np.ndarray:
    p = p0.copy()
    r = fun(p)
    cost = float(r @ r)
    lam = 1e-3
    for _ in range(iters):
        jac = np.empty((len(r), len(p)))
        for k in range(len(p)):
            dp = 1e-7 * max(abs(p[k]), 1e-3)
            q = p.copy()
            q[k] += dp
            jac[:, k] = (fun(q) - r) / dp
        jtj = jac.T @ jac
        g = jac.T @ r
        step = np.linalg.lstsq(jtj + lam * np.diag(np.diag(jtj) + 1e-300), -g, rcond=None)[0]
        pn = p + step
        rn = fun(pn)
        cn = float(rn @ rn)
        if cn < cost:
            done = cost - cn < 1e-14 * cost
            p, r, cost = pn, rn, cn
            lam = max(lam / 10, 1e-12)
            if done:
                break
        else:
            lam *= 10
            if lam > 1e10:
                break
    return p


def fit_yaw(
    mag: Any,
    *,
    accel: Any = None,
    field: Any = None,
    horizontal: float | None = None,
    vertical: float | None = None,
    raw_unit: str = "counts",
    unit: str | None = None,
) -> YawCalibration:
    """Calibrate a magnetometer from turns about the vertical only.

    Parameters
    ----------
    mag : array_like (N, 3)
        Raw readings while the vehicle turns (at least one full circle) about the vertical.
    accel : array_like (N, 3), optional
        The specific force (up at rest, any units) at the same instants: the up direction of
        each reading. Without it the body's z axis is taken as up (a level vehicle).
    field : ExpectedField, optional
        The World Magnetic Model's field at the location (:func:`triaxcal.expected_field`):
        gives ``horizontal`` (H) and ``vertical`` (``-Z``) in uT; the calibration is then in uT.
    horizontal, vertical : float, optional
        The same numbers given directly (calibrated units; ``vertical`` positive up, i.e.
        negative in the northern hemisphere). Without either, the horizontal scale is the
        data's own and the vertical offset is not determined.
    raw_unit : str
        Unit of ``mag``.
    unit : str, optional
        Unit of the calibrated readings: default ``"uT"`` with a field or ``horizontal``,
        else ``raw_unit`` (the data's own scale).

    Returns
    -------
    YawCalibration
        :func:`triaxcal.calibration.parts.part_from_yaw` gives the
        :class:`~triaxcal.SensorCalibration` (model ``"yaw"``).

    Examples
    --------
    >>> import numpy as np, triaxcal as tc
    >>> psi = np.linspace(0, 2 * np.pi, 72, endpoint=False)
    >>> f = np.column_stack([20 * np.cos(psi), -20 * np.sin(psi), np.full(72, -44.0)])
    >>> raw = f / [1.05, 0.95, 1.0] + [30.0, -12.0, 8.0]               # hard and soft iron
    >>> y = tc.fit_yaw(raw, horizontal=20.0, vertical=-44.0, raw_unit="uT")
    >>> np.round(y.offset, 3).tolist(), np.round(np.diag(y.matrix), 3).tolist()
    ([30.0, -12.0, 8.0], [1.05, 0.95, 1.0])
    """
    pts = as_samples(mag, "mag")
    n = len(pts)
    if field is not None and not isinstance(field, ExpectedField):
        raise CalibrationError(f"field must be an ExpectedField (from expected_field) or None, "
                               f"got {type(field).__name__}")
    horizontal = opt.optional_number(horizontal, "horizontal", ge=opt.MAGNITUDE[0],
                                     le=opt.MAGNITUDE[1], hint="the field's horizontal part")
    vertical = None if vertical is None else opt.magnitude(
        vertical, "vertical", signed=True, hint="the field's vertical part, up positive")
    if n < 12:
        raise CalibrationError(f"only {n} readings: record at least one full turn (50+ "
                               "readings spread around the circle)")
    if accel is None:
        up = np.tile([0.0, 0.0, 1.0], (n, 1))
        level_note = "the body's z axis is vertical (no accelerometer given): a level vehicle"
    else:
        a = as_samples(accel, "accel")
        if len(a) != n:
            raise CalibrationError(f"accel has {len(a)} readings and mag {n}: they must pair")
        na = np.linalg.norm(a, axis=1)
        if not (np.isfinite(a).all() and np.all(na > 0)):
            raise CalibrationError("accel readings must be finite and non-zero")
        up = a / na[:, None]
        level_note = "the up direction of each reading from the accelerometer"
    mean_up = up.mean(axis=0)
    mean_up /= np.linalg.norm(mean_up)
    tilt = np.degrees(np.arccos(np.clip(up @ mean_up, -1, 1)))
    q = _level_rotation(mean_up)
    lp = pts @ q.T  # leveled: z' along the mean up
    lu = up @ q.T
    if field is not None:
        if horizontal is not None or vertical is not None:
            raise CalibrationError("give field= or horizontal=/vertical=, not both")
        horizontal = float(field.horizontal_ut)
        vertical = -float(field.down_ut)
    if unit is None:
        unit = "uT" if (field is not None or horizontal is not None) else raw_unit
    centre, a2 = _ellipse2d(lp[:, :2])
    # coverage of the circle: at least ~3/4 of the headings
    ang = np.sort(np.arctan2(*(lp[:, 1::-1] - centre[::-1]).T))
    gap = float(np.max(np.diff(np.concatenate([ang, [ang[0] + 2 * np.pi]]))))
    if gap > math.radians(90):
        raise CalibrationError(
            f"the turns leave {math.degrees(gap):.0f} deg of headings unvisited: turn the "
            "vehicle through at least one full circle")
    own_h = 1.0 / math.sqrt(float(np.linalg.det(a2)))  # data's own horizontal radius
    h = float(horizontal) if horizontal is not None else own_h
    if not (math.isfinite(h) and h > 0):
        raise CalibrationError(f"horizontal field must be > 0, got {horizontal!r}")
    v = None if vertical is None else float(vertical)
    if v is not None and not math.isfinite(v):
        raise CalibrationError(f"vertical field must be finite, got {vertical!r}")
    m0 = np.zeros((3, 3))
    m0[:2, :2] = a2 * h
    g = math.sqrt(abs(np.linalg.det(m0[:2, :2])))
    m0[2, 2] = g
    oz = float(np.mean(lp[:, 2])) - (v / g if v is not None else 0.0)
    if v is None:
        oz = 0.0
    o0 = np.array([centre[0], centre[1], oz])
    p0 = _pack(o0, m0, False)
    if v is None:
        # nothing fixes the vertical offset or the coupling: fit the horizontal ellipse only
        def fun(p: np.ndarray) -> np.ndarray:
            full = np.array([p[0], p[1], 0.0, p[2], p[3], p[4], 0.0, 0.0])
            return _residuals(full, lp, lu, h, None, False)

        ph = _lm(np.array([p0[0], p0[1], p0[3], p0[4], p0[5]]), fun)
        p = np.array([ph[0], ph[1], 0.0, ph[2], ph[3], ph[4], 0.0, 0.0])
    else:
        p = _lm(p0, lambda p: _residuals(p, lp, lu, h, v, False))
    o_l, m_l = _unpack(p, False)
    res = _residuals(p, lp, lu, h, None, False)
    rms_pct = 100.0 * float(np.sqrt(np.mean(res**2))) / h
    heading_est = math.degrees(rms_pct / 100.0)
    offset = q.T @ o_l
    matrix = q.T @ m_l @ q
    if np.linalg.det(matrix) <= 0:
        raise CalibrationError("the yaw fit gave a reflected matrix: the readings are not "
                               "turns about one axis")
    determined = ["the horizontal offsets", "the horizontal soft iron (2x2 ellipse)"]
    assumed = [level_note,
               "the vertical axis's gain equals the mean of the horizontal gains"]
    limits: list[str] = []
    tilt_heading = None
    if v is not None:
        determined.append("the coupling between the vertical and horizontal axes")
        determined.append("the vertical offset, given the gain assumption")
        assumed.append(f"the field's vertical part is {v:.4g} {unit} (up positive) and its "
                       f"horizontal part {h:.4g} {unit}"
                       + (f" ({field.model} at {field.lat_deg:.3f}, {field.lon_deg:.3f})"
                          if field is not None else ""))
        tilt_heading = math.degrees(GAIN_MISMATCH * abs(v) * math.sin(math.radians(TILT_DEG))
                                    / h)
        limits.append(
            f"a {100 * GAIN_MISMATCH:.0f} % mismatch of the vertical gain moves the vertical "
            f"offset by {GAIN_MISMATCH * abs(v):.3g} {unit}, which turns tilt-compensated "
            f"headings by up to {tilt_heading:.2g} deg at {TILT_DEG:.0f} deg of tilt")
        limits.append("the vertical gain itself is not determined: |calibrated| is right only "
                      "near level; tumble the sensor (a full ellipsoid fit) to determine it")
    else:
        assumed.append(f"the horizontal scale is the data's own ({h:.4g} {raw_unit}); no "
                       "location was given")
        limits.append("the vertical offset and the vertical-horizontal coupling are NOT "
                      "determined (set to zero): headings are right only while the vehicle is "
                      "level; give the location (--location LAT,LON) to determine them")
        limits.append("the calibrated magnitude is in the data's own units, not uT")
    if tilt.std() > 5:
        limits.append(f"the turn axis wandered by {tilt.std():.1f} deg (std): turns about the "
                      "vertical fit best on flat ground or calm water")
    cal_l = (lp - o_l) @ m_l.T  # calibrated, levelled
    headings = np.sort(np.degrees(np.arctan2(cal_l[:, 1], cal_l[:, 0])) % 360.0)
    heading_gap = float(np.max(np.diff(np.concatenate([headings, [headings[0] + 360.0]]))))
    return YawCalibration(
        heading_gap_deg=heading_gap,
        offset=_ro(offset), matrix=_ro(0.5 * (matrix + matrix.T)), unit=unit,
        raw_unit=raw_unit, horizontal=h, vertical=v, raw_horizontal=own_h,
        rms_horizontal_pct=rms_pct,
        heading_rms_est_deg=heading_est, tilt_heading_deg=tilt_heading, level_up=_ro(mean_up),
        tilt_std_deg=float(tilt.std()), n=n, determined=tuple(determined),
        assumed=tuple(assumed), limits=tuple(limits))


def _ro(a: Any) -> np.ndarray:
    arr = np.array(a, dtype=float)
    arr.setflags(write=False)
    return arr
