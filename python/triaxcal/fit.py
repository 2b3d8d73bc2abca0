"""Sphere and ellipsoid fits: the Python face of the Rust core (``triaxcal._core``).

Error model (see ``rust/ellipsoid.rs``): a raw reading ``p`` and the true field ``f`` of
constant magnitude ``radius`` are related by ``f = matrix @ (p - offset)``, i.e. in numpy terms
``calibrated = (raw - offset) @ matrix.T``. ``offset`` is in raw units (counts, or whatever the
points are in); ``matrix`` **multiplies** and carries calibrated units per raw unit (for example
g per count). Its diagonal holds the per-axis scale (``diag``), the rest the cross-axis /
soft-iron terms (``offdiag``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from . import _core
from ._validate import as_points, as_radius, as_vector, require_radius
from .errors import CalibrationError

__all__ = [
    "MODELS",
    "BatchFit",
    "Descent",
    "EllipsoidFit",
    "LinearSphere",
    "descend_center",
    "fit_batch",
    "fit_ellipsoid",
    "fit_sphere",
    "fit_sphere_linear",
    "grid_center",
    "sphere_error",
]

MODELS = ("sphere", "axis", "full")
METHODS = ("lm", "gn", "algebraic")


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
        With ``model="auto"``: why this model was chosen (see :func:`triaxcal.select.fit_auto`).
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

    @classmethod
    def _from_core(cls, d: dict) -> EllipsoidFit:
        return cls(
            model=d["model"],
            offset=_frozen(d["offset"]),
            matrix=_frozen(d["matrix"]),
            radius=float(d["radius"]),
            rms=float(d["rms"]),
            stderr=_frozen(d["stderr"]),
            param_names=tuple(d["param_names"]),
            iterations=int(d["iterations"]),
            converged=bool(d["converged"]),
            condition=float(d["condition"]),
            n=int(d["n"]),
            warnings=tuple(d["warnings"]),
        )

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
        return _core.apply(pts, tuple(self.offset), self.matrix.tolist())

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
) -> EllipsoidFit:
    """Fit offset and gain matrix so that calibrated readings have constant magnitude.

    Minimises the geometric residual ``|matrix @ (p - offset)| - radius`` by
    Levenberg-Marquardt, started from an algebraic ellipsoid fit. Runs in Rust with the GIL
    released; the points are streamed, not copied (float64 C-contiguous input is borrowed).

    Parameters
    ----------
    points : array_like, shape (N, 3)
        Raw readings, any real dtype (int16 counts straight from a sensor are fine).
    model : {"full", "axis", "sphere", "auto"}
        ``"sphere"``: offset + one scale; ``"axis"``: offset + 3 gains; ``"full"``: offset +
        symmetric 3x3 (scale, cross-axis, soft iron); ``"auto"``: fit all three and keep the
        one with the lowest Bayesian information criterion (``model_reason`` says why).
    radius : float, optional
        Magnitude calibrated readings must have: 1.0 for g, 9.80665 for m/s^2, 16384 for counts
        at +-2 g, the local field in uT. ``None`` keeps the data's own scale.
    max_iter : int
        Most refinement steps.
    tol : float
        Converged when a step lowers the sum of squares by less than this fraction.
    method : {"lm", "gn", "algebraic"}
        Levenberg-Marquardt, Gauss-Newton, or the algebraic fit alone (no refinement).
    debias : bool
        Correct the residual for the length that noise adds to every vector (first order in
        the noise variance, which is estimated from the residuals). Removes the O(sigma^2)
        shrinkage of ``matrix`` that every length-based fit has; applied only where that bias
        exceeds a tenth of the statistical error (noise above 0.1/sqrt(N) of the radius).
        ``False`` gives the plain geometric least-squares fit.

    Returns
    -------
    EllipsoidFit

    Raises
    ------
    CalibrationError
        NaN/inf, too few points, points on a plane or a line, too small a cap of the sphere
        for the model, wrong shape or dtype. The message says what to do.

    Examples
    --------
    >>> import numpy as np, triaxcal as tc
    >>> rng = np.random.default_rng(0)
    >>> u = rng.normal(size=(500, 3)); u /= np.linalg.norm(u, axis=1, keepdims=True)
    >>> raw = u / [1.02, 0.98, 1.01] + [0.05, -0.03, 0.02]       # readings in g
    >>> fit = tc.fit_ellipsoid(raw, model="axis", radius=1.0)
    >>> np.round(fit.offset, 6).tolist(), np.round(np.diag(fit.matrix), 6).tolist()
    ([0.05, -0.03, 0.02], [1.02, 0.98, 1.01])
    """
    if model == "auto":
        from .select import fit_auto  # select builds on this module

        auto = fit_auto(
            points, radius=radius, max_iter=max_iter, tol=tol, method=method, debias=debias
        )
        return replace(auto.fit, model_reason=auto.reason)
    max_iter, r = _check_options(model, method, max_iter, radius, auto_ok=True)
    pts = as_points(points)
    d = _core.fit_ellipsoid(
        pts,
        model=model,
        radius=r,
        max_iter=max_iter,
        tol=float(tol),
        method=method,
        debias=bool(debias),
    )
    return EllipsoidFit._from_core(d)


def fit_sphere(
    points: Any,
    *,
    radius: float | None = None,
    max_iter: int = 100,
    tol: float = 1e-10,
    debias: bool = True,
) -> EllipsoidFit:
    """Geometric sphere fit: offset and one scale (``fit_ellipsoid(model="sphere")``).

    With ``radius`` given, ``matrix`` is ``radius / data_radius`` times the identity; without
    it, ``matrix`` is the identity and ``radius`` is the data's own.
    """
    return fit_ellipsoid(
        points, model="sphere", radius=radius, max_iter=max_iter, tol=tol, debias=debias
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
    c, r, rms = _core.fit_sphere_linear(as_points(points))
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
) -> BatchFit:
    """Fit many data sets in one call, in parallel (rayon), with the GIL released.

    Parameters
    ----------
    sets : array_like (B, N, 3), or a sequence of (Ni, 3) arrays
        One set of raw readings per device.
    model, radius, max_iter, tol, method, debias
        As for :func:`fit_ellipsoid`, applied to every set.

    Returns
    -------
    BatchFit
        ``offsets`` (B, 3), ``matrices`` (B, 3, 3), ``radii`` (B,), ``rms`` (B,),
        ``converged`` (B,), ``iterations`` (B,), ``errors`` (B,). One bad set reports its own
        error and does not spoil the others.
    """
    max_iter, r = _check_options(model, method, max_iter, radius, auto_ok=False)
    if isinstance(sets, np.ndarray) and sets.ndim == 3:
        if sets.shape[2] != 3:
            raise CalibrationError(f"sets must have shape (B, N, 3), got {sets.shape}")
        b, n = sets.shape[0], sets.shape[1]
        flat = as_points(sets.reshape(b * n, 3), name="sets")
        bounds = np.arange(b + 1, dtype=np.int64) * n
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
    d = _core.fit_batch(
        flat,
        bounds,
        model=model,
        radius=r,
        max_iter=max_iter,
        tol=float(tol),
        method=method,
        debias=bool(debias),
    )
    for k in ("offsets", "matrices", "radii", "rms", "converged", "iterations"):
        d[k].setflags(write=False)
    return BatchFit(
        model=model,
        offsets=d["offsets"],
        matrices=d["matrices"],
        radii=d["radii"],
        rms=d["rms"],
        converged=d["converged"],
        iterations=d["iterations"],
        errors=tuple(d["errors"]),
    )


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
    """The seed's error sum ``sum |(x-A)^2 + (y-B)^2 + (z-C)^2 - R^2|``.

    Examples
    --------
    >>> import triaxcal as tc
    >>> tc.sphere_error([[1, 0, 0], [0, 2, 0]], (0, 0, 0), 1.0)
    3.0
    """
    r = require_radius(radius)
    return float(_core.sphere_error(as_points(points), as_vector(center, "center"), r))


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
    below ``min_step``. ``min_step=step`` gives the fixed-step descent. Defaults are the seed's
    (raw counts: step 1000 down to 0.01).
    """
    r = require_radius(radius)
    d = _core.descend_center(
        as_points(points),
        r,
        start=as_vector(start, "start"),
        step=float(step),
        min_step=float(min_step),
        shrink=float(shrink),
        max_iter=_as_count(max_iter, "max_iter"),
    )
    return Descent._from_core(d)


def grid_center(points: Any, radius: float, *, lo: Any, hi: Any, step: float) -> Descent:
    """Brute-force search of the cube ``[lo, hi]`` (scalars or 3-vectors) at ``step``."""
    r = require_radius(radius)
    d = _core.grid_center(
        as_points(points), r, lo=as_vector(lo, "lo"), hi=as_vector(hi, "hi"), step=float(step)
    )
    return Descent._from_core(d)


def _check_options(
    model: str, method: str, max_iter: Any, radius: Any, *, auto_ok: bool
) -> tuple[int, float | None]:
    """Validate the options shared by the fits; returns (max_iter, radius)."""
    if model not in MODELS:
        raise CalibrationError(
            f"unknown model {model!r}: use 'sphere' (offset only), 'axis' (offset + 3 gains), "
            "'full' (offset + symmetric 3x3 matrix)" + (" or 'auto'" if auto_ok else "")
        )
    if method not in METHODS:
        raise CalibrationError(f"unknown method {method!r}: use one of {METHODS}")
    return _as_count(max_iter, "max_iter"), as_radius(radius)


def _as_count(value: Any, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
        raise CalibrationError(f"{name} must be a whole number >= 0, got {value!r}")
    return int(value)


def _as_sequence(sets: Any) -> Sequence[Any]:
    try:
        return list(sets)
    except TypeError:
        raise CalibrationError(
            "sets must be a (B, N, 3) array or a sequence of (N, 3) arrays"
        ) from None
