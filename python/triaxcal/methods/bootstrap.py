"""How far to trust a calibration: bootstrap confidence intervals for every coefficient.

Error model (the fits', :mod:`triaxcal.fit`): ``calibrated = (raw - offset) @ matrix.T``; the
coefficients are ``offset_x..z`` (raw units), ``diag_x..z`` and ``offdiag_xy, xz, yz``
(calibrated units per raw unit; the matrix **multiplies**), or ``data_radius`` (raw units) for
the sphere model -- the names of :attr:`triaxcal.EllipsoidFit.param_names`.

The fit's standard errors are asymptotic: they come from the curvature of the sum of squares at
the solution and assume many readings spread evenly with small, independent noise. The
bootstrap asks the data instead: draw the readings (or whole poses, ``groups``) with
replacement, refit, many times (in one call of the parallel batch engine,
:func:`triaxcal.fit_batch`), and read the spread of the refits. The interval is the percentile
interval of the refits (at ``level``, default 95 %), widened about the estimate by ``sqrt(N /
(N - P))`` for the ``P`` coefficients fitted to ``N`` readings (or poses), with a fixed seed so
that the same data give the same interval. A coefficient is *flagged* when half its interval
exceeds what firmware needs: by default 1 % of the radius in raw units for an offset, 1 % of
the mean gain for a gain or cross-axis term.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._checks import options as opt
from .._checks.arrays import as_samples
from ..errors import CalibrationError
from ..fit.ellipsoid import EllipsoidFit, fit_batch, fit_ellipsoid

__all__ = ["MAX_BOOTSTRAP", "BootstrapIntervals", "bootstrap", "fit_params"]

#: Most refits one call may ask for (each is a full fit; 10,000 resamples give 95 % intervals
#: to well under a percent of their width; 10^7 would run for hours).
MAX_BOOTSTRAP = 10_000

#: Default tolerances: offset as a fraction of the raw radius, gains as a fraction of the gain.
OFFSET_TOL = 0.01
GAIN_TOL = 0.01

_UPPER = ((0, 1), (0, 2), (1, 2))


def fit_params(model: str, offsets: Any, matrices: Any, radii: Any,
               radius: float | None) -> np.ndarray:
    """The coefficient vectors (B, P) of fits, in the order of ``param_names`` of ``model``."""
    o = np.asarray(offsets, dtype=np.float64).reshape(-1, 3)
    m = np.asarray(matrices, dtype=np.float64).reshape(-1, 3, 3)
    cols = [o[:, 0], o[:, 1], o[:, 2]]
    if model == "sphere":
        r = np.asarray(radii, dtype=np.float64).reshape(-1)
        cols.append(r / m[:, 0, 0] if radius is not None else r)
    else:
        cols += [m[:, 0, 0], m[:, 1, 1], m[:, 2, 2]]
        if model == "full":
            cols += [m[:, i, j] for i, j in _UPPER]
    return np.column_stack(cols)


@dataclass(frozen=True)
class BootstrapIntervals:
    """Bootstrap confidence intervals of a fit's coefficients.

    Attributes
    ----------
    param_names : tuple of str
        Coefficient names (as :attr:`triaxcal.EllipsoidFit.param_names`).
    estimate : ndarray (P,)
        The coefficients fitted on all the data.
    stderr : ndarray (P,)
        The fit's asymptotic standard errors.
    boot_std : ndarray (P,)
        Standard deviation of the bootstrap refits.
    lower, upper : ndarray (P,)
        The percentile interval at ``level``.
    level : float
        Coverage the interval is meant to have (0.95).
    n_boot : int
        Refits that succeeded (``n_failed`` did not and are left out).
    n_failed : int
    resample : str
        ``"readings"`` or ``"poses"`` (whole groups of readings).
    seed : int
    tolerance : ndarray (P,)
        Half-width above which a coefficient is flagged (units of the coefficient).
    raw_radius : float
        Radius in raw units, the yardstick of the offset tolerance.
    units : dict
        Unit of each coefficient.
    """

    param_names: tuple[str, ...]
    estimate: np.ndarray
    stderr: np.ndarray
    boot_std: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    level: float
    n_boot: int
    n_failed: int
    resample: str
    seed: int
    tolerance: np.ndarray
    raw_radius: float
    units: dict[str, str] = field(default_factory=dict)

    @property
    def half_width(self) -> np.ndarray:
        """Half the width of each interval."""
        return (self.upper - self.lower) / 2.0

    @property
    def flagged(self) -> tuple[str, ...]:
        """Coefficients whose interval is wider than firmware needs (see ``tolerance``)."""
        return tuple(n for n, h, t in zip(self.param_names, self.half_width, self.tolerance)
                     if h > t)

    def as_dict(self) -> dict[str, Any]:
        """Plain JSON values (what a calibration file stores under ``stats["intervals"]``)."""
        return {
            "level": self.level,
            "n_boot": self.n_boot,
            "n_failed": self.n_failed,
            "resample": self.resample,
            "seed": self.seed,
            "raw_radius": self.raw_radius,
            "coefficients": {
                n: {"estimate": float(e), "stderr": float(s), "boot_std": float(b),
                    "lower": float(lo), "upper": float(hi), "tolerance": float(t)}
                for n, e, s, b, lo, hi, t in zip(self.param_names, self.estimate, self.stderr,
                                                 self.boot_std, self.lower, self.upper,
                                                 self.tolerance)
            },
            "flagged": list(self.flagged),
            "warnings": self.warnings(),
        }

    def warnings(self) -> list[str]:
        """One plain-language warning per flagged coefficient, with what to do."""
        out = []
        pct = round(100 * self.level)
        for n, h, t in zip(self.param_names, self.half_width, self.tolerance):
            if h <= t:
                continue
            u = self.units.get(n, "")
            what = (f"{100 * h / self.raw_radius:.2g} % of the radius"
                    if n.startswith("offset") or n == "data_radius"
                    else f"{100 * h / (t / GAIN_TOL):.2g} % of the gain" if t > 0 else "")
            out.append(
                f"{n} is uncertain by +-{h:.3g} {u} ({what}; {pct} % bootstrap interval), more "
                "than firmware should accept: collect more readings, spread over more "
                "orientations, and hold the board still in each"
            )
        return out

    def text(self) -> str:
        """The table of estimates, standard errors and intervals."""
        pct = round(100 * self.level)
        lines = [f"  coefficients   estimate      stderr      {pct} % bootstrap interval "
                 f"({self.n_boot} refits over {self.resample}, seed {self.seed})"]
        for i, n in enumerate(self.param_names):
            flag = "  <- wide" if self.half_width[i] > self.tolerance[i] else ""
            lines.append(f"    {n:<12} {self.estimate[i]:>12.6g} {self.stderr[i]:>11.3g}   "
                         f"[{self.lower[i]:.6g}, {self.upper[i]:.6g}] "
                         f"{self.units.get(n, '')}{flag}")
        return "\n".join(lines)


def _units(names: tuple[str, ...], raw_unit: str, unit: str) -> dict[str, str]:
    gain = f"{unit}/{raw_unit}" if unit != raw_unit else "(ratio)"
    return {n: raw_unit if n.startswith("offset") or n == "data_radius" else gain
            for n in names}


def bootstrap(
    points: Any,
    *,
    fit: EllipsoidFit | None = None,
    model: str = "full",
    radius: float | None = None,
    n_boot: int = 1000,
    level: float = 0.95,
    seed: int = 0,
    groups: Any = None,
    debias: bool = True,
    offset_tol: float = OFFSET_TOL,
    gain_tol: float = GAIN_TOL,
    raw_unit: str = "counts",
    unit: str | None = None,
) -> BootstrapIntervals:
    """Bootstrap confidence intervals for every coefficient of an ellipsoid fit.

    Parameters
    ----------
    points : array_like (N, 3)
        The raw readings that were fitted (after any outlier rejection).
    fit : EllipsoidFit, optional
        The fit of ``points``; made here (with ``model``, ``radius``, ``debias``) if not
        given. Its model and radius are used for the refits.
    model, radius, debias
        As for :func:`triaxcal.fit_ellipsoid`, when ``fit`` is not given.
    n_boot : int
        Number of refits (default 1000).
    level : float
        Coverage of the intervals, between 0.5 and 0.999 (default 0.95).
    seed : int
        Seed of the resampling: the same data and seed give the same intervals.
    groups : array_like (N,), optional
        A label per reading (the pose it belongs to): whole poses are resampled instead of
        single readings, which keeps the readings of a pose together (their errors are not
        independent).
    offset_tol, gain_tol : float
        Flag an offset whose interval half-width exceeds ``offset_tol`` times the radius in
        raw units, and a gain or cross-axis term whose half-width exceeds ``gain_tol`` times
        the mean gain.
    raw_unit, unit : str
        Units of the readings and of calibrated values, for the text.

    Returns
    -------
    BootstrapIntervals

    Examples
    --------
    >>> import numpy as np, triaxcal as tc
    >>> rng = np.random.default_rng(0)
    >>> u = rng.normal(size=(300, 3)); u /= np.linalg.norm(u, axis=1, keepdims=True)
    >>> raw = u * 16384 / [1.03, 0.98, 1.01] + [412, -230, 97] + rng.normal(0, 30, (300, 3))
    >>> ci = tc.bootstrap(raw, model="axis", radius=1.0, n_boot=200, unit="g")
    >>> ci.param_names[:3], bool(ci.lower[0] < 412 < ci.upper[0]), ci.flagged
    (('offset_x', 'offset_y', 'offset_z'), True, ())
    """
    pts = as_samples(points, "points", min_rows=1)
    n_boot = opt.integer(n_boot, "n_boot", ge=20, le=MAX_BOOTSTRAP,
                         hint="refits; 1000 is plenty for 95 % intervals")
    seed = opt.seed(seed)
    level = opt.number(level, "level", ge=0.5, le=0.999)
    offset_tol = opt.number(offset_tol, "offset_tol", gt=0)
    gain_tol = opt.number(gain_tol, "gain_tol", gt=0)
    if radius is not None:
        radius = opt.magnitude(radius, "radius")
    if fit is None:
        fit = fit_ellipsoid(pts, model=model, radius=radius, debias=debias)
    elif not isinstance(fit, EllipsoidFit):
        raise CalibrationError(f"fit must be an EllipsoidFit (from fit_ellipsoid) or None, got "
                               f"{type(fit).__name__}")
    elif fit.n != len(pts):
        raise CalibrationError(
            f"fit was made on {fit.n} readings but {len(pts)} were given: pass the readings "
            "that were fitted"
        )
    model = fit.model
    # refit to the same radius; a fit given without one asked for a radius unless it kept
    # the data's own scale
    radius_opt = radius if radius is not None else (
        None if _own_scale(fit) else float(fit.radius))
    rng = np.random.default_rng([seed, 0xB007])
    n = len(pts)
    if groups is None:
        resample = "readings"
        params = []
        block = max(1, min(int(n_boot), 4_000_000 // max(n, 1)))
        done = 0
        errors = 0
        while done < n_boot:
            b = min(block, int(n_boot) - done)
            idx = rng.integers(0, n, size=(b, n))
            res = fit_batch(pts[idx], model=model, radius=radius_opt, debias=debias)
            ok = res.ok & res.converged
            params.append(fit_params(model, res.offsets[ok], res.matrices[ok], res.radii[ok],
                                     radius_opt))
            errors += int((~ok).sum())
            done += b
        boot = np.vstack(params)
    else:
        g = np.asarray(groups).reshape(-1)
        if g.shape[0] != n:
            raise CalibrationError(f"groups must have one label per reading ({n}), got "
                                   f"{g.shape[0]}")
        labels, inv = np.unique(g, return_inverse=True)
        if len(labels) < 10:
            raise CalibrationError(
                f"only {len(labels)} poses: resampling whole poses needs at least 10"
            )
        resample = "poses"
        members = [np.flatnonzero(inv == k) for k in range(len(labels))]
        sets = []
        for _ in range(int(n_boot)):
            pick = rng.integers(0, len(labels), size=len(labels))
            sets.append(pts[np.concatenate([members[k] for k in pick])])
        res = fit_batch(sets, model=model, radius=radius_opt, debias=debias)
        ok = res.ok & res.converged
        boot = fit_params(model, res.offsets[ok], res.matrices[ok], res.radii[ok], radius_opt)
        errors = int((~ok).sum())
    if len(boot) < 20:
        raise CalibrationError(
            f"only {len(boot)} of {n_boot} refits succeeded: the data barely determine the "
            f"{model!r} model; collect more orientations or use a simpler model"
        )
    est = fit_params(model, fit.offset, fit.matrix, [fit.radius], radius_opt)[0]
    alpha = (1.0 - level) / 2.0
    lower, upper = np.quantile(boot, [alpha, 1.0 - alpha], axis=0)
    # the resampled data have the spread of the sample, which for P fitted coefficients
    # understates the population's by (N - P) / N (the HC1 correction of the sandwich
    # variance that this bootstrap approximates): widen about the estimate by sqrt(N / (N - P))
    units_n = len(labels) if groups is not None else n
    widen = math.sqrt(units_n / max(units_n - len(est), 1))
    lower = est - (est - lower) * widen
    upper = est + (upper - est) * widen
    mean_gain = float(np.mean(np.diag(fit.matrix)))
    raw_radius = float(fit.radius / mean_gain) if mean_gain > 0 else float("nan")
    names = tuple(fit.param_names)
    tol = np.array([offset_tol * raw_radius if nm.startswith("offset") or nm == "data_radius"
                    else gain_tol * mean_gain for nm in names])
    for a in (est, lower, upper, tol):
        a.setflags(write=False)
    std = np.std(boot, axis=0, ddof=1)
    std.setflags(write=False)
    se = np.array(fit.stderr, dtype=np.float64)
    se.setflags(write=False)
    return BootstrapIntervals(
        param_names=names, estimate=est, stderr=se, boot_std=std, lower=lower, upper=upper,
        level=float(level), n_boot=int(len(boot)), n_failed=int(errors), resample=resample,
        seed=int(seed), tolerance=tol, raw_radius=raw_radius,
        units=_units(names, raw_unit, unit if unit is not None else raw_unit),
    )


def _own_scale(fit: EllipsoidFit) -> bool:
    """Whether the fit kept the data's own scale (no radius asked for): then det(matrix) = 1
    (or, for a sphere, matrix = I)."""
    if fit.model == "sphere":
        return bool(np.allclose(fit.matrix, np.eye(3), rtol=0, atol=1e-15))
    return abs(float(np.linalg.det(fit.matrix)) - 1.0) < 1e-9
