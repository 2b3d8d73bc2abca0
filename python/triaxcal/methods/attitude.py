"""Compass calibration from a flight: the logged attitude and the Earth's field.

A vehicle's attitude estimate (ArduPilot ``ATT``, PX4 ``vehicle_attitude``) says how the body
was turned at each compass reading; the Earth's field in the north-east-down frame (from the
World Magnetic Model at the log's position, or fitted when unknown) then says what the compass
should have read. This module fits the compass so that it does, the idea of ArduPilot's MAGFit
(MAVProxy ``MAVProxy/modules/lib/magfit.py``) and CompassLearn.

Error model (body frame, the frame ArduPilot corrects in; mG or any field unit)::

    c_i = M @ (raw_i - o) + v * x_i          calibrated reading
    r_i = c_i - R_i.T @ B                    residual, heading="attitude"

``o`` the hard iron (raw units), ``M`` the symmetric soft-iron matrix (it **multiplies**),
``x_i`` the interference regressor (battery current in A, or throttle 0..1) and ``v`` the
field it adds per unit (ArduPilot's ``COMPASS_MOT``, added after the matrix as
``AP_Compass_Backend::correct_field`` does), ``R_i`` the attitude (body to NED), ``B`` the
Earth's field in NED. With ``heading="free"`` the attitude's yaw is not used, only its roll and
pitch: the calibrated reading turned level, ``h_i = T_i @ c_i``, must have the field's
horizontal strength and vertical component, ``r_i = (|h_xy| - H, h_z - Z)``. That is the
criterion of MAGFit (which turns the expected field by the heading the corrected compass itself
gives), here in least squares; it is what a log allows whose attitude took its yaw from this
very compass, since comparing a compass with a heading made from it would be circular.

The minimisation is Levenberg-Marquardt with analytic derivatives, vectorised over the
samples in numpy (a few milliseconds for thousands of samples), with one round that drops
readings whose residual is more than ``REJECT_MAD`` robust deviations out (spikes, a motor
start). Unknown field: the field is fitted too; its strength and the gains then trade off (the
data cannot tell a stronger field from a larger gain), so the mean of the three gains is held
at 1 (``diag_x = 3 - diag_y - diag_z``) and the field's strength is the readings' own. Holding
one axis's gain instead would leave the others free to shrink towards a compass that reads a
constant, which a level flight with roll and pitch only (``heading="free"``) cannot refute.

What the data determine is read from the fit's covariance: a parameter whose standard error
exceeds its tolerance (:mod:`triaxcal.quality.bounds`: ``ATTITUDE_TOLERANCE``) is not
determined. Soft-iron terms that are not determined are held at their prior (1 on the
diagonal, 0 off it, or the stored calibration's) and the fit repeated; the part records them
under ``held`` (e.g. level yaw turns only: no z soft iron). Offsets, interference or the field
that are not determined are recorded under ``undetermined``, which the validity gate refuses.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..conventions.rotations import euler_to_dcm, quat_to_dcm
from ..errors import CalibrationError
from ..quality import bounds as B

__all__ = [
    "HEADINGS",
    "SOFT_IRON",
    "AttitudeFit",
    "euler_to_dcm",
    "fit_attitude",
    "quat_to_dcm",
    "tilt_dcm",
]

#: How the attitude's yaw is used: ``"attitude"`` (the full field vector), ``"free"`` (roll
#: and pitch only).
HEADINGS = ("attitude", "free")
#: Soft-iron models: full symmetric matrix, diagonal, one scale.
SOFT_IRON = ("full", "diagonal", "scale")

#: Residuals further out than this many robust standard deviations (1.4826 MAD) are dropped
#: once and the fit repeated.
REJECT_MAD = 5.0
_MAX_ITER = 200
#: Weight of the prior on the soft-iron terms while deciding which of them the data determine,
#: as a share of the field on one reading, times the square root of the number of readings.
PRIOR_WEIGHT = 0.05
_UPPER = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))
_M_NAMES = ("diag_x", "diag_y", "diag_z", "offdiag_xy", "offdiag_xz", "offdiag_yz")


def tilt_dcm(dcm: np.ndarray) -> np.ndarray:
    """The roll-and-pitch part of body-to-NED matrices: ``Ry(pitch) Rx(roll)`` (yaw removed),
    which turns a body vector into the level frame that points along the body's heading."""
    pitch = np.arcsin(np.clip(-dcm[:, 2, 0], -1.0, 1.0))
    roll = np.arctan2(dcm[:, 2, 1], dcm[:, 2, 2])
    return euler_to_dcm(np.degrees(roll), np.degrees(pitch), np.zeros(len(dcm)))


@dataclass(frozen=True, eq=False)
class AttitudeFit:
    """The result of :func:`fit_attitude` (units: those of the readings, e.g. mG).

    ``calibrated = (raw - offset) @ matrix.T + interference * x``: ``offset`` is SUBTRACTED,
    ``matrix`` MULTIPLIES, ``interference`` (per unit of ``x``: A or throttle) is ADDED after
    the matrix, in the body frame. ``field_ned`` is the Earth's field used or fitted.
    """

    offset: np.ndarray
    matrix: np.ndarray
    interference: np.ndarray | None
    field_ned: np.ndarray
    heading: str
    soft_iron: str
    field_fitted: bool
    rms: float
    n: int
    rejected: np.ndarray
    iterations: int
    converged: bool
    stderr: dict[str, float]
    held: dict[str, str] = field(default_factory=dict)
    undetermined: tuple[str, ...] = ()
    param_names: tuple[str, ...] = ()

    @property
    def field_strength(self) -> float:
        """``|B|``, in the readings' unit."""
        return float(np.linalg.norm(self.field_ned))

    @property
    def rms_pct(self) -> float:
        """The residual RMS as a share of the field (%)."""
        return 100.0 * self.rms / self.field_strength

    def apply(self, raw: Any, x: Any = None) -> np.ndarray:
        """Calibrated readings (N, 3) of raw body-frame readings, with the interference."""
        c = (np.asarray(raw, float).reshape(-1, 3) - self.offset) @ self.matrix.T
        if self.interference is not None:
            if x is None:
                raise CalibrationError("this fit has an interference term: give x (the current "
                                       "or throttle at each reading)")
            c = c + np.asarray(x, float).reshape(-1, 1) * self.interference
        return c


def _check_inputs(raw: Any, dcm: Any, x: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    r = np.asarray(raw, dtype=np.float64)
    if r.ndim != 2 or r.shape[1] != 3:
        raise CalibrationError(f"compass readings must have shape (N, 3), got {r.shape}")
    d = np.asarray(dcm, dtype=np.float64)
    if d.shape != (len(r), 3, 3):
        raise CalibrationError(f"attitudes must be one (3, 3) rotation per reading, got {d.shape} "
                               f"for {len(r)} readings")
    xs = None
    if x is not None:
        xs = np.asarray(x, dtype=np.float64).ravel()
        if xs.shape != (len(r),):
            raise CalibrationError(f"the interference regressor needs one value per reading, got "
                                   f"{xs.shape} for {len(r)}")
    ok = np.isfinite(r).all(axis=1) & np.isfinite(d).all(axis=(1, 2))
    if xs is not None:
        ok &= np.isfinite(xs)
    if not ok.all():
        raise CalibrationError(f"{int((~ok).sum())} readings, attitudes or regressor values are "
                               "not finite")
    if len(r) < 30:
        raise CalibrationError(f"a flight calibration needs at least 30 readings with attitude, "
                               f"got {len(r)}")
    return r, d, xs


class _Model:
    """Parameter layout and residuals/Jacobian of one configuration."""

    def __init__(self, raw: np.ndarray, dcm: np.ndarray, x: np.ndarray | None, heading: str,
                 soft: str, field_ned: np.ndarray | None, strength: float,
                 held: dict[int, float], prior_weight: float = 0.0,
                 mean_gain: bool = False) -> None:
        self.raw, self.dcm, self.x = raw, dcm, x
        self.heading, self.soft = heading, soft
        self.known = field_ned
        self.strength = strength
        self.held = held  # index in _UPPER -> value
        self.m_prior = np.zeros(0)
        self.prior_weight = prior_weight
        # the mean of the three gains held at 1: diag_x = 3 - diag_y - diag_z (field unknown)
        self.mean_gain = mean_gain and soft != "scale"
        self.m_free = [k for k in range(6) if k not in held and
                       not (self.mean_gain and k == 0) and
                       (soft == "full" or (soft == "diagonal" and k < 3) or
                        (soft == "scale" and k == 0))]
        if heading == "free":
            self.tilt = tilt_dcm(dcm)
        names = ["offset_x", "offset_y", "offset_z"]
        names += [_M_NAMES[k] if soft != "scale" else "scale" for k in self.m_free]
        if x is not None:
            names += ["interference_x", "interference_y", "interference_z"]
        if field_ned is None:
            names += ["field_n", "field_e", "field_d"] if heading == "attitude" else [
                "field_h", "field_d"]
        self.names = tuple(names)

    def matrix(self, p: np.ndarray) -> np.ndarray:
        m = np.zeros((3, 3))
        vals = dict(self.held)
        for k, v in zip(self.m_free, p[3:3 + len(self.m_free)]):
            vals[k] = v
        if self.soft == "scale":
            s = vals.get(0, 1.0)
            return np.eye(3) * s
        if self.mean_gain:
            vals[0] = 3.0 - vals.get(1, 1.0) - vals.get(2, 1.0)
        for k in range(6):
            i, j = _UPPER[k]
            v = vals.get(k, 1.0 if k < 3 else 0.0)
            if self.soft == "diagonal" and k >= 3:
                v = 0.0
            m[i, j] = m[j, i] = v
        return m

    def unpack(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray | None,
                                             np.ndarray]:
        o = p[:3]
        k = 3 + len(self.m_free)
        v = None
        if self.x is not None:
            v = p[k:k + 3]
            k += 3
        if self.known is not None:
            b = self.known
        elif self.heading == "attitude":
            b = p[k:k + 3].copy()
        else:
            b = np.array([p[k], 0.0, p[k + 1]])
        return o, self.matrix(p), v, b

    def prior_rows(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Weak pull of the free soft-iron terms towards their prior (the identity times the
        starting scale): it pins what the data leave free without moving what they decide
        (weight ``prior_weight`` times the field per unit; none in the final fit)."""
        k = len(self.m_free)
        w = self.prior_weight * self.strength
        rows = np.zeros((k, len(p)))
        for i in range(k):
            rows[i, 3 + i] = w
        return w * (p[3:3 + k] - self.m_prior), rows

    def solve_rows(self, p: np.ndarray, idx: np.ndarray, jac: bool = True
                   ) -> tuple[np.ndarray, np.ndarray | None]:
        """The residuals and Jacobian the minimisation sees: data and prior rows."""
        r, j = self.residuals(p, idx, jac)
        pr, pj = self.prior_rows(p)
        return np.concatenate([r, pr]), None if j is None else np.vstack([j, pj])

    def residuals(self, p: np.ndarray, idx: np.ndarray, jac: bool = True
                  ) -> tuple[np.ndarray, np.ndarray | None]:
        o, m, v, b = self.unpack(p)
        raw = self.raw[idx]
        d = raw - o
        c = d @ m.T
        x = None if self.x is None else self.x[idx]
        if x is not None:
            c = c + x[:, None] * v
        n, npar = len(idx), len(p)
        dc = None
        if jac:
            dc = np.zeros((n, 3, npar))
            dc[:, :, 0:3] = -m[None, :, :]
            for col, k in enumerate(self.m_free, start=3):
                if self.soft == "scale":
                    dc[:, :, col] = d
                    continue
                i, j = _UPPER[k]
                dc[:, i, col] = d[:, j]
                if i != j:
                    dc[:, j, col] = d[:, i]
                elif self.mean_gain:  # diag_x = 3 - diag_y - diag_z moves with it
                    dc[:, 0, col] -= d[:, 0]
            k = 3 + len(self.m_free)
            if x is not None:
                for a in range(3):
                    dc[:, a, k + a] = x
                k += 3
        if self.heading == "attitude":
            dcm = self.dcm[idx]
            pred = np.einsum("nji,j->ni", dcm, b)  # R.T @ B
            r = c - pred
            if not jac:
                return r.ravel(), None
            assert dc is not None
            if self.known is None:
                dc[:, :, -3:] = -dcm.transpose(0, 2, 1)
            return r.ravel(), dc.reshape(3 * n, npar)
        t = self.tilt[idx]
        h = np.einsum("nij,nj->ni", t, c)
        hh = np.hypot(h[:, 0], h[:, 1])
        hh_safe = np.where(hh > 0, hh, 1.0)
        big_h = math.hypot(b[0], b[1])
        r = np.column_stack([hh - big_h, h[:, 2] - b[2]])
        if not jac:
            return r.ravel(), None
        assert dc is not None
        dh = np.einsum("nij,njp->nip", t, dc)
        out = np.empty((n, 2, npar))
        out[:, 0, :] = (h[:, 0, None] * dh[:, 0, :] + h[:, 1, None] * dh[:, 1, :]) / hh_safe[:,
                                                                                            None]
        out[:, 1, :] = dh[:, 2, :]
        if self.known is None:
            out[:, :, -2:] = -np.eye(2)
        return r.ravel(), out.reshape(2 * n, npar)


def _lm(model: _Model, p0: np.ndarray, idx: np.ndarray) -> tuple[np.ndarray, int, bool]:
    """Levenberg-Marquardt (Marquardt's diagonal scaling)."""
    p = p0.copy()
    model.m_prior = p0[3:3 + len(model.m_free)].copy()
    r, j = model.solve_rows(p, idx)
    cost = float(r @ r)
    lam = 1e-3
    for it in range(1, _MAX_ITER + 1):
        assert j is not None
        jtj = j.T @ j
        g = j.T @ r
        diag = np.diag(jtj).copy()
        diag[diag <= 0] = 1.0
        improved = False
        for _ in range(12):
            try:
                step = np.linalg.solve(jtj + lam * np.diag(diag), -g)
            except np.linalg.LinAlgError:
                lam *= 10
                continue
            pn = p + step
            rn, _ = model.solve_rows(pn, idx, jac=False)
            cn = float(rn @ rn)
            if np.isfinite(cn) and cn <= cost:
                improved = True
                small = np.all(np.abs(step) <= 1e-10 * (np.abs(p) + 1e-6)) or \
                    cost - cn <= 1e-14 * max(cost, 1e-300)
                p, cost = pn, cn
                lam = max(lam / 10, 1e-12)
                break
            lam *= 10
        if not improved:
            return p, it, True  # no step lowers the cost: a minimum (to rounding)
        r, j = model.solve_rows(p, idx)
        if small:
            return p, it, True
    return p, _MAX_ITER, False


def _initial(raw: np.ndarray) -> tuple[np.ndarray, float]:
    """Offset and radius of the linear sphere fit ``|raw - o|^2 = r^2`` (a starting point)."""
    a = np.column_stack([2 * raw, np.ones(len(raw))])
    y = (raw * raw).sum(axis=1)
    sol, *_ = np.linalg.lstsq(a, y, rcond=None)
    o = sol[:3]
    r2 = sol[3] + o @ o
    radius = math.sqrt(r2) if r2 > 0 else float(np.linalg.norm(raw - raw.mean(0), axis=1).mean())
    return o, radius


def fit_attitude(
    raw: Any,
    attitude: Any,
    *,
    x: Any = None,
    field_ned: Any = None,
    heading: str = "attitude",
    soft_iron: str = "full",
    prior_matrix: Any = None,
) -> AttitudeFit:
    """Fit a compass to the Earth's field turned by the logged attitude (module docstring).

    Parameters
    ----------
    raw : array_like (N, 3)
        Raw compass readings in the body frame (the autopilot's calibration undone), e.g. mG.
    attitude : array_like (N, 3, 3)
        Body-to-NED rotation at each reading (:func:`euler_to_dcm`, :func:`quat_to_dcm`).
    x : array_like (N,), optional
        The interference regressor at each reading: battery current (A) or throttle (0..1).
        Without it no interference is fitted.
    field_ned : array_like (3,), optional
        The Earth's field (north, east, down) in the readings' unit (the World Magnetic
        Model's). Without it the field is fitted too, and the overall scale, which the data
        then cannot tell from the field's strength, is set by holding the mean gain at 1.
    heading : {"attitude", "free"}
        Use the attitude's yaw (the field vector) or only its roll and pitch.
    soft_iron : {"full", "diagonal", "scale"}
        The soft-iron model; terms the data do not determine are held (see ``held``).
    prior_matrix : array_like (3, 3), optional
        What held soft-iron terms are held at (default: the identity).

    Returns
    -------
    AttitudeFit

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> n = 600
    >>> att = euler_to_dcm(rng.uniform(-30, 30, n), rng.uniform(-30, 30, n),
    ...                    rng.uniform(0, 360, n))
    >>> b = np.array([200.0, 10.0, 450.0])                      # mG, NED
    >>> cur = rng.uniform(0, 20, n)                             # A
    >>> clean = np.einsum("nji,j->ni", att, b) - cur[:, None] * [2.0, -1.0, 3.0]
    >>> raw = clean @ np.linalg.inv(np.diag([1.05, 0.97, 1.0])).T + [80.0, -40.0, 25.0]
    >>> fit = fit_attitude(raw, att, x=cur, field_ned=b)
    >>> np.round(fit.offset, 3).tolist(), np.round(fit.interference, 3).tolist()
    ([80.0, -40.0, 25.0], [2.0, -1.0, 3.0])
    """
    r, dcm, xs = _check_inputs(raw, attitude, x)
    if heading not in HEADINGS:
        raise CalibrationError(f"heading must be one of {HEADINGS}, got {heading!r}")
    if soft_iron not in SOFT_IRON:
        raise CalibrationError(f"soft_iron must be one of {SOFT_IRON}, got {soft_iron!r}")
    known = None
    if field_ned is not None:
        known = np.asarray(field_ned, dtype=np.float64).ravel()
        if known.shape != (3,) or not np.isfinite(known).all() or not np.linalg.norm(known) > 0:
            raise CalibrationError(f"field_ned must be three finite numbers (north, east, down), "
                                   f"not all zero, got {field_ned!r}")
    prior = np.eye(3) if prior_matrix is None else np.asarray(prior_matrix, float)
    if prior.shape != (3, 3) or not np.isfinite(prior).all():
        raise CalibrationError("prior_matrix must be a finite (3, 3) matrix")
    o0, radius = _initial(r)
    held: dict[int, float] = {}
    held_why: dict[str, str] = {}
    mean_gain = known is None and soft_iron != "scale"
    if known is not None:
        f0 = float(np.linalg.norm(known))
    else:
        f0 = radius
        if soft_iron == "scale":
            held[0] = 1.0
        held_why["scale" if soft_iron == "scale" else "mean_gain"] = (
            "held at 1: without the field's strength (no position for the World Magnetic "
            "Model) the data cannot tell the scale from the field; "
            + ("the scale is 1" if soft_iron == "scale" else
               "the mean of the three gains is 1 (diag_x = 3 - diag_y - diag_z)"))
    idx = np.arange(len(r))
    rejected = np.zeros(0, dtype=np.int64)
    # 1. which soft-iron terms do the data determine? A prior as strong as the data pins the
    #    ones they leave free (at their starting value), so that their standard errors are
    #    read where they would be held rather than wherever a free direction wandered to.
    model = _Model(r, dcm, xs, heading, soft_iron, known, f0, held,
                   prior_weight=PRIOR_WEIGHT * math.sqrt(len(r)), mean_gain=mean_gain)
    p, _, _ = _lm(model, _start(model, o0, radius, f0, xs), idx)
    se = _geometry_stderr(model, p, idx)
    tol = B.ATTITUDE_TOLERANCE["soft_iron"]
    for col, k in enumerate(model.m_free, start=3):
        if not se[col] <= tol:
            i, j = _UPPER[k]
            held[k] = float(prior[i, j]) if soft_iron != "scale" else 1.0
            held_why[model.names[col]] = (
                f"held at {held[k]:g}: the flight does not determine it (standard error "
                f"{se[col]:.3g}, at most {tol:g})")
    # 2. the fit of what is determined; 3. once more without the outliers
    for round_ in range(2):
        model = _Model(r, dcm, xs, heading, soft_iron, known, f0, held, mean_gain=mean_gain)
        p, iters, converged = _lm(model, _start(model, o0, radius, f0, xs), idx)
        res, jac = model.residuals(p, idx)
        assert jac is not None
        rms = math.sqrt(float(res @ res) / len(res))
        se = _geometry_stderr(model, p, idx)
        und = _undetermined(model, se, f0, xs, known is None)
        if und or round_ == 1:
            break
        e = np.sqrt((res.reshape(len(idx), -1) ** 2).sum(axis=1))
        med = float(np.median(e))
        mad = 1.4826 * float(np.median(np.abs(e - med)))
        bad = e > med + REJECT_MAD * max(mad, 1e-12 * f0)
        if not bad.any():
            break
        rejected = idx[bad]
        idx = idx[~bad]
    o, m, v, b = model.unpack(p)
    stderr = {name: float(s) for name, s in zip(model.names, se)}
    return AttitudeFit(offset=o.copy(), matrix=m, interference=None if v is None else v.copy(),
                       field_ned=b, heading=heading, soft_iron=soft_iron,
                       field_fitted=known is None, rms=rms, n=len(idx), rejected=rejected,
                       iterations=iters, converged=converged, stderr=stderr, held=held_why,
                       undetermined=tuple(und), param_names=model.names)


def _stderr(jac: np.ndarray, sigma2: float) -> np.ndarray:
    """Standard errors of the parameters from the Jacobian at the minimum; a direction the
    data do not determine at all (a singular value below 1e-9 of the largest, after scaling
    the columns to unit length) gives an infinite error to every parameter it moves."""
    jtj = jac.T @ jac
    norms = np.sqrt(np.diag(jtj)).copy()
    norms[norms == 0] = 1.0
    ev, vec = np.linalg.eigh(jtj / np.outer(norms, norms))  # singular values squared
    cut = ev > 1e-18 * max(float(ev[-1]), 1e-300)
    var = (vec[:, cut] ** 2) @ (1.0 / ev[cut])
    free = (np.abs(vec[:, ~cut]) > 1e-3).any(axis=1) if (~cut).any() else np.zeros(len(norms),
                                                                                     bool)
    se = np.sqrt(var * sigma2) / norms
    se[free] = np.inf
    return se


def _geometry_stderr(model: _Model, p: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """Standard errors of the parameters, with the Jacobian taken at the readings the fitted
    model predicts from the attitude rather than at the noisy ones: the compass's own noise
    would otherwise pass for variation that determines a term (a level yaw turn's z reading
    varies by its noise only, which would seem to determine the z gain)."""
    o, m, v, b = model.unpack(p)
    pred = np.einsum("nji,j->ni", model.dcm[idx], b)
    if v is not None and model.x is not None:
        pred = pred - model.x[idx, None] * v
    try:
        clean = pred @ np.linalg.inv(m).T + o
    except np.linalg.LinAlgError:
        return np.full(len(p), np.inf)
    res, _ = model.residuals(p, idx, jac=False)
    raw = model.raw
    model.raw = raw.copy()
    model.raw[idx] = clean
    try:
        _, jac = model.residuals(p, idx)
    finally:
        model.raw = raw
    assert jac is not None
    return _stderr(jac, float(res @ res) / max(len(res) - len(p), 1))


def _start(model: _Model, o0: np.ndarray, radius: float, f0: float,
           xs: np.ndarray | None) -> np.ndarray:
    p = list(o0)
    scale = f0 / radius if radius > 0 else 1.0
    for k in model.m_free:
        p.append(scale if k < 3 else 0.0)
    if xs is not None:
        p += [0.0, 0.0, 0.0]
    if model.known is None:
        c = (model.raw - o0) * scale
        if model.heading == "attitude":
            p += list(np.einsum("nij,nj->i", model.dcm, c) / len(c))
        else:
            h = np.einsum("nij,nj->ni", tilt_dcm(model.dcm), c)
            p += [float(np.hypot(h[:, 0], h[:, 1]).mean()), float(h[:, 2].mean())]
    return np.array(p, dtype=np.float64)


def _undetermined(model: _Model, se: np.ndarray, f0: float, xs: np.ndarray | None,
                  fitted: bool) -> list[str]:
    tol = B.ATTITUDE_TOLERANCE
    out: list[str] = []
    lim = tol["offset_of_field"] * f0
    bad = [a for a, s in zip("xyz", se[:3]) if not s <= lim]
    if bad:
        out.append(
            f"the flight does not determine the {'/'.join(bad)} offset (standard error "
            f"{max(se[:3]):.3g}, at most {lim:.3g}: {100 * tol['offset_of_field']:g} % of the "
            "field): not enough turning; fly turns through every heading, with some roll and "
            "pitch")
    k = 3 + len(model.m_free)
    if xs is not None:
        span = float(np.max(np.abs(xs))) if len(xs) else 0.0
        lim_v = tol["interference_of_field"] * f0 / span if span > 0 else 0.0
        worst = float(np.max(se[k:k + 3]))
        if not worst <= lim_v:
            out.append(
                f"the flight does not determine the interference per unit of current/throttle "
                f"(standard error {worst:.3g} per unit, at most {lim_v:.3g}): the current or "
                "throttle hardly varied, or varied only with the attitude; fly with changing "
                "throttle in every direction")
        k += 3
    if fitted:
        worst = float(np.max(se[k:]))
        lim_b = tol["field_of_field"] * f0
        if not worst <= lim_b:
            out.append(f"the flight does not determine the Earth's field (standard error "
                       f"{worst:.3g}, at most {lim_b:.3g}): not enough turning; or give the place "
                       "of the flight (--location) for the World Magnetic Model's field")
    return out
