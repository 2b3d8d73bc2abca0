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
* :func:`fit_robust` rejects outliers with the rule Magneto users rely on: drop readings whose
  vector length is more than ``sigma`` standard deviations from the mean length (mean and
  standard deviation over all readings), here on the *calibrated* lengths of the current fit
  and iterated (refit on the kept readings, recompute every length, repeat until the kept set
  stops changing). ``lengths="raw"`` applies Magneto's first pass to raw lengths, as Magneto
  does (sensible only when the offset is small next to the radius).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._checks.arrays import as_choice, as_count, as_points, as_real
from ..errors import CalibrationError
from .ellipsoid import (  # model choice lives beside the fit, which dispatches model="auto" to it
    MODELS,
    AutoFit,
    EllipsoidFit,
    fit_auto,
    fit_ellipsoid,
    information_criterion,
)

__all__ = ["AutoFit", "RobustFit", "fit_auto", "fit_robust", "information_criterion"]

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


def fit_robust(
    points: Any,
    *,
    model: str = "full",
    radius: float | None = None,
    sigma: float = 2.0,
    max_rounds: int = 10,
    lengths: str = "calibrated",
    min_keep: float = 0.5,
    **kwargs: Any,
) -> RobustFit:
    """Fit, reject readings whose length is more than ``sigma`` std from the mean, refit.

    Parameters
    ----------
    points : array_like, shape (N, 3)
        Raw readings.
    model : {"full", "axis", "sphere", "auto"}
        Fit model; ``"auto"`` chooses by BIC (:func:`fit_auto`) in every round.
    radius : float, optional
        Magnitude of calibrated readings.
    sigma : float
        Rejection threshold in standard deviations of the lengths (Magneto's default is 2).
        ``0`` or ``inf`` disables rejection.
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
    sigma = as_real(sigma, "sigma", lo=0, allow_inf=True)
    min_keep = as_real(min_keep, "min_keep", lo=0, hi=1)
    n = len(pts)
    keep = np.ones(n, dtype=bool)
    off = sigma == 0 or math.isinf(sigma) or max_rounds == 0
    if lengths == "raw" and not off:
        norms = np.linalg.norm(pts, axis=1)
        keep = _within(norms, sigma)
    fit, auto = _fit(pts[keep], model, radius, kwargs)
    rounds = 1 if lengths == "raw" and not off else 0
    converged = True
    if not off:
        converged = False
        while rounds < max_rounds:
            norms = np.linalg.norm(fit.apply(pts), axis=1)
            new = _within(norms, sigma)
            rounds += 1
            if np.array_equal(new, keep):
                converged = True
                break
            if new.sum() < max(min_keep * n, 4):
                raise CalibrationError(
                    f"outlier rejection at {sigma} sigma would keep only {int(new.sum())} of {n} "
                    "readings: the data are not one sphere (mixed sensors or ranges?); check "
                    "the columns, or disable rejection (sigma=0)"
                )
            keep = new
            fit, auto = _fit(pts[keep], model, radius, kwargs)
        else:
            converged = bool(np.array_equal(_within(np.linalg.norm(fit.apply(pts), axis=1),
                                                    sigma), keep))
    rejected = np.flatnonzero(~keep)
    rejected.setflags(write=False)
    keep.setflags(write=False)
    return RobustFit(fit=fit, rejected=rejected, inliers=keep, rounds=rounds,
                     converged=converged, auto=auto)


def _within(norms: np.ndarray, sigma: float) -> np.ndarray:
    mu = float(np.mean(norms))
    sd = float(np.std(norms, ddof=1)) if len(norms) > 1 else 0.0
    if sd == 0.0:
        return np.ones(len(norms), dtype=bool)
    return np.abs(norms - mu) <= sigma * sd
