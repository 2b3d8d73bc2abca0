"""Magnetometer-to-accelerometer alignment, and the heading a compass would show.

Error model: after each sensor's own calibration the accelerometer reads the specific force
``a`` (pointing **up** at rest) in its frame and the magnetometer the field ``m`` in its own
frame, which a rotation ``R`` turns into the accelerometer's: ``m_accel = R @ m``. The Earth's
field dips by the same angle everywhere nearby, so in every still pose ``i``

    a_i / |a_i| . R m_i / |m_i| = -sin(dip)                                       (1)

:func:`align_mag_accel` finds ``R`` (and the dip) by minimising the squared misfit of (1) over
the still poses where both sensors were read (the dot-product method; e.g. Li & Li, "Calibration
of a three-axis magnetometer ... and alignment with an accelerometer", 2012): a closed-form
start (``a_i^T R m_i`` is linear in the nine entries of ``R``), 24 right-angle starts, then
Gauss-Newton on the rotation (three small angles) and the dip. It reports the dip angle and
its spread over the poses before (``R = I``) and after, and the nearest of the 24 right-angle
mountings (:mod:`triaxcal.conventions.rotations`) with the angle between them -- a mounting
rotation, as ArduPilot and PX4 detect for external compasses. Turns about one axis only leave the
rotation about that axis undetermined; the standard errors say so.

Heading: with ``u`` the unit up vector and ``n`` the horizontal part of the field (both in the
accelerometer frame), the heading of a body axis ``b`` is the angle from magnetic north to the
horizontal part of ``b``, clockwise seen from above: ``atan2(b . (n x u), b . n)``.
:func:`heading_errors` compares the attitude this gives with a known one (simulation);
:func:`axis_heading` gives the heading of one body axis per sample (real recordings: an axis
that should keep its heading while the board turns about it).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._checks import options as opt
from .._checks.arrays import as_matrix3, as_points, as_samples
from ..conventions.rotations import (
    MAX_MOUNTING_DEG,
    MOUNTINGS,
    Mounting,
    nearest_mounting,
    rotation_angle_deg,
)
from ..errors import CalibrationError

__all__ = [
    "MAX_MOUNTING_DEG",
    "AlignmentWarning",
    "MagAccelAlignment",
    "align_mag_accel",
    "axis_heading",
    "dip_angles",
    "heading_errors",
    "paired_still_poses",
]

#: A rotation axis whose standard error exceeds this (deg) is reported as undetermined.
_UNDETERMINED_DEG = 2.0


class AlignmentWarning(UserWarning):
    """An export holds only part of an alignment (the right-angle mounting, not the rest)."""


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    if np.any(n == 0):
        raise CalibrationError("a reading of zero length has no direction: drop it")
    return v / n


def _rotation(value: Any, name: str = "rotation") -> np.ndarray:
    """A rotation matrix (3x3, orthonormal, determinant +1, to 1e-6): one that is not would
    distort the headings silently."""
    r = as_matrix3(value, name)
    if not (np.allclose(r @ r.T, np.eye(3), atol=1e-6) and np.linalg.det(r) > 0):
        raise CalibrationError(
            f"{opt.named(name)} must be a rotation (orthonormal, determinant +1), got "
            f"{np.round(r, 6).tolist()}")
    return r


def _calibration(value: Any, name: str) -> Any:
    """A calibration to apply first (anything with ``apply``: a SensorCalibration, a fit)."""
    if value is not None and not callable(getattr(value, "apply", None)):
        raise CalibrationError(f"{opt.named(name)} must be a SensorCalibration (or a fit) to "
                               f"apply first, or None, got {type(value).__name__}")
    return value


def _skew(w: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def _expm(w: np.ndarray) -> np.ndarray:
    th = float(np.linalg.norm(w))
    k = _skew(w)
    if th < 1e-12:
        return np.eye(3) + k
    return np.eye(3) + math.sin(th) / th * k + (1 - math.cos(th)) / th**2 * (k @ k)


def _project_so3(m: np.ndarray) -> np.ndarray:
    u, _, vt = np.linalg.svd(m)
    d = np.sign(np.linalg.det(u @ vt)) or 1.0
    return u @ np.diag([1.0, 1.0, d]) @ vt


def dip_angles(accel: Any, mag: Any, rotation: Any = None) -> np.ndarray:
    """Dip of the field below the horizon (deg, positive down) in each pose.

    ``accel`` (P, 3) is the specific force (up at rest), ``mag`` (P, 3) the field in the
    magnetometer frame, ``rotation`` (default identity) turns it into the accelerometer frame.
    """
    u = _unit(as_samples(accel, "accel"))
    n = _unit(as_samples(mag, "mag"))
    r = np.eye(3) if rotation is None else _rotation(rotation)
    return np.degrees(np.arcsin(np.clip(-np.einsum("ij,ij->i", u, n @ r.T), -1.0, 1.0)))


def _solve(u: np.ndarray, n: np.ndarray, r0: np.ndarray, iters: int = 50
           ) -> tuple[np.ndarray, float, float, np.ndarray]:
    """Gauss-Newton for ``R`` (left perturbation) and ``s`` from start ``r0``."""
    r = r0.copy()
    s = float(np.mean(np.einsum("ij,ij->i", u, n @ r.T)))
    lam = 1e-6
    rn = n @ r.T
    res = np.einsum("ij,ij->i", u, rn) - s
    cost = float(res @ res)
    jac = np.zeros((len(u), 4))
    for _ in range(iters):
        jac[:, :3] = np.cross(rn, u)
        jac[:, 3] = -1.0
        jtj = jac.T @ jac
        g = jac.T @ res
        step = np.linalg.solve(jtj + lam * np.diag(np.diag(jtj) + 1e-12), -g)
        r_new = _expm(step[:3]) @ r
        s_new = s + step[3]
        rn_new = n @ r_new.T
        res_new = np.einsum("ij,ij->i", u, rn_new) - s_new
        c_new = float(res_new @ res_new)
        if c_new <= cost:
            done = cost - c_new <= 1e-15 * max(cost, 1e-300) or np.linalg.norm(step) < 1e-13
            r, s, rn, res, cost = _project_so3(r_new), s_new, rn_new, res_new, c_new
            lam = max(lam / 10, 1e-12)
            if done:
                break
        else:
            lam *= 10
            if lam > 1e8:
                break
    jac[:, :3] = np.cross(rn, u)
    jac[:, 3] = -1.0
    return r, s, cost, jac


def _linear_start(u: np.ndarray, n: np.ndarray) -> np.ndarray | None:
    """``R`` from least squares of ``kron(u_i, n_i) . x = 1`` (``x = vec(R) / s``)."""
    if len(u) < 12:
        return None
    k = np.einsum("ij,ik->ijk", u, n).reshape(len(u), 9)
    x, *_ = np.linalg.lstsq(k, np.ones(len(u)), rcond=None)
    m = x.reshape(3, 3)
    if not np.all(np.isfinite(m)) or np.linalg.norm(m) == 0:
        return None
    m = m if np.linalg.det(m) > 0 else -m
    return _project_so3(m)


@dataclass(frozen=True)
class MagAccelAlignment:
    """The result of :func:`align_mag_accel`.

    Attributes
    ----------
    rotation : ndarray (3, 3)
        ``v_accel_frame = rotation @ v_mag_frame`` (a proper rotation).
    mounting : Mounting or None
        The nearest of the 24 right-angle rotations when within ``MAX_MOUNTING_DEG`` (20 deg)
        of ``rotation``; ``mounting.name`` / ``.number`` are ArduPilot's and PX4's.
    mounting_residual_deg : float
        Angle between ``rotation`` and the nearest right-angle rotation (deg): the part of the
        alignment a ``COMPASS_ORIENT`` / ``CAL_MAGn_ROT`` cannot hold.
    dip_deg : float
        Dip of the field below the horizon (deg, positive down), fitted.
    dip_std_before_deg, dip_std_after_deg : float
        Spread (standard deviation, deg) of the per-pose dip over the fitted poses with the
        frames taken as equal, and after the alignment.
    dip_std_heldout_before_deg, dip_std_heldout_after_deg : float or None
        The same over the held-out poses (about the fitted dip), when any were held out.
    heading_rms_est_deg : float or None
        Heading error estimated from the held-out dip residuals (deg): a direction error of
        the field as large across the dip plane as along it turns the heading by
        ``d_dip / cos(dip)`` (rad); None without held-out poses.
    stderr_deg : ndarray (3,)
        Standard errors of small rotations about the accelerometer's x, y, z axes (deg).
    rms_deg : float
        RMS misfit of the dip over the fitted poses (deg).
    n_poses : int
        Still poses used in all; ``fit_index`` / ``heldout_index`` say which were fitted.
    accel, mag : ndarray (P, 3)
        Calibrated pose means: specific force (accelerometer frame), field (magnetometer frame).
    spans : list of (int, int)
        Sample ranges (start, end) of the poses, when they were detected.
    warnings : tuple of str
    """

    rotation: np.ndarray
    mounting: Mounting | None
    mounting_residual_deg: float
    dip_deg: float
    dip_std_before_deg: float
    dip_std_after_deg: float
    dip_std_heldout_before_deg: float | None
    dip_std_heldout_after_deg: float | None
    heading_rms_est_deg: float | None
    stderr_deg: np.ndarray
    rms_deg: float
    n_poses: int
    fit_index: np.ndarray
    heldout_index: np.ndarray
    accel: np.ndarray
    mag: np.ndarray
    spans: list[tuple[int, int]] = field(default_factory=list)
    warnings: tuple[str, ...] = ()

    @property
    def angle_deg(self) -> float:
        """Angle of the whole rotation (deg)."""
        return rotation_angle_deg(self.rotation)

    def apply(self, mag: Any) -> np.ndarray:
        """Field vectors (N, 3) in the magnetometer frame -> the accelerometer frame."""
        return as_points(mag, name="mag") @ self.rotation.T

    def stats(self) -> dict[str, Any]:
        """Plain-JSON numbers for the calibration file's ``alignment.stats``."""
        def f(v: float | None) -> float | None:
            return None if v is None else float(v)
        return {
            "dip_deg": float(self.dip_deg),
            "dip_std_before_deg": float(self.dip_std_before_deg),
            "dip_std_after_deg": float(self.dip_std_after_deg),
            "dip_std_heldout_before_deg": f(self.dip_std_heldout_before_deg),
            "dip_std_heldout_after_deg": f(self.dip_std_heldout_after_deg),
            "heading_rms_est_deg": f(self.heading_rms_est_deg),
            "rms_deg": float(self.rms_deg),
            "stderr_deg": [float(v) for v in self.stderr_deg],
            "angle_deg": float(self.angle_deg),
            "mounting_residual_deg": float(self.mounting_residual_deg),
            "n_poses": int(self.n_poses),
            "n_fit": int(len(self.fit_index)),
            "n_heldout": int(len(self.heldout_index)),
            "warnings": list(self.warnings),
        }

    def text(self) -> str:
        """The alignment in a few lines for the console."""
        mnt = (f"{self.mounting.name} ({self.mounting.number}) + {self.mounting_residual_deg:.2f}"
               " deg" if self.mounting is not None else
               f"none within {MAX_MOUNTING_DEG:g} deg (nearest is "
               f"{self.mounting_residual_deg:.1f} deg away)")
        lines = [
            f"magnetometer -> accelerometer alignment from {self.n_poses} still poses "
            f"({len(self.fit_index)} fitted, {len(self.heldout_index)} held out)",
            f"  rotation        {self.angle_deg:.2f} deg; mounting {mnt}",
            f"  std. errors     about x {self.stderr_deg[0]:.3f}, y {self.stderr_deg[1]:.3f}, "
            f"z {self.stderr_deg[2]:.3f} deg",
            f"  dip angle       {self.dip_deg:.2f} deg; spread over poses "
            f"{self.dip_std_before_deg:.3f} deg before, {self.dip_std_after_deg:.3f} deg after",
        ]
        if self.dip_std_heldout_after_deg is not None:
            lines.append(
                f"  held-out poses  dip spread {self.dip_std_heldout_before_deg:.3f} -> "
                f"{self.dip_std_heldout_after_deg:.3f} deg; heading error estimated "
                f"{self.heading_rms_est_deg:.2f} deg rms")
        lines += [f"  warning: {w}" for w in self.warnings]
        return "\n".join(lines)


def paired_still_poses(mag: Any, accel: Any, *, window: int = 25,
                       threshold: float | None = None, units_per_g: float = 1.0
                       ) -> tuple[np.ndarray, np.ndarray, list[tuple[int, int]]]:
    """Means ``(mag (P, 3), accel (P, 3), spans)`` of both sensors over the runs where BOTH
    are still; ``spans`` are the sample ranges ``(start, end)``.

    The pose detector runs on each sensor (the magnetometer's threshold is the same share of
    its field strength as the accelerometer's is of 1 g): a turn about the vertical moves the
    field but not gravity, so the accelerometer alone would merge the poses on either side.
    """
    from ..detect import detect_poses

    mag = as_samples(mag, "mag")
    accel = as_samples(accel, "accel")
    if len(mag) != len(accel):
        raise CalibrationError(f"mag has {len(mag)} readings and accel {len(accel)}: give "
                               "both sensors at the same instants")
    thr_g = 0.07 if threshold is None else opt.magnitude(threshold, "threshold") / units_per_g
    field_mag = float(np.median(np.linalg.norm(mag, axis=1)))
    spans = []
    for data, thr in ((accel, thr_g * units_per_g), (mag, thr_g * field_mag)):
        det = detect_poses(data, window=window, threshold=thr, min_separation=0.0)
        spans.append([(int(q.start), int(q.end)) for q in det.poses])
    both: list[tuple[int, int]] = []
    i = j = 0
    sa, sm = spans
    while i < len(sa) and j < len(sm):
        # one window off each end: the detector sees the slow start and end of a turn as still
        lo, hi = max(sa[i][0], sm[j][0]) + window, min(sa[i][1], sm[j][1]) - window
        if hi - lo >= window:
            both.append((lo, hi))
        if sa[i][1] < sm[j][1]:
            i += 1
        else:
            j += 1
    if not both:
        raise CalibrationError(
            f"no still poses found (window {window} samples) where both sensors are steady: "
            "hold the board still in each pose for a second or two while both are read")
    m = np.array([mag[lo:hi].mean(axis=0) for lo, hi in both])
    a = np.array([accel[lo:hi].mean(axis=0) for lo, hi in both])
    return m, a, both


def _units_per_g(accel_cal: Any) -> float:
    from ..conventions.units import unit_factor

    unit = getattr(accel_cal, "unit", "g") if accel_cal is not None else "g"
    try:
        return unit_factor("g", unit)
    except CalibrationError:
        return 1.0


def align_mag_accel(
    mag: Any,
    accel: Any,
    *,
    mag_cal: Any = None,
    accel_cal: Any = None,
    detect: bool = True,
    window: int = 25,
    threshold: float | None = None,
    holdout: float = 0.25,
    expected_inclination_deg: float | None = None,
) -> MagAccelAlignment:
    """Rotation from the magnetometer's frame to the accelerometer's, from still poses.

    Parameters
    ----------
    mag, accel : array_like (N, 3)
        Readings of both sensors at the same instants (resample one onto the other first if
        they are logged at different rates: ``LogRecording.synchronized``). Raw readings when
        ``mag_cal`` / ``accel_cal`` are given, else already calibrated (any units).
    mag_cal, accel_cal : SensorCalibration or EllipsoidFit, optional
        Applied to the readings first (hard / soft iron must be removed before the field's
        direction means anything).
    detect : bool
        True: find still poses with the project's pose detector on the accelerometer and use
        the mean of both sensors over each. False: every row is already a still pose.
    window, threshold : int, float
        Pose detector options (:func:`triaxcal.detect_poses`), in calibrated accelerometer
        units (``threshold`` default: 0.07 g).
    holdout : float
        Share of the poses (every k-th, spread evenly) kept out of the fit to judge it: their
        dip spread and the heading error it implies are reported. 0 fits all.
    expected_inclination_deg : float, optional
        The inclination the World Magnetic Model gives here (:func:`triaxcal.expected_field`):
        a fitted dip of the opposite sign means the accelerometer reads gravity (down) instead
        of the specific force (up), or one sensor's axes are mirrored -- raised as an error.

    Returns
    -------
    MagAccelAlignment

    Raises
    ------
    CalibrationError
        Too few poses (fewer than 6 to fit), mismatched inputs, or the sign problem above.

    Examples
    --------
    >>> import numpy as np, triaxcal as tc
    >>> rng = np.random.default_rng(3)
    >>> up = rng.normal(size=(40, 3)); up /= np.linalg.norm(up, axis=1, keepdims=True)
    >>> world_to_body = [tc.sim.rotvec_to_matrix(v) for v in rng.normal(size=(40, 3))]
    >>> f_world = np.array([20.0, 0.0, -45.0])                # north, west, up (uT)
    >>> accel = np.array([w @ [0, 0, 1.0] for w in world_to_body])
    >>> mount = np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]])  # magnetometer turned 90 deg
    >>> mag = np.array([mount.T @ w @ f_world for w in world_to_body])
    >>> al = tc.align_mag_accel(mag, accel, detect=False)
    >>> al.mounting.name, round(al.mounting_residual_deg, 6), round(al.dip_deg, 2)
    ('ROTATION_YAW_90', 0.0, 66.04)
    """
    m = as_samples(mag, "mag")
    a = as_samples(accel, "accel")
    if len(m) != len(a):
        raise CalibrationError(
            f"mag has {len(m)} readings and accel {len(a)}: give both sensors at the same "
            "instants (resample one onto the other's times first)")
    h = opt.number(holdout, "holdout", ge=0, lt=0.75, hint="a share of the poses")
    inc = opt.optional_number(expected_inclination_deg, "expected_inclination_deg", ge=-90,
                              le=90, hint="degrees")
    detect = opt.flag(detect, "detect")
    if _calibration(mag_cal, "mag_cal") is not None:
        m = as_samples(mag_cal.apply(m), "mag (calibrated)")
    if _calibration(accel_cal, "accel_cal") is not None:
        a = as_samples(accel_cal.apply(a), "accel (calibrated)")
    spans: list[tuple[int, int]] = []
    if detect:
        m, a, spans = paired_still_poses(m, a, window=window, threshold=threshold,
                                         units_per_g=_units_per_g(accel_cal))
    p = len(m)
    heldout = (np.arange(p)[(np.arange(p) % max(round(min(1 / h, p + 1)), 2)) == 1]
               if h > 0 and p >= 12 else np.zeros(0, dtype=int))
    fit_idx = np.setdiff1d(np.arange(p), heldout)
    if len(fit_idx) < 6:
        raise CalibrationError(
            f"only {len(fit_idx)} still poses to fit the alignment (need at least 6, better "
            "20+ spread over all orientations): hold the board still in more poses, tilted "
            "every way")
    u = _unit(a)
    n = _unit(m)
    uf, nf = u[fit_idx], n[fit_idx]
    starts = [mt.matrix for mt in MOUNTINGS]
    lin = _linear_start(uf, nf)
    if lin is not None:
        starts.insert(0, lin)
    best: tuple[np.ndarray, float, float, np.ndarray] | None = None
    for r0 in starts:
        sol = _solve(uf, nf, r0)
        if best is None or sol[2] < best[2] - 1e-15:
            best = sol
    assert best is not None
    rot, s, cost, jac = best
    dof = max(len(fit_idx) - 4, 1)
    sigma2 = cost / dof
    with np.errstate(all="ignore"):
        try:
            cov = np.linalg.inv(jac.T @ jac) * sigma2
            se = np.degrees(np.sqrt(np.clip(np.diag(cov)[:3], 0, None)))
        except np.linalg.LinAlgError:
            se = np.full(3, np.inf)
    warn: list[str] = []
    bad = [("xyz")[k] for k in range(3) if not se[k] < _UNDETERMINED_DEG]
    if bad:
        warn.append(
            f"the rotation about the accelerometer's {', '.join(bad)} axis is poorly determined "
            f"(standard error {', '.join(f'{se[k]:.2g}' for k in range(3) if se[k] >= 2)} deg): "
            "the poses turn about too few axes; add poses tilted about that axis")
    dip = math.degrees(math.asin(max(-1.0, min(1.0, -s))))
    if inc is not None:
        if abs(inc) > 5 and abs(dip) > 5 and math.copysign(1, inc) != math.copysign(1, dip):
            raise CalibrationError(
                f"the fitted dip is {dip:.1f} deg but the World Magnetic Model gives "
                f"{inc:.1f} deg here: either the accelerometer reports gravity (pointing down) "
                "instead of the specific force (up at rest) -- negate its readings -- or one "
                "axis of one sensor is mirrored (a left-handed frame): negate that axis")
        if abs(dip - inc) > 5:
            warn.append(f"the dip angle is {dip:.1f} deg, {dip - inc:+.1f} deg from the World "
                        f"Magnetic Model's {inc:.1f} deg: a magnetised environment or a poor "
                        "magnetometer calibration")
    d_before = dip_angles(a, m)
    d_after = dip_angles(a, m, rot)
    mt, resid = nearest_mounting(rot)
    hb = ha = hest = None
    if len(heldout):
        hb = float(np.sqrt(np.mean((d_before[heldout] - np.mean(d_before[fit_idx])) ** 2)))
        ha = float(np.sqrt(np.mean((d_after[heldout] - dip) ** 2)))
        hest = float(ha / max(math.cos(math.radians(dip)), 0.05))
    rms = float(np.sqrt(np.mean((d_after[fit_idx] - dip) ** 2)))
    return MagAccelAlignment(
        rotation=_frozen(rot), mounting=mt if resid <= MAX_MOUNTING_DEG else None,
        mounting_residual_deg=float(resid), dip_deg=dip,
        dip_std_before_deg=float(np.std(d_before[fit_idx], ddof=1)),
        dip_std_after_deg=float(np.std(d_after[fit_idx], ddof=1)),
        dip_std_heldout_before_deg=hb, dip_std_heldout_after_deg=ha, heading_rms_est_deg=hest,
        stderr_deg=_frozen(se), rms_deg=rms, n_poses=p, fit_index=_frozen(fit_idx, int),
        heldout_index=_frozen(heldout, int), accel=_frozen(a), mag=_frozen(m), spans=spans,
        warnings=tuple(warn))


def _frozen(x: Any, dtype: Any = float) -> np.ndarray:
    arr = np.array(x, dtype=dtype)
    arr.setflags(write=False)
    return arr


# --------------------------------------------------------------------------------------------
# heading


def _up_north(accel: Any, mag: Any, rotation: Any) -> tuple[np.ndarray, np.ndarray]:
    u = _unit(as_samples(accel, "accel"))
    f = as_samples(mag, "mag")
    if rotation is not None:
        f = f @ _rotation(rotation).T
    if len(f) != len(u):
        raise CalibrationError(f"accel has {len(u)} readings and mag {len(f)}: they must pair")
    h = f - np.einsum("ij,ij->i", f, u)[:, None] * u
    hn = np.linalg.norm(h, axis=1)
    if np.any(~(hn > 1e-9 * np.linalg.norm(f, axis=1))):
        raise CalibrationError("the field is vertical (or zero) in some pose: no heading can be "
                               "defined")
    return u, h / hn[:, None]


def axis_heading(accel: Any, mag: Any, *, axis: Any = 0, rotation: Any = None) -> np.ndarray:
    """Magnetic heading (deg, 0..360, clockwise from magnetic north seen from above) of a body
    axis (index 0, 1, 2 or a 3-vector in the accelerometer frame), per reading.

    ``accel`` is the specific force (up at rest), ``mag`` the calibrated field (in the
    magnetometer frame; ``rotation`` turns it into the accelerometer frame). Add the WMM's
    declination to get the heading from true north.

    >>> axis_heading([[0, 0, 1.0]], [[0, 20.0, -40.0]], axis=1).round(6).tolist()  # y to north
    [0.0]
    """
    u, n = _up_north(accel, mag, rotation)
    if isinstance(axis, (int, np.integer)) and not isinstance(axis, (bool, np.bool_)):
        if not 0 <= int(axis) <= 2:
            raise CalibrationError(f"axis must be 0, 1, 2 or a 3-vector, got {axis!r}")
        b = np.eye(3)[int(axis)]
    else:
        b = _unit(opt.vector3(axis, "axis", hint="0, 1, 2 or a direction in the "
                              "accelerometer's frame"))
    e = np.cross(n, u)  # north x up = east
    east, north = e @ b, n @ b
    # an axis (nearly) along the vertical in some reading points nowhere on the compass
    level = np.hypot(east, north)
    if (level < 1e-6).any():
        k = int(np.flatnonzero(level < 1e-6)[0])
        raise CalibrationError(
            f"the axis points straight up or down in reading {k}: it has no heading there "
            "(take the heading of a horizontal axis)")
    return np.degrees(np.arctan2(east, north)) % 360.0


def heading_errors(accel: Any, mag: Any, orientation: Any, *, rotation: Any = None
                   ) -> np.ndarray:
    """Heading error (deg, signed, clockwise positive) of the tilt-compensated compass per pose.

    ``orientation`` (P, 3, 3) is the true body-to-world rotation with the world frame x
    towards magnetic north, y west, z up (the simulator's); the attitude the compass gives --
    up from ``accel``, north from the horizontal part of ``mag`` (turned by ``rotation``) -- is
    compared with it about the vertical.
    """
    u, n = _up_north(accel, mag, rotation)
    try:
        o = np.asarray(orientation)
    except (TypeError, ValueError):
        o = np.zeros(0, dtype=object)
    if o.dtype.kind not in "iuf" or not np.isfinite(o.astype(np.float64)).all():
        raise CalibrationError("orientation must hold finite rotation matrices, shape (P, 3, 3)")
    o = o.astype(np.float64)
    if o.shape != (len(u), 3, 3):
        raise CalibrationError(f"orientation must have shape ({len(u)}, 3, 3), got {o.shape}")
    est = np.stack([n, np.cross(u, n), u], axis=1)  # rows: north, west, up (body coords)
    d = est @ np.swapaxes(o, 1, 2)  # estimated body-to-world times true world-to-body
    yaw = np.degrees(np.arctan2(d[:, 1, 0], d[:, 0, 0]))  # counter-clockwise about up
    return -yaw


def _warn_partial(what: str, residual_deg: float) -> None:
    warnings.warn(
        f"{what} holds only the right-angle mounting; the remaining {residual_deg:.2f} deg of "
        "the magnetometer-to-accelerometer alignment are left out (headings may be off by "
        "about as much)", AlignmentWarning, stacklevel=3)
