"""Sphere and ellipsoid fits: the Python face of the Rust core (``triaxcal._core``).

Error model (see ``rust/ellipsoid/mod.rs``): a raw reading ``p`` and the true field ``f`` of
constant magnitude ``radius`` are related by ``f = matrix @ (p - offset)``, i.e. in numpy terms
``calibrated = (raw - offset) @ matrix.T``. ``offset`` is in raw units (counts, or whatever the
points are in); ``matrix`` **multiplies** and carries calibrated units per raw unit (for example
g per count). Its diagonal holds the per-axis scale (``diag``), the rest the cross-axis /
soft-iron terms (``offdiag``).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from .._checks.arrays import (
    as_choice,
    as_count,
    as_flag,
    as_points,
    as_radius,
    as_real,
    as_vector,
    lengths,
    require_radius,
)
from .._core import apply as _core_apply
from .._core import descend_center as _core_descend_center
from .._core import fit_batch as _core_fit_batch
from .._core import fit_ellipsoid as _core_fit_ellipsoid
from .._core import fit_sphere_linear as _core_fit_sphere_linear
from .._core import grid_center as _core_grid_center
from .._core import sphere_error as _core_sphere_error
from ..conventions.names import PARAM_NAMES as _PARAM_NAMES
from ..errors import CalibrationError

__all__ = [
    "MODELS",
    "AutoFit",
    "BatchFit",
    "Descent",
    "EllipsoidFit",
    "LinearSphere",
    "descend_center",
    "fit_auto",
    "fit_batch",
    "fit_ellipsoid",
    "fit_sphere",
    "fit_sphere_linear",
    "grid_center",
    "information_criterion",
    "sphere_error",
]

MODELS = ("sphere", "axis", "full")
METHODS = ("lm", "gn", "algebraic")

#: Names of the parameters whose standard errors ``EllipsoidFit.stderr`` holds, per model
#: (kept in :mod:`triaxcal.conventions.names`; the compiled core reads them from this module).
PARAM_NAMES = _PARAM_NAMES

#: Most refinement steps a fit accepts (each is a pass over the points; fits take tens).
MAX_ITER = 1_000_000

#: Parameters that ``fixed`` can hold, per model, with their place in the core's vector
#: (``gain_*`` are the ``diag_*`` of the axis and full models; the sphere's one gain is ``gain``).
FIXABLE = {
    "sphere": {"offset_x": 0, "offset_y": 1, "offset_z": 2, "gain": 3},
    "axis": {
        "offset_x": 0, "offset_y": 1, "offset_z": 2,
        "gain_x": 3, "gain_y": 4, "gain_z": 5, "diag_x": 3, "diag_y": 4, "diag_z": 5,
    },
    "full": {
        "offset_x": 0, "offset_y": 1, "offset_z": 2,
        "gain_x": 3, "gain_y": 4, "gain_z": 5, "diag_x": 3, "diag_y": 4, "diag_z": 5,
        "offdiag_xy": 6, "offdiag_xz": 7, "offdiag_yz": 8,
    },
}


def _frozen(a: Any, dtype: Any = np.float64) -> np.ndarray:
    arr = np.array(a, dtype=dtype)
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True)
class EllipsoidFit:
    """The result of :func:`fit_ellipsoid` or :func:`fit_sphere`.

    Attributes
    ----------
    model : str
        ``"sphere"``, ``"axis"`` or ``"full"``.
    offset : ndarray, shape (3,)
        Bias / hard iron, in raw units.
    matrix : ndarray, shape (3, 3)
        Symmetric gain matrix that **multiplies**: ``calibrated = (raw - offset) @ matrix.T``.
    radius : float
        Magnitude of calibrated readings: the requested radius, or the data's own
        (``det(matrix) == 1``) when none was given.
    rms : float
        RMS of ``|calibrated| - radius`` over the points, in calibrated units.
    stderr : ndarray
        Standard errors of the parameters named in ``param_names`` (offset in raw units,
        matrix terms in calibrated units per raw unit, ``data_radius`` in raw units).
    param_names : tuple of str
        ``offset_x, offset_y, offset_z``, then ``data_radius`` (sphere), ``diag_x..z``
        (axis), or ``diag_x..z, offdiag_xy, offdiag_xz, offdiag_yz`` (full).
    iterations : int
        Trial steps of the Levenberg-Marquardt / Gauss-Newton refinement.
    converged : bool
        Whether the refinement met its tolerance.
    condition : float
        Condition number of the column-scaled normal matrix (large: poorly determined).
    n : int
        Number of points fitted.
    warnings : tuple of str
        Plain-language warnings, e.g. poor coverage of the sphere, with what to do.
    model_reason : str or None
        With ``model="auto"``: why this model was chosen (see :func:`fit_auto`).
    fixed : tuple of str
        Parameters held at given values (``fixed=``) instead of fitted; their standard error is
        0.
    """

    model: str
    offset: np.ndarray
    matrix: np.ndarray
    radius: float
    rms: float
    stderr: np.ndarray
    param_names: tuple[str, ...]
    iterations: int
    converged: bool
    condition: float
    n: int
    warnings: tuple[str, ...] = field(default=())
    model_reason: str | None = None
    fixed: tuple[str, ...] = ()

    def apply(self, points: Any) -> np.ndarray:
        """Calibrate raw readings: ``(points - offset) @ matrix.T``, shape (N, 3).

        Examples
        --------
        >>> import numpy as np, triaxcal as tc
        >>> pts = np.array([[2, 0, 0], [0, 0, 0], [1, 1, 0], [1, -1, 0], [1, 0, 1], [1, 0, -1]])
        >>> fit = tc.fit_sphere(pts, radius=1.0)
        >>> np.round(fit.apply([[2, 0, 0]]), 6).tolist()
        [[1.0, 0.0, 0.0]]
        """
        pts = as_points(points)
        return _core_apply(pts, tuple(self.offset), self.matrix.tolist())

    @property
    def stderr_dict(self) -> dict[str, float]:
        """Standard errors keyed by parameter name."""
        return dict(zip(self.param_names, (float(v) for v in self.stderr)))

    def __repr__(self) -> str:
        off = ", ".join(f"{v:.6g}" for v in self.offset)
        diag = ", ".join(f"{v:.6g}" for v in np.diag(self.matrix))
        return (
            f"EllipsoidFit(model={self.model!r}, offset=[{off}], diag=[{diag}], "
            f"radius={self.radius:.6g}, rms={self.rms:.3g}, n={self.n}, "
            f"converged={self.converged}, warnings={len(self.warnings)})"
        )


def fit_ellipsoid(
    points: Any,
    *,
    model: str = "full",
    radius: float | None = None,
    max_iter: int = 100,
    tol: float = 1e-10,
    method: str = "lm",
    debias: bool = True,
    fixed: dict[str, float] | None = None,
) -> EllipsoidFit:
    """Fit offset and gain matrix so that calibrated readings have constant magnitude.

    Minimises the geometric residual ``|matrix @ (p - offset)| - radius`` by
    Levenberg-Marquardt, started from an algebraic ellipsoid fit. Runs in Rust, with the GIL
    released above 1,024 points (a smaller fit takes under 0.3 ms and keeps it); the points
    are streamed, not copied (aligned float64 C-contiguous input is read in place; anything
    else is converted first).

    Parameters
    ----------
    points : array_like, shape (N, 3)
        Raw readings, any real dtype (int16 counts straight from a sensor are fine). At least
        as many as the model has free unknowns (4, 6 or 9, fewer with ``fixed``); exactly that
        many give an exactly determined solve (a note in ``warnings``, NaN standard errors).
    model : {"full", "axis", "sphere", "auto"}
        ``"sphere"``: offset + one scale; ``"axis"``: offset + 3 gains; ``"full"``: offset +
        symmetric 3x3 (scale, cross-axis, soft iron); ``"auto"``: fit all three and keep the
        one with the lowest Bayesian information criterion (``model_reason`` says why).
    radius : float, optional
        Magnitude calibrated readings must have: 1.0 for g, 9.80665 for m/s^2, 16384 for counts
        at +-2 g, the local field in uT. ``None`` keeps the data's own scale.
    max_iter : int
        Most refinement steps (0 to 1,000,000).
    tol : float
        Converged when a step lowers the sum of squares by less than this fraction (0 <= tol <
        1).
    method : {"lm", "gn", "algebraic"}
        Levenberg-Marquardt, Gauss-Newton, or the algebraic fit alone (no refinement).
    debias : bool
        Correct the residual for the length that noise adds to every vector (first order in
        the noise variance, which is estimated from the residuals). Removes the O(sigma^2)
        shrinkage of ``matrix`` that every length-based fit has; applied only where that bias
        exceeds a tenth of the statistical error (noise above 0.1/sqrt(N) of the radius).
        ``False`` gives the plain geometric least-squares fit (the objective of the original
        method's
        spreadsheet: the sum of ``(|calibrated| - radius)^2``).
    fixed : dict, optional
        Parameters held at given values instead of fitted: ``offset_x/y/z`` (raw units) and,
        with ``radius`` given, gains in calibrated units per raw unit: ``gain_x/y/z`` (alias
        ``diag_x/y/z``) and ``offdiag_xy/xz/yz`` for "axis"/"full", ``gain`` for "sphere"
        (``matrix = gain * I``). ``{"gain_z": 1.0}`` with ``radius=16384`` is the original method's
        spreadsheet fit (offsets and the x and y gains varied, the z gain 1).

    Returns
    -------
    EllipsoidFit

    Raises
    ------
    CalibrationError
        NaN/inf, too few points, points on a plane or a line, too small a cap of the sphere
        for the model, wrong shape or dtype, an option out of range. The message says what to
        do.

    Examples
    --------
    >>> import numpy as np, triaxcal as tc
    >>> rng = np.random.default_rng(0)
    >>> u = rng.normal(size=(500, 3)); u /= np.linalg.norm(u, axis=1, keepdims=True)
    >>> raw = u / [1.02, 0.98, 1.01] + [0.05, -0.03, 0.02]       # readings in g
    >>> fit = tc.fit_ellipsoid(raw, model="axis", radius=1.0)
    >>> np.round(fit.offset, 6).tolist(), np.round(np.diag(fit.matrix), 6).tolist()
    ([0.05, -0.03, 0.02], [1.02, 0.98, 1.01])

    Six readings, one per face of a cube, with the z gain held at 1 as the spreadsheet method does:

    >>> faces = np.array([[16900, 40, -20], [-15800, 40, -20], [560, 16700, -20],
    ...                   [560, -16100, -20], [560, 40, 16400], [560, 40, -16440]])
    >>> fit = tc.fit_ellipsoid(faces, model="axis", radius=16384, fixed={"gain_z": 1.0})
    >>> np.round(fit.offset, 1).tolist(), np.round(np.diag(fit.matrix), 4).tolist()
    ([550.0, 299.4, -20.0], [1.002, 0.999, 1.0])
    """
    if fixed is None:
        # the common call: the core checks that the arguments are already plain and valid,
        # fits and builds the result (None: something needs validating or converting first,
        # or model is "auto")
        fit = _core_fit_ellipsoid(
            points, EllipsoidFit, model, radius, max_iter, tol, method, debias, None, ()
        )
        if fit is not None:
            return fit
    if isinstance(model, str) and model == "auto":
        auto = fit_auto(
            points, radius=radius, max_iter=max_iter, tol=tol, method=method, debias=debias,
            fixed=fixed,
        )
        return replace(auto.fit, model_reason=auto.reason)
    opts = _options(model, radius, max_iter, tol, method, debias)
    fix, names = _fixed_vector(fixed, model, opts[1]) if fixed else (None, ())
    pts = points if _ready(points) else as_points(points)
    fit = _core_fit_ellipsoid(pts, EllipsoidFit, *opts, fix, names)
    if fit is None:  # the options and points are plain now: the core must have fitted
        raise RuntimeError("triaxcal._core.fit_ellipsoid refused validated arguments")
    return fit


def fit_sphere(
    points: Any,
    *,
    radius: float | None = None,
    scale: str = "free",
    max_iter: int = 100,
    tol: float = 1e-10,
    debias: bool = True,
) -> EllipsoidFit:
    """Geometric sphere fit: offset and one scale (``fit_ellipsoid(model="sphere")``).

    With ``radius`` given, ``matrix`` is ``radius / data_radius`` times the identity; without
    it, ``matrix`` is the identity and ``radius`` is the data's own.

    ``scale="fixed"`` (needs ``radius``) fits only the centre: Gauss-Newton /
    Levenberg-Marquardt on ``|p - center| - radius`` with ``matrix`` the identity, i.e. the
    readings are taken to lie on a sphere of exactly ``radius`` raw units (16384 counts for an
    accelerometer at +-2 g). A known radius determines the centre from a part of the sphere (a
    cap), where a free scale cannot be told from the centre's distance.

    Examples
    --------
    >>> import numpy as np, triaxcal as tc
    >>> t = np.radians(np.arange(0, 360, 30))
    >>> cap = np.c_[np.cos(t) * 8192, np.sin(t) * 8192, np.full(12, 14189.0)]  # 30 deg cap
    >>> cap = np.r_[cap, [[0, 0, 16384]]] + [120, -40, 300]                   # offset in counts
    >>> fit = tc.fit_sphere(cap, radius=16384, scale="fixed")
    >>> np.round(fit.offset).tolist(), fit.matrix.tolist() == np.eye(3).tolist()
    ([120.0, -40.0, 300.0], True)
    """
    as_choice(scale, "scale", ("free", "fixed"))
    fixed = None
    if scale == "fixed":
        if radius is None:
            raise CalibrationError(
                "scale='fixed' needs radius: the radius of the sphere the readings lie on, in "
                "raw units (16384 counts at +-2 g)"
            )
        fixed = {"gain": 1.0}
    return fit_ellipsoid(
        points, model="sphere", radius=radius, max_iter=max_iter, tol=tol, debias=debias,
        fixed=fixed,
    )


@dataclass(frozen=True)
class LinearSphere:
    """The result of :func:`fit_sphere_linear`: ``center``, ``radius``, ``rms`` (geometric)."""

    center: np.ndarray
    radius: float
    rms: float


def fit_sphere_linear(points: Any) -> LinearSphere:
    """Linear least-squares sphere fit (centre and radius unknown), one pass over the data.

    Solves ``|p|^2 = 2 c.p + d``: fast and closed-form, but it minimises an algebraic error,
    so with noisy data :func:`fit_sphere` is more accurate.
    """
    c, r, rms = _core_fit_sphere_linear(as_points(points))
    return LinearSphere(center=_frozen(c), radius=float(r), rms=float(rms))


@dataclass(frozen=True)
class BatchFit:
    """The result of :func:`fit_batch`; row ``i`` belongs to set ``i``.

    A set that could not be fitted has NaN in its rows, ``converged[i] == False`` and the
    reason in ``errors[i]`` (``None`` for sets that were fitted).
    """

    model: str
    offsets: np.ndarray
    matrices: np.ndarray
    radii: np.ndarray
    rms: np.ndarray
    converged: np.ndarray
    iterations: np.ndarray
    errors: tuple[str | None, ...]

    @property
    def ok(self) -> np.ndarray:
        """Boolean mask of the sets that were fitted."""
        return np.array([e is None for e in self.errors], dtype=bool)

    def __len__(self) -> int:
        return len(self.errors)


def fit_batch(
    sets: Any,
    *,
    model: str = "full",
    radius: float | None = None,
    max_iter: int = 100,
    tol: float = 1e-10,
    method: str = "lm",
    debias: bool = True,
    fixed: dict[str, float] | None = None,
) -> BatchFit:
    """Fit many data sets in one call, in parallel (rayon), with the GIL released.

    Parameters
    ----------
    sets : array_like (B, N, 3), or a sequence of (Ni, 3) arrays
        One set of raw readings per device.
    model, radius, max_iter, tol, method, debias, fixed
        As for :func:`fit_ellipsoid`, applied to every set.

    Returns
    -------
    BatchFit
        ``offsets`` (B, 3), ``matrices`` (B, 3, 3), ``radii`` (B,), ``rms`` (B,),
        ``converged`` (B,), ``iterations`` (B,), ``errors`` (B,). One bad set reports its own
        error and does not spoil the others.
    """
    opts = _options(model, radius, max_iter, tol, method, debias)
    fix, _ = _fixed_vector(fixed, model, opts[1])
    bounds: np.ndarray | int
    if isinstance(sets, np.ndarray) and sets.ndim == 3:
        if sets.shape[2] != 3:
            raise CalibrationError(f"sets must have shape (B, N, 3), got {sets.shape}")
        b, n = sets.shape[0], sets.shape[1]
        flat = sets.reshape(b * n, 3)
        if not _ready(flat):
            flat = as_points(flat, name="sets")
        # sets of n points each: the core splits the rows itself
        bounds = n if n > 0 else np.zeros(b + 1, dtype=np.int64)
    else:
        if isinstance(sets, np.ndarray) and sets.ndim != 1:
            raise CalibrationError(
                "sets must be a (B, N, 3) array or a sequence of (N, 3) arrays, got shape "
                f"{sets.shape}"
            )
        parts = [as_points(s, name=f"sets[{i}]") for i, s in enumerate(_as_sequence(sets))]
        bounds = np.zeros(len(parts) + 1, dtype=np.int64)
        bounds[1:] = np.cumsum([len(p) for p in parts])
        flat = np.concatenate(parts) if parts else np.zeros((0, 3))
    d = _core_fit_batch(flat, bounds, *opts, fix)  # its arrays come read-only
    # the fields set at once: the frozen dataclass's __init__ sets them one by one through
    # object.__setattr__, 1.1 us of a 10-set batch's 55 us (the result is the same object)
    fit = object.__new__(BatchFit)
    fit.__dict__.update(
        model=model,
        offsets=d["offsets"],
        matrices=d["matrices"],
        radii=d["radii"],
        rms=d["rms"],
        converged=d["converged"],
        iterations=d["iterations"],
        errors=tuple(d["errors"]),
    )
    return fit


@dataclass(frozen=True)
class Descent:
    """The result of :func:`descend_center` or :func:`grid_center`.

    ``center`` (3,), ``error`` (the error sum there), ``iterations`` (neighbourhoods examined
    or grid nodes visited), ``evaluations`` (error sums computed), ``step`` (final step),
    ``converged`` (False if ``max_iter`` stopped the descent).
    """

    center: np.ndarray
    error: float
    iterations: int
    evaluations: int
    step: float
    converged: bool

    @classmethod
    def _from_core(cls, d: dict) -> Descent:
        return cls(
            center=_frozen(d["center"]),
            error=float(d["error"]),
            iterations=int(d["iterations"]),
            evaluations=int(d["evaluations"]),
            step=float(d["step"]),
            converged=bool(d["converged"]),
        )


def sphere_error(points: Any, center: Any, radius: float) -> float:
    """The sphere-centre note's error sum ``sum |(x-A)^2 + (y-B)^2 + (z-C)^2 - R^2|``.

    Examples
    --------
    >>> import triaxcal as tc
    >>> tc.sphere_error([[1, 0, 0], [0, 2, 0]], (0, 0, 0), 1.0)
    3.0
    """
    r = require_radius(radius)
    return float(_core_sphere_error(as_points(points), as_vector(center, "center"), r))


def descend_center(
    points: Any,
    radius: float,
    *,
    start: Any = (0.0, 0.0, 0.0),
    step: float = 1000.0,
    min_step: float = 0.01,
    shrink: float = 10.0,
    max_iter: int = 1_000_000,
) -> Descent:
    """Variable-step 26-neighbour descent for the centre of a sphere of known radius.

    From ``start``, look at the 26 neighbours one ``step`` away; move to the best if it lowers
    :func:`sphere_error`, otherwise divide ``step`` by ``shrink``; stop once ``step`` falls
    below ``min_step``. ``min_step=step`` gives the fixed-step descent. Defaults are the
    sphere-centre note's
    (raw counts: step 1000 down to 0.01). The work is bounded before the search starts: a
    search whose steps alone would need more than ``5e8`` point evaluations (neighbourhoods
    times points; e.g. ``shrink=1.0001`` down to ``min_step=1e-300``) is refused with a
    message, and a search that keeps moving stops there with ``converged=False``.
    """
    r = require_radius(radius)
    step = as_real(step, "step", lo=0, lo_open=True)
    min_step = as_real(min_step, "min_step", lo=0, hi=step, lo_open=True)
    shrink = as_real(shrink, "shrink", lo=1, lo_open=True)
    d = _core_descend_center(
        as_points(points),
        r,
        start=as_vector(start, "start"),
        step=step,
        min_step=min_step,
        shrink=shrink,
        max_iter=as_count(max_iter, "max_iter", hi=10**12),
    )
    return Descent._from_core(d)


def grid_center(points: Any, radius: float, *, lo: Any, hi: Any, step: float) -> Descent:
    """Brute-force search of the cube ``[lo, hi]`` (scalars or 3-vectors) at ``step``.

    Nodes times points may not exceed ``2e10`` (about ten seconds on one core): a larger
    search is refused before it starts, with a message saying so.
    """
    r = require_radius(radius)
    d = _core_grid_center(
        as_points(points),
        r,
        lo=as_vector(lo, "lo"),
        hi=as_vector(hi, "hi"),
        step=as_real(step, "step", lo=0, lo_open=True),
    )
    return Descent._from_core(d)


# ------------------------------------------------------------------------ model choice


#: Free parameters of each model (offset 3 + scale terms).
N_PARAMS = {"sphere": 4, "axis": 6, "full": 9}


def information_criterion(fit: EllipsoidFit, points: Any, criterion: str = "bic") -> float:
    """BIC (or AIC) of ``fit`` on ``points`` from the relative residuals ``|cal| / radius - 1``.

    Lower is better. ``BIC = n ln(RSS / n) + k ln(n)``; ``AIC = n ln(RSS / n) + 2 k``.
    """
    as_choice(criterion, "criterion", ("bic", "aic"))
    if not isinstance(fit, EllipsoidFit):
        raise CalibrationError(f"fit must be an EllipsoidFit (from fit_ellipsoid), got "
                               f"{type(fit).__name__}")
    pts = as_points(points, min_rows=1)
    with np.errstate(over="ignore"):  # points far from the fit: an infinite criterion
        res = lengths(fit.apply(pts)) / fit.radius - 1.0
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
    >>> from triaxcal.fit.select import fit_auto
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


def _check_options(
    model: Any, radius: Any, max_iter: Any, tol: Any, method: Any, debias: Any
) -> tuple[str, float | None, int, float, str, bool]:
    """Validate the options shared by the fits: the core's arguments, in its order."""
    if not isinstance(model, str) or model not in MODELS:
        raise CalibrationError(
            f"unknown model {model!r}: use 'sphere' (offset only), 'axis' (offset + 3 gains), "
            "'full' (offset + symmetric 3x3 matrix) or 'auto'"
        )
    if not isinstance(method, str) or method not in METHODS:
        raise CalibrationError(f"unknown method {method!r}: use one of {METHODS}")
    return (
        model,
        as_radius(radius),
        as_count(max_iter, "max_iter", hi=MAX_ITER),
        as_real(tol, "tol", lo=0, hi=1, hi_open=True),
        method,
        as_flag(debias, "debias"),
    )


# The same options validate the same way: remember the last few (typed, so that True, 1 and
# 1.0 are told apart). Unhashable values (a radius given as an array) skip the cache.
_options_cached = functools.lru_cache(maxsize=64, typed=True)(_check_options)


def _options(*args: Any) -> tuple[str, float | None, int, float, str, bool]:
    try:
        return _options_cached(*args)
    except TypeError:  # unhashable
        return _check_options(*args)


_F64 = np.dtype(np.float64)


def _ready(points: Any) -> bool:
    """Whether ``points`` can go to the core as they are (an aligned, C-contiguous float64
    (N, 3) array), so that the conversion in ``as_points`` can be skipped."""
    return (
        type(points) is np.ndarray
        and points.dtype == _F64
        and points.ndim == 2
        and points.shape[1] == 3
        and points.flags.carray
    )


def _fixed_vector(
    fixed: Any, model: str, radius: float | None
) -> tuple[list[float | None] | None, tuple[str, ...]]:
    """``fixed`` as the core's 9-vector (None: free), and the names given."""
    if fixed is None or (isinstance(fixed, dict) and not fixed):
        return None, ()
    if not isinstance(fixed, dict):
        raise CalibrationError(
            f"fixed must be a dict of parameter name -> value, got {type(fixed).__name__}"
        )
    names = FIXABLE[model]
    out: list[float | None] = [None] * 9
    for name, value in fixed.items():
        if name not in names:
            raise CalibrationError(
                f"cannot fix {name!r} in the {model!r} model: choose from "
                + ", ".join(sorted(names))
            )
        i = names[name]
        if out[i] is not None:
            raise CalibrationError(f"{name!r} is given twice in fixed (an alias of the other)")
        gain = i >= 3
        if gain and radius is None:
            raise CalibrationError(
                f"fixing {name!r} needs radius: a gain is in calibrated units per raw unit, so "
                "give the magnitude calibrated readings must have (radius=16384 for counts at "
                "+-2 g, 1.0 for g)"
            )
        positive = 3 <= i <= 5
        out[i] = as_real(value, f"fixed[{name!r}]", lo=0, lo_open=positive) if positive else (
            as_real(value, f"fixed[{name!r}]")
        )
    return out, tuple(fixed)


def _as_sequence(sets: Any) -> Sequence[Any]:
    try:
        return list(sets)
    except TypeError:
        raise CalibrationError(
            "sets must be a (B, N, 3) array or a sequence of (N, 3) arrays"
        ) from None
