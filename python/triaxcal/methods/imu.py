"""Multi-position accelerometer + gyroscope calibration without a rig (Tedaldi et al. 2014).

Error model (the imu_tk model, in this package's convention): raw accelerometer readings ``a``
and gyro readings ``w`` (counts) relate to the true specific force and angular rate in one
common body frame by

    acc_cal  = (a - accel.offset) @ accel.matrix.T     # in the units of ``gravity``
    gyro_cal = (w - gyro.offset)  @ gyro.matrix.T      # rad/s

``accel.matrix`` (symmetric: scale + non-orthogonality; its frame fixes the body frame) and
``accel.offset`` come from an ellipsoid fit of the still-pose means with radius ``gravity``.
``gyro.offset`` is the gyro mean while still; ``gyro.matrix`` (a general 3x3: scale,
non-orthogonality and the misalignment to the accelerometer frame) is fitted by
Levenberg-Marquardt so that, between consecutive still poses, the gravity direction measured
by the calibrated accelerometer before the move, rotated by the attitude change integrated
from the calibrated gyro, equals the direction measured after it.

Integration: the rotation over each move is the ordered product of per-sample quaternion
increments, each the exact exponential of the mean rate over the step plus the two-sample
coning correction ``(w_k x w_k+1) dt^2 / 12``; the product is evaluated as a balanced tree, all
moves and all Jacobian columns at once (numpy only, no scipy at run time). It agrees with
imu_tk's fourth-order Runge-Kutta on the quaternion (``quatIntegrationStepRK4`` in imu_tk's
``integration.h``) to 1e-9 on the imu_tk recording's moves: the integration order is not a
source of error at 100 Hz.

Gyro offset and g-sensitivity. A MEMS gyro at rest does not read the same in every orientation:
its reading depends on the specific force it feels (g-sensitivity, the ``K_ga`` of Ferraris and
imucal, part of the "cross coupling between acceleration and angular rate" of Xsens's model).
On the imu_tk Xsens recording the mean gyro reading of the 40 still poses scatters by 4-7
counts (0.05-0.09 deg/s) about its mean, and ``offset + g_sensitivity @ acc`` explains it to
1.2-1.5 counts (up to 13 counts per g). With one constant offset (imu_tk takes the mean of the
initial rest) each move's integral carries the change of that bias along the move; modelling it
lowers the gravity-direction residual after the gyro fit from 0.48 deg to 0.13 deg on that
recording. So by default (``gyro_g_sensitivity=True``) the still-pose means are fitted as
``offset + g_sensitivity @ acc_cal`` (least squares, one equation per pose), and the gyro is
integrated as ``(w - offset - g_sensitivity @ acc_cal) @ matrix.T`` with the accelerometer
sampled with it (the motion's own acceleration integrates to the change of velocity, zero
between two rests). Calibrate with :meth:`ImuCalibration.apply_gyro`.

Gains for comparison with a maker's certificate (``u = K s + b``, ``K = G A`` with unit rows in
A, Xsens's MTi manual, "Physical sensor model"): ``gain = row norms of inv(matrix)``, counts
per unit, independent of the frame.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._checks import options as opt
from .._checks.arrays import as_samples
from ..detect import detect_still
from ..errors import CalibrationError
from ..fit.ellipsoid import fit_ellipsoid
from ..quality.bounds import sample_rate

__all__ = ["ImuCalibration", "SweepStep", "TriadCalibration", "calibrate_imu", "rotate_gravity"]

AXES = "xyz"


def _ro(a: Any) -> np.ndarray:
    arr = np.array(a, dtype=np.float64)
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True)
class TriadCalibration:
    """Offset and matrix of one triaxial sensor: ``calibrated = (raw - offset) @ matrix.T``.

    ``offset`` is in counts; ``matrix`` multiplies and is in ``units`` per count.
    """

    offset: np.ndarray
    matrix: np.ndarray
    units: str

    @property
    def gains(self) -> np.ndarray:
        """Sensitivity of each raw axis, counts per ``units``: row norms of ``inv(matrix)``."""
        return np.linalg.norm(np.linalg.inv(self.matrix), axis=1)

    def apply(self, raw: Any) -> np.ndarray:
        """Calibrate raw counts (N, 3)."""
        return (np.asarray(raw, dtype=np.float64) - self.offset) @ self.matrix.T


@dataclass(frozen=True)
class SweepStep:
    """One threshold of the sweep: multiplier ``k``, poses found, accelerometer fit rms
    (gravity units; NaN if the fit was not possible)."""

    k: float
    n_intervals: int
    accel_rms: float


@dataclass(frozen=True)
class ImuCalibration:
    """The result of :func:`calibrate_imu`.

    Attributes
    ----------
    accel : TriadCalibration
        Units of ``gravity`` (m/s^2 for 9.80665).
    accel_model : str
        ``"full"`` or ``"axis"``: the accelerometer model used.
    gyro : TriadCalibration
        rad/s. ``gyro.offset`` is the reading at zero specific force when
        ``gyro_g_sensitivity`` is non-zero (use :meth:`apply_gyro`).
    gyro_g_sensitivity : ndarray (3, 3)
        Gyro counts per unit of calibrated acceleration (the units of ``gravity``): the rest
        reading is ``gyro.offset + gyro_g_sensitivity @ acc_cal``. Zeros when not fitted.
    intervals : tuple of (int, int)
        Still intervals used (sample indices, end exclusive).
    k : float
        Threshold multiplier chosen by the sweep.
    accel_rms : float
        RMS of ``|acc_cal| - gravity`` over the pose means, gravity units.
    gyro_rms_deg : float
        RMS angle between measured and predicted gravity directions after each move, deg.
    gyro_rms_deg_before : float
        The same with the starting guess of the gyro matrix (nominal scale only).
    n_moves : int
        Moves between consecutive still poses used by the gyro fit.
    sweep : tuple of SweepStep
        Every threshold tried.
    gyro_iterations : int
        Levenberg-Marquardt iterations of the gyro fit.
    """

    accel: TriadCalibration
    accel_model: str
    gyro: TriadCalibration
    intervals: tuple[tuple[int, int], ...]
    k: float
    accel_rms: float
    gyro_rms_deg: float
    gyro_rms_deg_before: float
    n_moves: int
    sweep: tuple[SweepStep, ...]
    gyro_iterations: int
    gyro_g_sensitivity: np.ndarray = field(default_factory=lambda: _ro(np.zeros((3, 3))))

    def apply_gyro(self, gyro: Any, acc: Any) -> np.ndarray:
        """Calibrated rates (rad/s) of raw gyro readings sampled with raw ``acc``:
        ``(gyro - offset - g_sensitivity @ acc_cal) @ matrix.T``."""
        a = self.accel.apply(acc)
        return (np.asarray(gyro, dtype=np.float64) - self.gyro.offset
                - a @ self.gyro_g_sensitivity.T) @ self.gyro.matrix.T


# --- quaternions (w, x, y, z), vectorised over leading axes -----------------------------------


def _qmul(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    pw, px, py, pz = p[..., 0], p[..., 1], p[..., 2], p[..., 3]
    qw, qx, qy, qz = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack(
        [
            pw * qw - px * qx - py * qy - pz * qz,
            pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw,
        ],
        axis=-1,
    )


def _qexp(rv: np.ndarray) -> np.ndarray:
    """Unit quaternion of rotation vectors (..., 3)."""
    ang = np.linalg.norm(rv, axis=-1)
    half = 0.5 * ang
    # sin(half)/ang with a series near zero
    small = ang < 1e-8
    safe = np.where(small, 1.0, ang)
    k = np.where(small, 0.5 - ang**2 / 48.0, np.sin(half) / safe)
    return np.concatenate([np.cos(half)[..., None], rv * k[..., None]], axis=-1)


def _qprod_tree(q: np.ndarray) -> np.ndarray:
    """Ordered product q[..., 0, :] * q[..., 1, :] * ... along axis -2, as a balanced tree."""
    while q.shape[-2] > 1:
        if q.shape[-2] % 2:
            ident = np.zeros(q.shape[:-2] + (1, 4))
            ident[..., 0] = 1.0
            q = np.concatenate([q, ident], axis=-2)
        q = _qmul(q[..., 0::2, :], q[..., 1::2, :])
        q /= np.linalg.norm(q, axis=-1, keepdims=True)
    return q[..., 0, :]


def _qrot_inv(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate v by the inverse (transpose) of q: R(q).T @ v, vectorised."""
    w = q[..., :1]
    u = -q[..., 1:]  # conjugate
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def _move_rotations(mats: np.ndarray, u: np.ndarray, dt: np.ndarray) -> np.ndarray:
    """Quaternions (B, P, 4) of every move for every candidate matrix.

    mats (B, 3, 3) rad/s per count; u (P, L, 3) bias-free counts, zero-padded; dt (P, L-1) s,
    zero where padded.
    """
    w = np.einsum("bij,plj->bpli", mats, u)  # (B, P, L, 3) rad/s
    w0, w1 = w[:, :, :-1], w[:, :, 1:]
    d = dt[None, :, :, None]
    rv = 0.5 * (w0 + w1) * d + np.cross(w0, w1) * (d * d / 12.0)
    return _qprod_tree(_qexp(rv))


def rotate_gravity(matrix: Any, gyro_counts: Any, t: Any, g0: Any) -> np.ndarray:
    """Predict the gravity direction after a move: ``R.T @ g0``.

    ``R`` is the attitude change integrated from ``(gyro_counts) @ matrix.T`` (rad/s, offset
    already removed) over the time stamps ``t`` (s).
    """
    u = np.asarray(gyro_counts, dtype=np.float64)[None]
    dt = np.diff(np.asarray(t, dtype=np.float64))[None]
    q = _move_rotations(np.asarray(matrix, dtype=np.float64)[None], u, dt)[0, 0]
    return _qrot_inv(q, np.asarray(g0, dtype=np.float64))


class _GyroProblem:
    """Residuals of the gyro fit for a batch of candidate matrices."""

    def __init__(self, u: np.ndarray, dt: np.ndarray, g0: np.ndarray, g1: np.ndarray,
                 chunk_bytes: float = 64e6) -> None:
        self.u, self.dt, self.g0, self.g1 = u, dt, g0, g1
        per = u.shape[0] * u.shape[1] * 3 * 8 * 6  # bytes per candidate, roughly
        self.chunk = max(1, int(chunk_bytes // max(per, 1)))

    def residuals(self, mats: np.ndarray) -> np.ndarray:
        """(B, P, 3): measured minus predicted gravity direction after each move."""
        out = []
        for i in range(0, mats.shape[0], self.chunk):
            q = _move_rotations(mats[i:i + self.chunk], self.u, self.dt)
            pred = _qrot_inv(q, self.g0[None])
            out.append(self.g1[None] - pred)
        return np.concatenate(out, axis=0)


def _lm(problem: _GyroProblem, m0: np.ndarray, max_iter: int, tol: float) -> tuple[np.ndarray, int]:
    """Levenberg-Marquardt over the 9 entries of the gyro matrix (forward-difference Jacobian)."""
    x = m0.reshape(9).copy()
    r = problem.residuals(x.reshape(1, 3, 3))[0].reshape(-1)
    cost = float(r @ r)
    lam = 1e-3
    iters = 0
    scale = np.abs(np.diag(m0)).mean()
    for it in range(1, max_iter + 1):
        iters = it
        h = 1e-6 * scale
        cand = np.repeat(x[None], 9, axis=0) + np.eye(9) * h
        rr = problem.residuals(cand.reshape(9, 3, 3)).reshape(9, -1)
        jac = ((rr - r[None]) / h).T  # (3P, 9)
        jtj = jac.T @ jac
        g = jac.T @ r
        improved = False
        for _ in range(12):
            a = jtj + lam * np.diag(np.diag(jtj))
            try:
                step = -np.linalg.solve(a, g)
            except np.linalg.LinAlgError:
                lam *= 10
                continue
            xn = x + step
            rn = problem.residuals(xn.reshape(1, 3, 3))[0].reshape(-1)
            cn = float(rn @ rn)
            if cn < cost:
                rel = (cost - cn) / max(cost, 1e-300)
                x, r, cost = xn, rn, cn
                lam = max(lam / 10, 1e-12)
                improved = True
                break
            lam *= 10
        if not improved or rel < tol:
            break
    return x.reshape(3, 3), iters


def calibrate_imu(
    acc: Any,
    gyro: Any,
    *,
    rate_hz: float,
    gravity: float = 9.80665,
    t: Any = None,
    rest_s: float = 3.0,
    window_s: float = 1.0,
    k_values: Sequence[float] = (2, 3, 4, 5, 6, 7, 8, 9, 10),
    min_still_s: float = 1.0,
    min_poses: int = 9,
    accel_model: str = "auto",
    gyro_offset: Any = None,
    gyro_g_sensitivity: bool = True,
    gyro_scale_guess: float | None = None,
    max_iter: int = 50,
    tol: float = 1e-10,
) -> ImuCalibration:
    """Calibrate accelerometer and gyroscope from still poses joined by hand rotations.

    Lay the sensor still for ``rest_s`` seconds (longer is better: the detector learns its
    noise there), then place it by hand in many (>= 9, ideally 30-40) different orientations,
    holding each for a few seconds.

    Parameters
    ----------
    acc, gyro : array_like, shape (N, 3)
        Raw accelerometer and gyro readings sampled together (counts, any offset).
    rate_hz : float
        Sampling rate, Hz (used for the detector's windows; see ``t`` for integration).
    gravity : float
        Local gravity in the units wanted for the accelerometer (9.80665 m/s^2, or 1.0 g).
    t : array_like (N,), optional
        Sample time stamps, s, for the gyro integration; ``None``: uniform at ``rate_hz``.
    rest_s, window_s, min_still_s
        Initial rest, sliding-window length and shortest still pose, s (see
        :func:`triaxcal.detect_still`).
    k_values : sequence of float
        Threshold multipliers to sweep (imu_tk: 1..10); the one whose accelerometer fit has
        the smallest rms residual is kept.
    min_poses : int
        Fewest still poses for a threshold to be considered (the full ellipsoid has 9
        unknowns).
    accel_model : {"auto", "full", "axis"}
        Accelerometer model: symmetric 3x3 (``"full"``), per-axis gains (``"axis"``), or
        ``"auto"``: full, unless the poses do not determine it (a fit that does not converge
        or has a condition number above 1e6, e.g. only the six faces of a cube), then axis.
    gyro_offset : array_like (3,), optional
        Gyro bias in counts, constant; ``None``: from the still intervals (see
        ``gyro_g_sensitivity``).
    gyro_g_sensitivity : bool
        Fit the gyro's rest reading in each still pose as ``offset + g_sensitivity @ acc_cal``
        (default) rather than one mean offset; ignored when ``gyro_offset`` is given.
    gyro_scale_guess : float, optional
        Nominal rad/s per count, to start the gyro fit; ``None``: found by a 1-D search.
    max_iter, tol
        Levenberg-Marquardt limits of the gyro fit (``max_iter`` in 1..10000, ``tol`` in
        [0, 1)).

    Returns
    -------
    ImuCalibration

    Raises
    ------
    CalibrationError
        Wrong shapes, NaN, no initial rest, too few still poses, moves too small, or rotations
        that leave a gyro axis unexcited; the message says which.
    """
    a = as_samples(acc, "acc")
    g = as_samples(gyro, "gyro")
    if a.shape[0] != g.shape[0]:
        raise CalibrationError(
            f"acc has {a.shape[0]} rows, gyro {g.shape[0]}: sample them together"
        )
    n = a.shape[0]
    rate = sample_rate(rate_hz)
    grav = opt.magnitude(gravity, "gravity", hint="9.80665 for m/s^2, 1.0 for g")
    rest = opt.number(rest_s, "rest_s", gt=0, hint="seconds of initial rest")
    win = opt.number(window_s, "window_s", gt=0, hint="seconds")
    min_still = opt.number(min_still_s, "min_still_s", ge=0, hint="seconds")
    ks = opt.numbers_list(k_values, "k_values", gt=0)
    min_p = opt.integer(min_poses, "min_poses", ge=6, hint="the per-axis model needs 6 poses")
    opt.choice(accel_model, "accel_model", ("auto", "full", "axis"))
    g_sens = opt.flag(gyro_g_sensitivity, "gyro_g_sensitivity")
    scale_guess = None if gyro_scale_guess is None else opt.magnitude(
        gyro_scale_guess, "gyro_scale_guess", hint="rad/s per count")
    iters_max = opt.integer(max_iter, "max_iter", ge=1, le=10_000)
    tol_f = opt.number(tol, "tol", ge=0, lt=1)
    g_off_given = None if gyro_offset is None else opt.vector3(gyro_offset, "gyro_offset",
                                                               hint="counts")
    if t is None:
        tt = np.arange(n) / rate
    else:
        tarr = np.asarray(t) if not isinstance(t, (str, bytes)) else np.asarray([t])
        if tarr.dtype.kind not in "iuf":
            raise CalibrationError(f"t must hold real numbers (seconds), got dtype {tarr.dtype}")
        tt = tarr.astype(np.float64).reshape(-1)
        if tt.shape[0] != n or not np.isfinite(tt).all() or np.any(np.diff(tt) <= 0):
            raise CalibrationError("t must hold one finite, strictly increasing time (s) per row")

    # 1. still intervals with a threshold sweep; keep the best accelerometer fit
    sweep: list[SweepStep] = []
    best = None
    best_n = 0
    fit_error = ""

    for k in ks:
        det = detect_still(a, rate_hz=rate, window_s=win, rest_s=rest, k=k,
                           min_duration_s=min_still)
        iv = det.intervals
        best_n = max(best_n, len(iv))
        if len(iv) < min_p:
            sweep.append(SweepStep(float(k), len(iv), float("nan")))
            continue
        pts = np.array([a[s:e].mean(axis=0) for s, e in iv])
        try:
            fit = _fit_accel(pts, grav, accel_model)
        except CalibrationError as exc:
            fit_error = str(exc)
            sweep.append(SweepStep(float(k), len(iv), float("nan")))
            continue
        sweep.append(SweepStep(float(k), len(iv), float(fit.rms)))
        rank = (fit.model != "full", fit.rms)  # a full model beats an axis fallback
        if best is None or rank < (best[2].model != "full", best[2].rms):
            best = (float(k), iv, fit)
    if best is None and fit_error:
        raise CalibrationError(
            f"the accelerometer fit failed on the {best_n} still poses found: {fit_error}"
        )
    if best is None:
        raise CalibrationError(
            f"found at most {best_n} still poses over thresholds k={list(ks)}, the "
            f"accelerometer fit needs at least {min_p}: hold the sensor still in more "
            f"orientations (>= {min_p}, ideally 30-40, each for > {min_still:g} s), after "
            f"an initial rest of {rest:g} s"
        )
    k_best, iv, afit = best
    accel = TriadCalibration(_ro(afit.offset), _ro(afit.matrix), "gravity units")

    # 2. gyro offset: constant (given), or offset + g-sensitivity fitted to the still poses
    means = np.array([a[s:e].mean(axis=0) for s, e in iv])
    pose_acc = accel.apply(means)  # gravity units
    k_ga = np.zeros((3, 3))
    if g_off_given is not None:
        g_off = g_off_given
    elif g_sens:
        g_off, k_ga = _gyro_rest_model(np.array([g[s:e].mean(axis=0) for s, e in iv]),
                                       pose_acc)
    else:
        g_off = np.concatenate([g[s:e] for s, e in iv]).mean(axis=0)
    acc_cal = accel.apply(a) if np.any(k_ga) else None

    # 3. gyro matrix from the moves between consecutive still poses
    dirs = pose_acc / np.linalg.norm(pose_acc, axis=1, keepdims=True)
    segs = []
    angles = []
    for i in range(len(iv) - 1):
        s0 = iv[i][1] - 1
        s1 = iv[i + 1][0]
        segs.append((s0, s1 + 1))
        angles.append(np.degrees(np.arccos(np.clip(dirs[i] @ dirs[i + 1], -1, 1))))
    angles_a = np.asarray(angles)
    use = angles_a >= 5.0
    if use.sum() < 3:
        raise CalibrationError(
            f"rotations too small: only {int(use.sum())} of {len(segs)} moves between still "
            "poses turned the gravity direction by 5 deg or more; the gyro fit needs at least "
            "3 such rotations, about different axes (turn by 30-90 deg between poses)"
        )
    sel = [segs[i] for i in np.flatnonzero(use)]
    lmax = max(e - s for s, e in sel)
    u = np.zeros((len(sel), lmax, 3))
    dt = np.zeros((len(sel), lmax - 1))
    for j, (s, e) in enumerate(sel):
        u[j, : e - s] = g[s:e] - g_off
        if acc_cal is not None:
            u[j, : e - s] -= acc_cal[s:e] @ k_ga.T
        dt[j, : e - s - 1] = np.diff(tt[s:e])
    g0 = dirs[:-1][use]
    g1 = dirs[1:][use]
    problem = _GyroProblem(u, dt, g0, g1)

    # the gyro must have registered the moves: each integral well above its noise
    noise = float(np.linalg.norm(np.concatenate([g[s:e] for s, e in iv]).std(axis=0)))
    lens = np.array([e - s for s, e in sel])
    integ = np.linalg.norm(np.einsum("pl,plk->pk", dt, 0.5 * (u[:, 1:] + u[:, :-1])), axis=1)
    felt = integ > 10 * noise * np.median(np.diff(tt)) * np.sqrt(lens)
    if felt.sum() < 3:
        raise CalibrationError(
            f"rotations too small for the gyro: only {int(felt.sum())} of {len(sel)} moves "
            "between still poses show a rotation above the gyro's noise; is the gyro channel "
            "connected, and are acc and gyro from the same recording?"
        )

    # excitation: integrated |rate| per raw axis, each must carry a share of the motion
    excite = np.array([np.sum(np.abs(u[j, :, :]) * np.r_[dt[j], 0][:, None], axis=0)
                       for j in range(len(sel))]).sum(axis=0)
    weak = [AXES[i] for i in range(3) if excite[i] < 0.05 * excite.max()]
    if weak:
        raise CalibrationError(
            f"rotations about the gyro's {', '.join(weak)} axis are missing (it turned by less "
            "than 5 % of the other axes); turn the sensor about every axis between poses"
        )

    if scale_guess is None:
        scale0 = _scale_search(problem, u, dt, g0, g1)
    else:
        scale0 = scale_guess
    m0 = scale0 * np.eye(3)
    r0 = problem.residuals(m0[None])[0]
    mg, iters = _lm(problem, m0, iters_max, tol_f)
    r1 = problem.residuals(mg[None])[0]
    jac_ok = _check_observable(problem, mg)
    if not jac_ok:
        raise CalibrationError(
            "the moves do not determine the 3x3 gyro matrix (rotations about too few "
            "directions): turn the sensor about each of its axes, and not only about the "
            "vertical, between still poses"
        )

    def _rms_deg(r: np.ndarray) -> float:
        return float(np.degrees(np.sqrt(np.mean(np.sum(r * r, axis=1)))))

    return ImuCalibration(
        accel=accel,
        accel_model=afit.model,
        gyro=TriadCalibration(_ro(g_off), _ro(mg), "rad/s"),
        intervals=tuple((int(s), int(e)) for s, e in iv),
        k=k_best,
        accel_rms=float(afit.rms),
        gyro_rms_deg=_rms_deg(r1),
        gyro_rms_deg_before=_rms_deg(r0),
        n_moves=len(sel),
        sweep=tuple(sweep),
        gyro_iterations=iters,
        gyro_g_sensitivity=_ro(k_ga),
    )


def _gyro_rest_model(rest_means: np.ndarray, pose_acc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares ``rest_means[i] = offset + k_ga @ pose_acc[i]`` over the still poses.

    Returns ``offset`` (3,) counts and ``k_ga`` (3, 3) counts per unit of acceleration. Poses
    that do not span three directions of gravity cannot
    separate the offset from the g-sensitivity: with fewer than 5 poses, or poses in one plane,
    the plain mean and zeros are returned.
    """
    design = np.column_stack([np.ones(len(pose_acc)), pose_acc])
    sv = np.linalg.svd(design / np.linalg.norm(design, axis=0), compute_uv=False)
    if len(pose_acc) < 5 or sv[-1] < 1e-3 * sv[0]:
        return rest_means.mean(axis=0), np.zeros((3, 3))
    coef, *_ = np.linalg.lstsq(design, rest_means, rcond=None)
    return coef[0], coef[1:].T


def _fit_accel(pts: np.ndarray, grav: float, model: str) -> Any:
    if model not in ("auto", "full", "axis"):
        raise CalibrationError(f"accel_model must be 'auto', 'full' or 'axis', got {model!r}")
    if model != "auto":
        return fit_ellipsoid(pts, model=model, radius=grav)
    try:
        full = fit_ellipsoid(pts, model="full", radius=grav)
        if full.converged and full.condition < 1e6:
            return full
    except CalibrationError:
        pass
    return fit_ellipsoid(pts, model="axis", radius=grav)


def _scale_search(problem: _GyroProblem, u: np.ndarray, dt: np.ndarray, g0: np.ndarray,
                  g1: np.ndarray) -> float:
    """Nominal rad/s per count: the scalar (times identity) that best explains the moves."""
    # a first guess: measured angle / integrated |rate|, then a log-spaced search around it
    integ = np.array([np.linalg.norm(np.sum(0.5 * (u[j, 1:] + u[j, :-1]) * dt[j][:, None],
                                            axis=0)) for j in range(u.shape[0])])
    ang = np.arccos(np.clip(np.sum(g0 * g1, axis=1), -1, 1))
    ok = integ > 0
    guess = float(np.median(ang[ok] / integ[ok])) if ok.any() else 1.0
    grid = guess * np.logspace(-1, 1, 41)
    best = guess
    for _ in range(3):
        mats = grid[:, None, None] * np.eye(3)[None]
        cost = np.sum(problem.residuals(mats) ** 2, axis=(1, 2))
        i = int(np.argmin(cost))
        best = float(grid[i])
        lo = grid[max(i - 1, 0)]
        hi = grid[min(i + 1, len(grid) - 1)]
        grid = np.geomspace(lo, hi, 21)
    return best


def _check_observable(problem: _GyroProblem, m: np.ndarray) -> bool:
    x = m.reshape(9)
    h = 1e-6 * np.abs(np.diag(m)).mean()
    cand = np.vstack([x[None], x[None] + np.eye(9) * h])
    rr = problem.residuals(cand.reshape(10, 3, 3)).reshape(10, -1)
    jac = (rr[1:] - rr[:1]) / h
    sv = np.linalg.svd(jac, compute_uv=False)
    return bool(sv[-1] > 1e-6 * sv[0])
