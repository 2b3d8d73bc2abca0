"""The zero offset as the centre of a sphere of known radius (the sphere-centre descent).

The readings lie on a sphere of radius ``R`` (16384 counts = 1 g for a 16-bit +-2 g
accelerometer) around the unknown offset; because ``R`` is known, a part of the sphere (a
"wedge") is enough. Three ways to find the centre, each a call into the Rust core
(:mod:`triaxcal.fit.ellipsoid`):

* ``"descent"``: the sphere-centre method's variable-step 26-neighbour search of the error sum
  ``sum |(x-A)^2 + (y-B)^2 + (z-C)^2 - R^2|`` (:func:`~triaxcal.fit.ellipsoid.descend_center`);
* ``"grid"``: its brute-force cube search around the mean of the readings, repeated around the
  best node 20 times finer down to ``min_step`` (:func:`~triaxcal.fit.ellipsoid.grid_center`);
* ``"fit"``: least squares of ``|p - c| - R`` for the centre alone (Gauss-Newton,
  :func:`~triaxcal.fit.ellipsoid.fit_sphere` with ``scale="fixed"``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._checks import options as opt
from .._checks.arrays import as_points
from .._checks.spelling import opt as flag
from ..errors import CalibrationError
from .ellipsoid import descend_center, fit_sphere, grid_center

__all__ = ["CENTER_METHODS", "SphereCenter", "sphere_center"]

#: The ways :func:`sphere_center` finds the centre.
CENTER_METHODS = ("descent", "grid", "fit")


@dataclass(frozen=True)
class SphereCenter:
    """The centre found by :func:`sphere_center`.

    Attributes
    ----------
    center : ndarray (3,)
        The centre, raw units.
    method : str
        How it was found.
    info : dict
        What to record about the search: ``iterations`` (descent steps, grid passes or
        Gauss-Newton iterations), ``evaluations`` (error sums, descent and grid), the steps
        used, and for ``"fit"`` the standard errors of the centre (``stderr``).
    """

    center: np.ndarray
    method: str
    info: dict[str, Any] = field(default_factory=dict)


def sphere_center(
    points: Any,
    radius: float,
    *,
    method: str = "descent",
    step: float | None = None,
    min_step: float = 0.01,
    shrink: float = 10.0,
    start: Any = (0.0, 0.0, 0.0),
    half_width: float | None = None,
    refine: bool = True,
) -> SphereCenter:
    """The centre of the sphere of radius ``radius`` the readings lie on.

    Parameters
    ----------
    points : array_like (N, 3)
        Readings, raw units (at least 4).
    radius : float
        The sphere's radius in the same units.
    method : {"descent", "grid", "fit"}
        See the module notes.
    step : float, optional
        descent: the first step (default 1000); grid: the node spacing (default
        ``half_width / 20``).
    min_step : float
        descent, grid: stop when the step falls below this.
    shrink : float
        descent: divide the step by this when no neighbour is better.
    start : array_like (3,)
        descent: the start point (the sphere-centre method's 0, 0, 0).
    half_width : float, optional
        grid: search the cube ``mean +- half_width`` (default ``radius / 10``).
    refine : bool
        grid: repeat the search around the best node, 20 times finer, down to ``min_step``
        (``False``: one pass at ``step``).

    Returns
    -------
    SphereCenter

    Examples
    --------
    >>> import numpy as np
    >>> d = np.random.default_rng(0).normal(size=(200, 3))
    >>> pts = [120.0, -80.0, 300.0] + 16384 * d / np.linalg.norm(d, axis=1, keepdims=True)
    >>> [sphere_center(pts, 16384.0, method=m).center.round(2).tolist()
    ...  for m in ("descent", "fit")]
    [[120.0, -80.0, 300.0], [120.0, -80.0, 300.0]]
    """
    opt.choice(method, "method", CENTER_METHODS)
    pts = as_points(points, "points")
    if len(pts) < 4:
        raise CalibrationError(f"{len(pts)} readings: a centre needs at least 4 (better 10+)")
    r = opt.number(radius, "radius", gt=0, hint="the sphere's radius in the readings' units")
    min_s = opt.number(min_step, "min_step", gt=0)
    if method == "descent":
        s0 = 1000.0 if step is None else opt.number(step, "step", gt=0)
        d = descend_center(pts, r, start=opt.vector3(start, "start"), step=s0, min_step=min_s,
                           shrink=shrink)  # which it checks (> 1)
        if not d.converged:
            raise CalibrationError(
                f"the descent did not converge in {d.iterations} steps (step now {d.step:g}): "
                f"start nearer ({flag('start')}), or take a larger {flag('min_step')}"
            )
        return SphereCenter(np.asarray(d.center), method, {
            "iterations": d.iterations, "evaluations": d.evaluations, "step": s0,
            "min_step": min_s, "shrink": float(shrink)})
    if method == "grid":
        hw = r / 10.0 if half_width is None else opt.number(half_width, "half_width", gt=0)
        s = hw / 20.0 if step is None else opt.number(step, "step", gt=0)
        mid = pts.mean(axis=0)
        c, half = mid, hw
        evaluations = passes = 0
        while True:  # the cube search, then again around its best node, 20 times finer
            g = grid_center(pts, r, lo=c - half, hi=c + half, step=s)
            c = np.asarray(g.center)
            evaluations += g.evaluations
            passes += 1
            if not refine or s <= min_s:
                break
            half, s = s, max(s / 20.0, min_s)
        return SphereCenter(c, method, {"iterations": passes, "evaluations": evaluations,
                                        "step": s, "half_width": hw,
                                        "grid_center": mid.tolist()})
    f = fit_sphere(pts, radius=r, scale="fixed")  # the centre only, |p - c| = R
    if not f.converged:
        raise CalibrationError("the fixed-radius sphere fit did not converge: try "
                               f"{flag('method', 'descent')}")
    return SphereCenter(np.asarray(f.offset), method, {
        "iterations": f.iterations,
        "stderr": {name: float(v) for name, v in zip(f.param_names[:3], f.stderr[:3])}})

