"""How the live page fits (:class:`LiveOptions`) and the small pieces its state is made of:
the shared coverage cells as rectangles, the accelerometer's checks, a fit as the page shows
it, and plain-JSON conversion."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..detect.session import PoseSettings
from ..errors import CalibrationError
from ..fit.ellipsoid import MODELS

__all__ = ["ACCEL_LIMITS", "SENSOR_COLUMNS", "LiveOptions"]

#: Column names of each sensor in a session (the device channel order).
SENSOR_COLUMNS = {"accel": ("ax", "ay", "az"), "gyro": ("gx", "gy", "gz"),
                  "mag": ("mx", "my", "mz")}

#: Accelerometer checks: fewest poses (twice the 9 parameters of the full model), largest
#: empty cap of directions (the report's warning, degrees), largest RMS in % of the radius
#: (the report's accelerometer warning).
ACCEL_LIMITS = {"poses": 18, "empty_cap_deg": 40.0, "fit_error": 2.0}

_MC_NAMES = {"gaps": "gaps", "variance": "variance", "wobble": "wobble",
             "fit_error": "fit error"}
_MC_HELP = {"gaps": "empty regions of the sphere (MotionCal's 100)",
            "variance": "spread of |calibrated| over its mean",
            "wobble": "how far the cloud sits off centre",
            "fit_error": "RMS of |calibrated| - radius, in % of the radius"}

def _rects() -> list[list[float]]:
    from ..quality.coverage import sphere_cells

    return [[round(v, 6) for v in r] for r in sphere_cells().rectangles()]


#: The shared coverage cells (``triaxcal.quality.coverage``) as (lon_lo, lon_hi deg, z_lo, z_hi).
_RECTS = _rects()

_TRAIL_HZ = 25.0
_TRAIL_S = 10.0


@dataclass(frozen=True)
class LiveOptions:
    """How the live page fits, and where its buttons write.

    The fit options are ``triaxcal fit``'s, with its defaults: ``model`` (``"auto"``: by BIC),
    ``outliers``, ``sigma`` and ``rounds`` (outlier rejection), ``accel_radius`` and ``mag_radius``
    (as ``--radius`` text, e.g. ``"1g"``, ``"50uT"``; ``None`` keeps the data's own scale),
    ``detection`` (the pose detection of ``capture`` and ``fit --poses``,
    :class:`~triaxcal.detect.session.PoseSettings`; ``None``: the command line's defaults).
    ``gyro_counts_per_dps`` (``None``: 131, or 16 for ``Raw:``) only scales
    the displayed rates. ``mag_buffer`` is the size of the magnetometer's
    buffer of well-spread samples; ``refresh_hz`` how often the background thread refits and
    publishes. ``out_dir`` (default: the session's folder) receives ``calibration.json`` and
    the C headers, named with ``prefix``; ``send_timeout_s`` bounds the wait for a board's echo.
    ``counts_per_unit`` (``{"accel": (16384, "g")}``) and ``sensor_model`` (part names such as
    ``"MPU-6050:2g,250dps"``) give the board driver's scale for Send (the MotionCal packet is
    in m/s^2, rad/s and uT); without them only ``Raw:`` lines, whose format fixes the scale,
    can be sent.
    """

    model: str = "auto"
    outliers: str = "robust"
    sigma: float = 2.0
    rounds: int = 10
    accel_radius: str = "1g"
    mag_radius: str | None = None
    detection: PoseSettings | None = None
    gyro_counts_per_dps: float | None = None
    mag_buffer: int = 650
    refresh_hz: float = 10.0
    out_dir: Path | None = None
    prefix: str = "triaxcal"
    send_timeout_s: float = 3.0
    counts_per_unit: Any = None
    sensor_model: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        from ..calibration.request import parse_radius
        from ..export._cgen import _ident

        if self.model not in (*MODELS, "auto"):
            raise CalibrationError(f"model must be one of {(*MODELS, 'auto')}, got {self.model!r}")
        from ..calibration.request import OUTLIER_RULES

        if self.outliers not in OUTLIER_RULES:
            raise CalibrationError(f"outliers must be one of {OUTLIER_RULES}, got "
                                   f"{self.outliers!r}")
        if not (isinstance(self.sigma, (int, float)) and self.sigma >= 0):
            raise CalibrationError(f"sigma must be >= 0, got {self.sigma!r}")
        for name, lo in (("rounds", 0), ("mag_buffer", 50)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < lo:
                raise CalibrationError(f"{name} must be a whole number >= {lo}, got {v!r}")
        parse_radius(self.accel_radius, "accel")
        if self.mag_radius is not None:
            parse_radius(self.mag_radius, "mag")
        if self.detection is not None and not isinstance(self.detection, PoseSettings):
            raise CalibrationError(f"detection must be a PoseSettings, got {self.detection!r}")
        for name in ("gyro_counts_per_dps",):
            v = getattr(self, name)
            if v is not None and not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise CalibrationError(f"{name} must be > 0, got {v!r}")
        if not (isinstance(self.refresh_hz, (int, float)) and 0.2 <= self.refresh_hz <= 50):
            raise CalibrationError(f"refresh_hz must lie in 0.2..50, got {self.refresh_hz!r}")
        if not (isinstance(self.send_timeout_s, (int, float)) and self.send_timeout_s > 0):
            raise CalibrationError(f"send_timeout_s must be > 0, got {self.send_timeout_s!r}")
        _ident(self.prefix)
        from ..export._trust import Scales

        if isinstance(self.sensor_model, str):
            object.__setattr__(self, "sensor_model", (self.sensor_model,))
        Scales(self.counts_per_unit, tuple(self.sensor_model))  # checked now, not at Send


def _jsonable(obj: Any) -> Any:
    """Plain JSON values: numpy to Python, non-finite floats to None."""
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist())
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        v = float(obj)
        return v if math.isfinite(v) else None
    return obj


def _round(a: np.ndarray, digits: int) -> list:
    return np.round(np.asarray(a, dtype=np.float64), digits).tolist()


def _columns(names: Sequence[str], want: Sequence[str]) -> list[int] | None:
    return [names.index(c) for c in want] if all(c in names for c in want) else None


@dataclass
class _Fit:
    """A fit as the page shows it (from a live RobustFit or from the session's fit)."""

    model: str
    offset: np.ndarray
    matrix: np.ndarray
    radius: float
    rms: float
    stderr: dict[str, float]
    n: int
    rejected: list[int]
    converged: bool
    condition: float | None
    reason: str | None
    source: str  # "live" or "session"
    unit: str
    raw_unit: str = "counts"
    rejected_points: int = 0
    extra: dict[str, Any] = field(default_factory=dict)

    def apply(self, raw: np.ndarray) -> np.ndarray:
        return (np.asarray(raw, dtype=np.float64).reshape(-1, 3) - self.offset) @ self.matrix.T

    def doc(self) -> dict[str, Any]:
        return {
            "source": self.source, "model": self.model, "unit": self.unit,
            "raw_unit": self.raw_unit, "offset": self.offset, "matrix": self.matrix,
            "radius": self.radius, "rms": self.rms,
            "rms_pct": 100.0 * self.rms / self.radius if self.radius else None,
            "stderr": self.stderr, "n": self.n, "rejected": len(self.rejected),
            "converged": self.converged, "condition": self.condition, "reason": self.reason,
        }
