"""Model selection and outlier rejection around :func:`triaxcal.fit_ellipsoid`.

Error model (as in :mod:`triaxcal.fit`): ``calibrated = (raw - offset) @ matrix.T`` with
``|calibrated| = radius``; the models differ in ``matrix``: ``"sphere"`` (one scale: 4 free
parameters with the offset), ``"axis"`` (per-axis gains ``diag``: 6), ``"full"`` (``diag`` and
``offdiag``, symmetric: 9).

* :func:`fit_auto` fits all three and keeps the one with the lowest Bayesian information
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
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ._validate import as_choice, as_count, as_points, as_real
from .errors import CalibrationError
from .fit import FIXABLE, MODELS, EllipsoidFit, fit_ellipsoid

__all__ = ["AutoFit", "RobustFit", "fit_auto", "fit_robust", "information_criterion"]

#: Free parameters of each model (offset 3 + scale terms).
N_PARAMS = {"sphere": 4, "axis": 6, "full": 9}


def information_criterion(fit: EllipsoidFit, points: Any, criterion: str = "bic") -> float:
    """BIC (or AIC) of ``fit`` on ``points`` from the relative residuals ``|cal| / radius - 1``.

    Lower is better. ``BIC = n ln(RSS / n) + k ln(n)``; ``AIC = n ln(RSS / n) + 2 k``.
    """
    as_choice(criterion, "criterion", ("bic", "aic"))
    pts = as_points(points)
    res = np.linalg.norm(fit.apply(pts), axis=1) / fit.radius - 1.0
    n = len(res)
    rss = max(float(res @ res), 1e-300)
    k = N_PARAMS.get(fit.model, 9) - len(fit.fixed)  # free parameters only
    if criterion == "bic":
        pen = k * math.log(n)
    elif criterion == "aic":
        pen = 2.0 * k
    else:
        raise CalibrationError(f"unknown criterion {criterion!r}: use 'bic' or 'aic'")
    return n * math.log(rss / n) + pen


@dataclass(frozen=True)
class AutoFit:
    """The result of :func:`fit_auto`.

    Attributes
    ----------
    fit : EllipsoidFit
        The chosen model's fit.
    model : str
        The chosen model.
    scores : dict
        Criterion value per model tried (lower is better); models that failed are missing.
    reason : str
        One plain-language sentence saying why this model won.
    errors : dict
        Model -> error message for models that could not be fitted.
    """

    fit: EllipsoidFit
    model: str
    scores: dict[str, float]
    reason: str
    errors: dict[str, str] = field(default_factory=dict)


def fit_auto(
    points: Any,
    *,
    radius: float | None = None,
    models: tuple[str, ...] = MODELS,
    criterion: str = "bic",
    **kwargs: Any,
) -> AutoFit:
    """Fit ``sphere``, ``axis`` and ``full`` and keep the best by an information criterion.

    Parameters
    ----------
    points : array_like, shape (N, 3)
        Raw readings.
    radius : float, optional
        Magnitude of calibrated readings (see :func:`~triaxcal.fit_ellipsoid`).
    models : tuple of str
        Models to compare.
    criterion : {"bic", "aic"}
        Bayesian (default; stricter with many points) or Akaike information criterion.
    **kwargs
        Passed to :func:`~triaxcal.fit_ellipsoid` (``max_iter``, ``tol``, ``method``...).

    Returns
    -------
    AutoFit

    Examples
    --------
    >>> import numpy as np, triaxcal as tc
    >>> from triaxcal.select import fit_auto
    >>> rng = np.random.default_rng(1)
    >>> u = rng.normal(size=(400, 3)); u /= np.linalg.norm(u, axis=1, keepdims=True)
    >>> raw = u / [1.1, 0.9, 1.0] + 0.01 * rng.normal(size=(400, 3))
    >>> fit_auto(raw, radius=1.0).model
    'axis'
    """
    pts = as_points(points)
    as_choice(criterion, "criterion", ("bic", "aic"))
    if (
        isinstance(models, str)
        or not isinstance(models, (tuple, list))
        or not models
        or any(not isinstance(m, str) or m not in MODELS for m in models)
    ):
        raise CalibrationError(f"models must be chosen from {MODELS}, got {models!r}")
    fits: dict[str, EllipsoidFit] = {}
    scores: dict[str, float] = {}
    errors: dict[str, str] = {}
    fixed = kwargs.get("fixed") or {}
    for m in models:
        if any(name not in FIXABLE[m] for name in fixed):
            # e.g. gain_z in the sphere model: that model cannot honour the request
            errors[m] = f"cannot fix {', '.join(sorted(set(fixed) - set(FIXABLE[m])))}"
            continue
        try:
            f = fit_ellipsoid(pts, model=m, radius=radius, **kwargs)
        except CalibrationError as exc:
            errors[m] = str(exc)
            continue
        fits[m] = f
        scores[m] = information_criterion(f, pts, criterion)
    if not fits:
        raise CalibrationError(
            "no model could be fitted: " + "; ".join(f"{m}: {e}" for m, e in errors.items())
        )
    best = min(scores, key=lambda m: scores[m])
    reason = _reason(best, scores, fits, criterion, len(pts))
    return AutoFit(fit=fits[best], model=best, scores=scores, reason=reason, errors=errors)


def _reason(best: str, scores: dict[str, float], fits: dict[str, EllipsoidFit], crit: str,
            n: int) -> str:
    name = crit.upper()
    others = [m for m in scores if m != best]
    if not others:
        return f"only {best!r} could be fitted"
    parts = []
    for m in others:
        d = scores[m] - scores[best]
        rel = fits[m].rms / fits[m].radius * 100
        parts.append(f"{m!r} {name} +{d:.1f} (RMS {rel:.3g} %)")
    simpler = [m for m in others if N_PARAMS[m] < N_PARAMS[best]]
    richer = [m for m in others if N_PARAMS[m] > N_PARAMS[best]]
    why = []
    if simpler:
        why.append(f"its extra terms lower the residuals by more than their price ln({n}) = "
                   f"{math.log(n):.1f} each")
    if richer:
        why.append("the extra terms of " + " and ".join(repr(m) for m in richer)
                   + " do not lower the residuals enough to pay for themselves")
    rel_best = fits[best].rms / fits[best].radius * 100
    return (f"chose {best!r} (RMS {rel_best:.3g} % of radius, lowest {name}): "
            + "; ".join(why) + ". Others: " + ", ".join(parts) + ".")


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
