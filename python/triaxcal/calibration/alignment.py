"""How a calibration file keeps a rotation of one part's frame into another's (the
magnetometer's into the accelerometer's), with the nearest right-angle mounting
(:mod:`triaxcal.conventions.rotations`)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._checks import fields as _schema
from ..conventions.names import SENSORS
from ..conventions.rotations import MAX_MOUNTING_DEG, mounting, rotation_angle_deg
from ..errors import CalibrationError

__all__ = ["Alignment"]


#: The ``alignment`` object of a calibration part (values checked by :class:`Alignment`).
#: The alignment statistics the report prints as numbers (the others are kept as plain JSON).
_ALIGNMENT_STATS: dict[str, _schema.Field] = {
    **{k: _schema.Field(_schema.real) for k in (
        "dip_deg", "dip_std_before_deg", "dip_std_after_deg", "rms_deg", "angle_deg",
        "mounting_residual_deg")},
    **{k: _schema.Field(_schema.optional(_schema.real)) for k in (
        "dip_std_heldout_before_deg", "dip_std_heldout_after_deg", "heading_rms_est_deg")},
    **{k: _schema.Field(_schema.integer) for k in ("n_poses", "n_fit", "n_heldout")},
}

_ALIGNMENT_FIELDS: dict[str, _schema.Field] = {
    "to": _schema.Field(_schema.text(16, nonblank=True), required=True),
    "rotation": _schema.Field(lambda v, w: _schema.reals(v, (3, 3), w), required=True),
    "mounting": _schema.Field(_schema.optional(_schema.text(64, nonblank=True))),
    "stats": _schema.Field(_schema.optional(lambda v, w: _schema.check_fields(
        v, _ALIGNMENT_STATS, w, open_ended=True))),
}


@dataclass(frozen=True, eq=False)
class Alignment:
    """Rotation of a part's calibrated frame into another part's: ``v_to = rotation @ v``.

    Attributes
    ----------
    to : str
        The part whose frame ``rotation`` turns into (``"accel"`` for a magnetometer).
    rotation : ndarray (3, 3)
        A proper rotation (orthonormal, determinant +1, checked to 1e-6).
    mounting : str or None
        The nearest of the 24 right-angle rotations (ArduPilot's / PX4's name, e.g.
        ``"ROTATION_ROLL_90"``; :mod:`triaxcal.conventions.rotations`) when it lies within 20 deg of
        ``rotation``: what ``COMPASS_ORIENTn`` / ``CAL_MAGn_ROT`` can hold.
    stats : dict
        How it was found (dip angle and its spread before / after, poses, standard errors).
    """

    rotation: np.ndarray
    to: str = "accel"
    mounting: str | None = None
    stats: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        r = _schema.reals(self.rotation, (3, 3), "alignment.rotation")
        # (the entries of a rotation lie within +-1: larger ones are refused before r @ r.T,
        # which they could overflow)
        if (np.abs(r).max() > 1 + 1e-6 or np.abs(r @ r.T - np.eye(3)).max() > 1e-6
                or np.linalg.det(r) <= 0):
            raise CalibrationError(
                "alignment.rotation must be a proper rotation (orthonormal rows, determinant "
                f"+1), got {r.tolist()}; a mirrored axis is a sign error in the readings")
        object.__setattr__(self, "rotation", r)
        if self.to not in SENSORS:
            raise CalibrationError(
                f"alignment.to must be one of {SENSORS}, got {self.to!r}")
        if self.mounting is not None:
            _schema.text(64, nonblank=True)(self.mounting, "alignment.mounting")
            m = mounting(self.mounting)
            ang = rotation_angle_deg(r, m.matrix)
            if ang > MAX_MOUNTING_DEG:
                raise CalibrationError(
                    f"alignment.mounting {m.name} is {ang:.1f} deg from alignment.rotation "
                    f"(at most {MAX_MOUNTING_DEG:g}): the two disagree")
            object.__setattr__(self, "mounting", m.name)
        if not isinstance(self.stats, Mapping):
            raise CalibrationError("alignment.stats must be a JSON object")
        object.__setattr__(self, "stats", _schema.json_object(dict(self.stats), "alignment.stats"))

    @property
    def mounting_residual_deg(self) -> float | None:
        """Angle between ``rotation`` and ``mounting`` (deg), None without a mounting."""
        if self.mounting is None:
            return None
        return rotation_angle_deg(self.rotation, mounting(self.mounting).matrix)

    @classmethod
    def from_result(cls, result: Any, to: str = "accel") -> Alignment:
        """From a :class:`triaxcal.methods.alignment.MagAccelAlignment`."""
        mnt = getattr(result, "mounting", None)
        return cls(rotation=result.rotation, to=to, mounting=None if mnt is None else mnt.name,
                   stats=result.stats())

    def to_dict(self) -> dict[str, Any]:
        return {"to": self.to, "rotation": self.rotation.tolist(), "mounting": self.mounting,
                "stats": self.stats}

    @classmethod
    def from_dict(cls, d: Any, what: str = "alignment") -> Alignment:
        v = _schema.check_fields(d, _ALIGNMENT_FIELDS, what)
        try:
            return cls(rotation=v["rotation"], to=v["to"], mounting=v.get("mounting"),
                       stats=v.get("stats") or {})
        except CalibrationError as exc:
            raise CalibrationError(f"{what}: {exc}") from None

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Alignment) and self.to_dict() == other.to_dict()

    __hash__ = None  # type: ignore[assignment]
