"""Sphere and ellipsoid fits: the Python face of the Rust core, model choice and outlier
rejection.

* :mod:`~triaxcal.fit.ellipsoid` -- the fits themselves (sphere, axis, full), the original method's
  sphere-centre descent and the batch fit, each a thin, validating call into ``triaxcal._core``;
  model choice by information criterion (``model="auto"``).
* :mod:`~triaxcal.fit.select` -- outlier rejection around a fit (Magneto's rule and the
  default robust rule).
* :mod:`~triaxcal.fit.center` -- the zero offset as the centre of a sphere of known radius
  (the sphere-centre method's descent, its grid search, or a fixed-radius fit).
"""

from .center import CENTER_METHODS, SphereCenter, sphere_center
from .ellipsoid import (
    FIXABLE,
    MAX_ITER,
    METHODS,
    MODELS,
    PARAM_NAMES,
    AutoFit,
    BatchFit,
    Descent,
    EllipsoidFit,
    LinearSphere,
    descend_center,
    fit_auto,
    fit_batch,
    fit_ellipsoid,
    fit_sphere,
    fit_sphere_linear,
    grid_center,
    information_criterion,
    sphere_error,
)
from .select import RobustFit, fit_robust

#: The public names (``triaxcal.__all__`` gathers them); ``FIXABLE``, ``MAX_ITER``,
#: ``METHODS``, ``PARAM_NAMES`` and ``CENTER_METHODS`` stay importable from here.
__all__ = [
    "MODELS",
    "AutoFit",
    "BatchFit",
    "Descent",
    "EllipsoidFit",
    "LinearSphere",
    "RobustFit",
    "SphereCenter",
    "descend_center",
    "fit_auto",
    "fit_batch",
    "fit_ellipsoid",
    "fit_robust",
    "fit_sphere",
    "fit_sphere_linear",
    "grid_center",
    "information_criterion",
    "sphere_center",
    "sphere_error",
]
