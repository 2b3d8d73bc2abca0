"""The 24 right-angle rotations a sensor can be mounted in, named and numbered as the autopilots
number them.

ArduPilot's ``enum Rotation`` (``libraries/AP_Math/rotations.h``) and PX4's (``src/lib/
conversion/rotation.h``) share their numbers 0..40; of those, the 24 listed here turn every
axis onto an axis (26 and 27 repeat 14 and 10, so the lowest number is used). Both apply a
rotation as ``v_body = R v_sensor`` with ``R = Rz(yaw) @ Ry(pitch) @ Rx(roll)`` (roll first):
PX4 builds ``Dcmf(Eulerf(roll, pitch, yaw))`` from its ``rot_lookup`` table, and ArduPilot's
``Vector3::rotate`` (``AP_Math/vector3.cpp``) swaps components in the same order (e.g.
``ROTATION_YAW_90``: ``x' = -y, y' = x``; ``ROTATION_ROLL_90``: ``y' = -z, z' = y``).
``COMPASS_ORIENTn`` (ArduPilot) and ``CAL_MAGn_ROT`` (PX4) hold these numbers for external
magnetometers.

:class:`Alignment` is how a calibration file keeps a rotation of one part's frame into
another's (the magnetometer's into the accelerometer's), with the nearest mounting.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from . import _schema
from .errors import CalibrationError

__all__ = ["MAX_MOUNTING_DEG", "MOUNTINGS", "Alignment", "Mounting", "mounting", "nearest_mounting",
           "rotation_angle_deg"]


def _axis_rot(axis: int, deg: int) -> np.ndarray:
    c = round(math.cos(math.radians(deg)))
    s = round(math.sin(math.radians(deg)))
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    m = np.eye(3)
    m[i, i], m[i, j], m[j, i], m[j, j] = c, -s, s, c
    return m


@dataclass(frozen=True, eq=False)
class Mounting:
    """One right-angle mounting: ``name`` (ArduPilot's and PX4's enum name), ``number`` (its
    value in both, for ``COMPASS_ORIENTn`` / ``CAL_MAGn_ROT``), roll, pitch, yaw in degrees,
    and ``matrix`` with ``v_body = matrix @ v_sensor``."""

    name: str
    number: int
    roll: int
    pitch: int
    yaw: int

    @property
    def matrix(self) -> np.ndarray:
        return _axis_rot(2, self.yaw) @ _axis_rot(1, self.pitch) @ _axis_rot(0, self.roll)


# (number, roll, pitch, yaw) as in PX4's rot_lookup; names as in both enums
_TABLE = (
    (0, 0, 0, 0), (2, 0, 0, 90), (4, 0, 0, 180), (6, 0, 0, 270), (8, 180, 0, 0),
    (10, 180, 0, 90), (12, 0, 180, 0), (14, 180, 0, 270), (16, 90, 0, 0), (18, 90, 0, 90),
    (20, 270, 0, 0), (22, 270, 0, 90), (24, 0, 90, 0), (25, 0, 270, 0), (28, 90, 90, 0),
    (29, 180, 90, 0), (30, 270, 90, 0), (31, 90, 180, 0), (32, 270, 180, 0), (33, 90, 270, 0),
    (34, 180, 270, 0), (35, 270, 270, 0), (36, 90, 180, 90), (37, 90, 0, 270),
)


def _name(roll: int, pitch: int, yaw: int) -> str:
    parts = [f"{w}_{a}" for w, a in (("ROLL", roll), ("PITCH", pitch), ("YAW", yaw)) if a]
    return "ROTATION_" + ("_".join(parts) if parts else "NONE")


#: The 24 right-angle mountings, in enum order.
MOUNTINGS: tuple[Mounting, ...] = tuple(Mounting(_name(r, p, y), n, r, p, y)
                                        for n, r, p, y in _TABLE)
_BY_NAME = {m.name: m for m in MOUNTINGS}
_BY_NUMBER = {m.number: m for m in MOUNTINGS}


def mounting(key: Any) -> Mounting:
    """The mounting called ``key`` (``"ROTATION_YAW_90"``, ``"YAW_90"``) or numbered ``key``."""
    if isinstance(key, str):
        k = key.strip().upper()
        m = _BY_NAME.get(k) or _BY_NAME.get("ROTATION_" + k)
        if m is None:
            raise CalibrationError(
                f"unknown mounting {key!r}: use one of the 24 right-angle rotations "
                f"({', '.join(x.name for x in MOUNTINGS[:4])}, ...)")
        return m
    if isinstance(key, (int, np.integer)) and not isinstance(key, bool) and int(key) in _BY_NUMBER:
        return _BY_NUMBER[int(key)]
    raise CalibrationError(f"{key!r} is not one of the 24 right-angle rotations' numbers "
                           f"({sorted(_BY_NUMBER)})")


def rotation_angle_deg(a: Any, b: Any = None) -> float:
    """Angle (deg) of the rotation taking ``b`` to ``a`` (of ``a`` alone when ``b`` is None)."""
    m = np.asarray(a, float) if b is None else np.asarray(a, float) @ np.asarray(b, float).T
    c = float(np.clip((np.trace(m) - 1.0) / 2.0, -1.0, 1.0))
    return math.degrees(math.acos(c))


def nearest_mounting(rotation: Any) -> tuple[Mounting, float]:
    """The right-angle mounting nearest to ``rotation`` and the angle between them (deg).

    >>> import numpy as np
    >>> m, ang = nearest_mounting([[0, -1, 0], [1, 0, 0], [0, 0, 1]])
    >>> m.name, m.number, round(ang, 6)
    ('ROTATION_YAW_90', 2, 0.0)
    """
    r = np.asarray(rotation, float)
    best = min(MOUNTINGS, key=lambda m: rotation_angle_deg(r, m.matrix))
    return best, rotation_angle_deg(r, best.matrix)


#: A rotation is named as a right-angle mounting only within this angle of it (deg).
MAX_MOUNTING_DEG = 20.0


#: The ``alignment`` object of a calibration part (values checked by :class:`Alignment`).
_ALIGNMENT_FIELDS: dict[str, _schema.Field] = {
    "to": _schema.Field(_schema.text(16, nonblank=True), required=True),
    "rotation": _schema.Field(lambda v, w: _schema.reals(v, (3, 3), w), required=True),
    "mounting": _schema.Field(_schema.optional(_schema.text(64, nonblank=True))),
    "stats": _schema.Field(_schema.optional(_schema.json_object)),
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
        ``"ROTATION_ROLL_90"``; :mod:`triaxcal.rotations`) when it lies within 20 deg of
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
        if np.abs(r @ r.T - np.eye(3)).max() > 1e-6 or np.linalg.det(r) <= 0:
            raise CalibrationError(
                "alignment.rotation must be a proper rotation (orthonormal rows, determinant "
                f"+1), got {r.tolist()}; a mirrored axis is a sign error in the readings")
        object.__setattr__(self, "rotation", r)
        if self.to not in _schema.SENSORS:
            raise CalibrationError(
                f"alignment.to must be one of {_schema.SENSORS}, got {self.to!r}")
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
