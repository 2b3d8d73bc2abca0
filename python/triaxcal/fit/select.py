"""Model selection and outlier rejection around :func:`triaxcal.fit_ellipsoid`.

Error model (as in :mod:`triaxcal.fit`): ``calibrated = (raw - offset) @ matrix.T`` with
``|calibrated| = radius``; the models differ in ``matrix``: ``"sphere"`` (one scale: 4 free
parameters with the offset), ``"axis"`` (per-axis gains ``diag``: 6), ``"full"`` (``diag`` and
``offdiag``, symmetric: 9).

* :func:`fit_auto` (defined in :mod:`triaxcal.fit`, which dispatches ``model="auto"`` to it,
  and re-exported here) fits all three and keeps the one with the lowest Bayesian information
  criterion on the relative geometric residuals ``|calibrated| / radius - 1``:
  ``BIC = n ln(RSS / n) + k ln(n)``. Extra gain / cross-axis terms must lower the residual sum
  by more than their ``ln(n)`` price each; the result says which model won and by how much.
* :func:`fit_robust` rejects outliers by the length of each calibrated reading and refits, until
  the kept set stops changing. Two rules:

  - ``rule="robust"`` (the default): a reading is an outlier when its modified z-score
    ``0.6745 |l - median(l)| / MAD(l)`` exceeds ``k = 3.5`` (Iglewicz and Hoaglin, *How to
    Detect and Handle Outliers*, ASQC 1993). The median and the median absolute deviation are
    not dragged by the outliers themselves, and on clean (Gaussian) lengths the rule drops
    about 1 reading in 2000 -- it keeps clean data and removes gross errors (a reading taken
    while the board moved, a glitch).
  - ``rule="sigma"``: the rule Magneto users rely on: drop readings whose length is more than
    ``sigma`` standard deviations from the mean length. On clean data a 2-sigma cut drops about
    5 % of the readings in each round. ``lengths="raw"`` applies the first pass to raw lengths,
    as Magneto does; Magneto exactly is ``rule="sigma", sigma=2, max_rounds=1,
    lengths="raw"`` (``triaxcal fit --outliers magneto``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._checks.arrays import as_choice, as_count, as_points, as_real
from .._checks.arrays import lengths as row_lengths
from .._checks.spelling import opt
from ..errors import CalibrationError
from .ellipsoid import (  # model choice lives beside the fit, which dispatches model="auto" to it
    MODELS,
    AutoFit,
    EllipsoidFit,
    fit_auto,
    fit_ellipsoid,
    information_criterion,
)

__all__ = ["RULES", "AutoFit", "RobustFit", "fit_auto", "fit_robust", "information_criterion"]

@dataclass(frozen=True)
class RobustFit:
    """The result of :func:`fit_robust`.

    Attributes
    ----------
    fit : EllipsoidFit
        Fit to the kept readings.
    rejected : ndarray of int
        Indices (into the input) of the readings rejected, ascending.
    inliers : ndarray of bool
        Mask of the kept readings.
    rounds : int
        Rejection rounds run.
    converged : bool
        Whether the kept set stopped changing before ``max_rounds``.
    auto : AutoFit, optional
        The model choice, when ``model="auto"``.
    """

    fit: EllipsoidFit
    rejected: np.ndarray
    inliers: np.ndarray
    rounds: int
    converged: bool
    auto: AutoFit | None = None

    @property
    def model_reason(self) -> str | None:
        return None if self.auto is None else self.auto.reason


def _fit(pts: np.ndarray, model: str, radius: float | None, kw: dict) -> tuple[EllipsoidFit,
                                                                                AutoFit | None]:
    if model == "auto":
        a = fit_auto(pts, radius=radius, **kw)
        return a.fit, a
    return fit_ellipsoid(pts, model=model, radius=radius, **kw), None


#: The outlier rules of :func:`fit_robust`.
RULES = ("robust", "sigma", "none")

#: The robust rule's threshold on the modified z-score (Iglewicz and Hoaglin 1993).
ROBUST_Z = 3.5


def fit_robust(
    points: Any,
    *,
    model: str = "full",
    radius: float | None = None,
    rule: str | None = None,
    sigma: float | None = None,
    max_rounds: int = 10,
    lengths: str = "calibrated",
    min_keep: float = 0.5,
    **kwargs: Any,
) -> RobustFit:
    """Fit, reject readings whose calibrated length is an outlier, refit (see the module
    notes for the rules).

    Parameters
    ----------
    points : array_like, shape (N, 3)
        Raw readings.
    model : {"full", "axis", "sphere", "auto"}
        Fit model; ``"auto"`` chooses by BIC (:func:`fit_auto`) in every round.
    radius : float, optional
        Magnitude of calibrated readings.
    rule : {"robust", "sigma", "none"}, optional
        ``"robust"`` (the default): modified z-score above 3.5; ``"sigma"``: more than
        ``sigma`` standard deviations from the mean length; ``"none"``: keep every reading.
        Giving ``sigma`` alone selects ``"sigma"``.
    sigma : float, optional
        The sigma rule's threshold in standard deviations of the lengths (Magneto's is 2,
        the default). ``0`` or ``inf`` disables rejection.
    max_rounds : int
        Most reject-and-refit rounds (1 = a single pass, as Magneto does).
    lengths : {"calibrated", "raw"}
        ``"raw"``: the first round judges raw vector lengths (exactly Magneto's rule); later
        rounds always judge calibrated lengths.
    min_keep : float
        Refuse to reject more than this fraction of readings in total (raises).
    **kwargs
        Passed to :func:`~triaxcal.fit_ellipsoid`.

    Returns
    -------
    RobustFit
        The fit and the rejected indices.
    """
    pts = as_points(points)
    if not isinstance(model, str) or (model != "auto" and model not in MODELS):
        raise CalibrationError(f"unknown model {model!r}: use one of {MODELS + ('auto',)}")
    as_choice(lengths, "lengths", ("calibrated", "raw"))
    max_rounds = as_count(max_rounds, "max_rounds", hi=1000)
    if rule is None:
        rule = "robust" if sigma is None else "sigma"
    as_choice(rule, "rule", RULES)
    sigma = as_real(2.0 if sigma is None else sigma, "sigma", lo=0, allow_inf=True)
    min_keep = as_real(min_keep, "min_keep", lo=0, hi=1)
    n = len(pts)
    keep = np.ones(n, dtype=bool)
    off = rule == "none" or max_rounds == 0 or (
        rule == "sigma" and (sigma == 0 or math.isinf(sigma)))
    threshold = ROBUST_Z if rule == "robust" else sigma

    def _within(norms: np.ndarray, t: float) -> np.ndarray:
        # the rules are scale-free: lengths scaled by a power of two (exact) near 1, so that
        # their means and spreads cannot overflow for readings near the edge of a double
        if not np.isfinite(norms).all():
            raise CalibrationError(
                "the calibrated lengths overflow double precision (radius "
                f"{radius!r}): give the radius in a unit the readings can be scaled to")
        _, e = np.frexp(np.max(norms, initial=1.0))
        return _kept(np.ldexp(norms, -e), rule, t)

    if lengths == "raw" and not off:
        norms = row_lengths(pts)
        keep = _within(norms, threshold)
    fit, auto = _fit(pts[keep], model, radius, kwargs)
    rounds = 1 if lengths == "raw" and not off else 0
    converged = True
    if not off:
        converged = False
        while rounds < max_rounds:
            norms = row_lengths(fit.apply(pts))
            new = _within(norms, threshold)
            rounds += 1
            if np.array_equal(new, keep):
                converged = True
                break
            if new.sum() < max(min_keep * n, 4):
                raise CalibrationError(
                    f"outlier rejection ({rule} rule) would keep only {int(new.sum())} of {n} "
                    "readings: the data are not one sphere (mixed sensors or ranges?); check "
                    f"the columns, or disable rejection ({opt('outliers', 'none')})"
                )
            keep = new
            fit, auto = _fit(pts[keep], model, radius, kwargs)
        else:
            converged = bool(np.array_equal(_within(row_lengths(fit.apply(pts)),
                                                    threshold), keep))
    rejected = np.flatnonzero(~keep)
    rejected.setflags(write=False)
    keep.setflags(write=False)
    return RobustFit(fit=fit, rejected=rejected, inliers=keep, rounds=rounds,
                     converged=converged, auto=auto)


def _kept(norms: np.ndarray, rule: str, t: float) -> np.ndarray:
    """Which lengths the rule keeps: ``t`` is the sigma rule's sigma or the robust rule's
    modified z-score threshold."""
    if rule == "robust":
        med = float(np.median(norms))
        mad = float(np.median(np.abs(norms - med)))
        if mad == 0.0:
            return np.ones(len(norms), dtype=bool)
        return 0.6745 * np.abs(norms - med) / mad <= t
    mu = float(np.mean(norms))
    sd = float(np.std(norms, ddof=1)) if len(norms) > 1 else 0.0
    if sd == 0.0:
        return np.ones(len(norms), dtype=bool)
    return np.abs(norms - mu) <= t * sd
