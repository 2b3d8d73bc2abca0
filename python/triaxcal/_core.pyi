"""Stubs of the compiled core (``rust/py/mod.rs``). Use the ``triaxcal`` package instead."""

from typing import Any, final

import numpy as np
import numpy.typing as npt

__all__ = [
    "__version__",
    "BOUNDS",
    "CalibrationError",
    "NonFiniteError",
    "TooFewPointsError",
    "DegenerateDataError",
    "sphere_error",
    "descend_center",
    "grid_center",
    "fit_sphere_linear",
    "fit_ellipsoid",
    "fit_batch",
    "apply",
    "AllanStream",
    "read_ulog",
    "read_dataflash",
]

__version__: str
#: The core's physical bounds and warning thresholds (rust/bounds.rs), by name.
BOUNDS: dict[str, float]

class CalibrationError(ValueError): ...
class NonFiniteError(CalibrationError): ...
class TooFewPointsError(CalibrationError): ...
class DegenerateDataError(CalibrationError): ...

_Points = npt.NDArray[np.float64]
_Vec3 = tuple[float, float, float]

def sphere_error(points: _Points, center: _Vec3, radius: float) -> float: ...
def descend_center(
    points: _Points,
    radius: float,
    *,
    start: _Vec3,
    step: float,
    min_step: float,
    shrink: float,
    max_iter: int,
) -> dict[str, Any]: ...
def grid_center(
    points: _Points, radius: float, *, lo: _Vec3, hi: _Vec3, step: float
) -> dict[str, Any]: ...
def fit_sphere_linear(points: _Points) -> tuple[_Vec3, float, float]: ...
def fit_ellipsoid(
    points: Any,
    cls: type,
    model: Any,
    radius: Any,
    max_iter: Any,
    tol: Any,
    method: Any,
    debias: Any,
    fixed: list[float | None] | None,
    fixed_names: tuple[str, ...],
) -> Any: ...
def fit_batch(
    points: _Points,
    bounds: npt.NDArray[np.int64] | int,
    model: str,
    radius: float | None,
    max_iter: int,
    tol: float,
    method: str,
    debias: bool,
    fixed: list[float | None] | None = None,
) -> dict[str, Any]: ...
def apply(
    points: _Points, offset: _Vec3, matrix: list[list[float]]
) -> npt.NDArray[np.float64]: ...

@final
class AllanStream:
    def __new__(
        cls,
        rate_hz: float,
        axes: int,
        ms: list[int],
        *,
        exact_up_to: int | None,
        overlapping: bool = True,
    ) -> AllanStream: ...
    def push(self, chunk: npt.NDArray[np.float64]) -> None: ...
    @property
    def n(self) -> int: ...
    @property
    def memory_bytes(self) -> int: ...
    def result(self) -> dict[str, Any]: ...

def read_ulog(path: str, topics: list[str] | None = None) -> dict[str, Any]: ...
def read_dataflash(path: str, types: list[str]) -> dict[str, Any]: ...
