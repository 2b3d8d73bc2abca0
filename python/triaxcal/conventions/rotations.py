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
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import CalibrationError

__all__ = ["MAX_MOUNTING_DEG", "MOUNTINGS", "Mounting", "euler_to_dcm", "mounting",
           "nearest_mounting", "quat_to_dcm", "rotation_angle_deg"]


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


def euler_to_dcm(roll_deg: Any, pitch_deg: Any, yaw_deg: Any) -> np.ndarray:
    """Body-to-NED rotation matrices ``Rz(yaw) Ry(pitch) Rx(roll)`` (N, 3, 3) from Euler angles
    in degrees (ArduPilot ``ATT.Roll/Pitch/Yaw``; pymavlink ``mavextra.rotation_df``).

    >>> np.round(euler_to_dcm([0.0], [0.0], [90.0])[0] @ [1.0, 0.0, 0.0], 6).tolist()
    [0.0, 1.0, 0.0]
    """
    r, p, y = (np.radians(np.asarray(a, float).ravel()) for a in (roll_deg, pitch_deg, yaw_deg))
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    out = np.empty((len(r), 3, 3))
    out[:, 0, 0] = cp * cy
    out[:, 0, 1] = sr * sp * cy - cr * sy
    out[:, 0, 2] = cr * sp * cy + sr * sy
    out[:, 1, 0] = cp * sy
    out[:, 1, 1] = sr * sp * sy + cr * cy
    out[:, 1, 2] = cr * sp * sy - sr * cy
    out[:, 2, 0] = -sp
    out[:, 2, 1] = sr * cp
    out[:, 2, 2] = cr * cp
    return out


def quat_to_dcm(q: Any) -> np.ndarray:
    """Body-to-NED rotation matrices (N, 3, 3) from unit quaternions ``(w, x, y, z)`` (PX4
    ``vehicle_attitude.q``, Hamilton convention, ``matrix::Dcm(Quaternion)``)."""
    q = np.asarray(q, float).reshape(-1, 4)
    n = np.linalg.norm(q, axis=1, keepdims=True)
    if not np.all(n > 0):
        raise CalibrationError("attitude quaternions must not be zero")
    w, x, y, z = (q / n).T
    out = np.empty((len(q), 3, 3))
    out[:, 0, 0] = 1 - 2 * (y * y + z * z)
    out[:, 0, 1] = 2 * (x * y - w * z)
    out[:, 0, 2] = 2 * (x * z + w * y)
    out[:, 1, 0] = 2 * (x * y + w * z)
    out[:, 1, 1] = 1 - 2 * (x * x + z * z)
    out[:, 1, 2] = 2 * (y * z - w * x)
    out[:, 2, 0] = 2 * (x * z - w * y)
    out[:, 2, 1] = 2 * (y * z + w * x)
    out[:, 2, 2] = 1 - 2 * (x * x + y * y)
    return out
