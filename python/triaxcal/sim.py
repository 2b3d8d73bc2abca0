"""A simulated IMU and a simulated serial device, for tests, demos and trying the tools out.

Error model (the same as the fits'): a sensor with offset ``offset`` (counts) and symmetric
matrix ``matrix`` (physical units per count, **multiplies**) reports, for a true physical
vector ``v`` (g, rad/s or uT, in the sensor's body frame),

    raw = offset(T) + inv(matrix(T)) @ v + noise,   rounded to integers, clipped to int16,

so that the true calibration ``(raw - offset) @ matrix.T`` gives ``v`` back within the noise.
``matrix`` holds the per-axis scale on its diagonal and the cross-axis (accelerometer,
gyroscope) or soft-iron (magnetometer) terms off it. The offset drifts linearly with the die
temperature ``T`` (``tempco``, counts per degC) and, optionally, the matrix scales by
``1 + gain_tempco * (T - temp_ref_c)``.

Frames
------
World frame: x north, y west, z up. ``orientation`` is the body-to-world rotation ``R``; a
world vector ``w`` reads ``R.T @ w`` in the body frame. At rest the accelerometer reads the
specific force ``+1 g`` straight up; the magnetometer reads a field of magnitude ``field_ut``
pointing north and ``inclination_deg`` below the horizon; the gyroscope reads the body-frame
angular rate (Earth's rotation, 0.004 deg/s, is left out). Rotations between poses turn about
one body-fixed axis with a minimum-jerk angle profile, so integrating the true gyro rate over a
move gives exactly that rotation.

Device channel order (K=10): ``ax ay az gx gy gz mx my mz temp``, int16 counts; nominal scales
16384 counts/g, 131 counts/(deg/s), 10 counts/uT, ``T_degC = temp_raw / 340 + 36.53``.

Offline: :class:`SimIMU` holds the truth and :meth:`SimIMU.record` samples it along a
:class:`Script` (:func:`globe_script`, :func:`six_face_script`, :func:`rotation_script`).
Online: :class:`SimDevice` serves the same samples on a pseudo-terminal in any of the wire
protocols, answers the firmware's commands, runs faster than real time, injects
:class:`Faults`, and can be unplugged or silenced; it logs every frame it sent
(:class:`SentFrame`) so that tests can compare a capture with what went over the wire.
"""

from __future__ import annotations

import contextlib
import math
import os
import select
import tempfile
import threading
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from .errors import CalibrationError

__all__ = [
    "ACCEL_COUNTS_PER_G",
    "CHANNELS_7",
    "CHANNELS_10",
    "GYRO_COUNTS_PER_DPS",
    "MAG_COUNTS_PER_UT",
    "Faults",
    "Recording",
    "Script",
    "SensorTruth",
    "SentFrame",
    "SimDevice",
    "SimIMU",
    "Truth",
    "globe_script",
    "rotation_script",
    "six_face_script",
    "temp_c_from_raw",
    "temp_raw_from_c",
]

#: Nominal scales of the simulated device (MPU-6050 style at +-2 g, +-250 deg/s).
ACCEL_COUNTS_PER_G = 16384.0
GYRO_COUNTS_PER_DPS = 131.0
GYRO_COUNTS_PER_RAD_S = GYRO_COUNTS_PER_DPS * 180.0 / math.pi
MAG_COUNTS_PER_UT = 10.0
#: Channel names in device order, 10 channels (with magnetometer) and 7 (AVR / MPU-6050).
CHANNELS_10 = ("ax", "ay", "az", "gx", "gy", "gz", "mx", "my", "mz", "temp")
CHANNELS_7 = ("ax", "ay", "az", "gx", "gy", "gz", "temp")
INT16_MIN, INT16_MAX = -32768, 32767


def temp_c_from_raw(raw: Any) -> np.ndarray:
    """Die temperature in degC from MPU-6050 style counts: ``raw / 340 + 36.53``."""
    return np.asarray(raw, dtype=np.float64) / 340.0 + 36.53


def temp_raw_from_c(temp_c: Any) -> np.ndarray:
    """Inverse of :func:`temp_c_from_raw` (float counts, not rounded)."""
    return (np.asarray(temp_c, dtype=np.float64) - 36.53) * 340.0


# --------------------------------------------------------------------------------------------
# rotations


def rotvec_to_matrix(rotvec: Any) -> np.ndarray:
    """Rotation matrices from rotation vectors (axis * angle, rad): (..., 3) -> (..., 3, 3)."""
    r = np.asarray(rotvec, dtype=np.float64)
    theta = np.linalg.norm(r, axis=-1)[..., None, None]
    small = theta < 1e-12
    safe = np.where(small, 1.0, theta)
    k = r / safe[..., 0]
    kx, ky, kz = k[..., 0], k[..., 1], k[..., 2]
    zero = np.zeros_like(kx)
    kmat = np.stack(
        [
            np.stack([zero, -kz, ky], axis=-1),
            np.stack([kz, zero, -kx], axis=-1),
            np.stack([-ky, kx, zero], axis=-1),
        ],
        axis=-2,
    )
    eye = np.broadcast_to(np.eye(3), kmat.shape)
    rot = eye + np.sin(safe) * kmat + (1.0 - np.cos(safe)) * (kmat @ kmat)
    return np.where(small, eye, rot)


def matrix_to_rotvec(rot: Any) -> np.ndarray:
    """Rotation vector (axis * angle, angle in [0, pi]) of one rotation matrix."""
    m = np.asarray(rot, dtype=np.float64)
    cos = np.clip((np.trace(m) - 1.0) / 2.0, -1.0, 1.0)
    theta = math.acos(cos)
    if theta < 1e-12:
        return np.zeros(3)
    if math.pi - theta > 1e-6:
        w = np.array([m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1]])
        return w / (2.0 * math.sin(theta)) * theta
    # near 180 degrees: axis from the symmetric part
    b = (m + np.eye(3)) / 2.0
    i = int(np.argmax(np.diag(b)))
    axis = b[:, i] / math.sqrt(max(b[i, i], 1e-300))
    return axis / np.linalg.norm(axis) * theta


# --------------------------------------------------------------------------------------------
# truth


@dataclass(frozen=True)
class SensorTruth:
    """The true calibration of one simulated triaxial sensor.

    Attributes
    ----------
    name : str
        ``"accel"``, ``"gyro"`` or ``"mag"``.
    units : str
        Physical units of calibrated readings: ``"g"``, ``"rad/s"`` or ``"uT"``.
    counts_per_unit : float
        Nominal sensitivity (16384 counts/g, 7505.7 counts/(rad/s) = 131 counts/(deg/s),
        10 counts/uT).
    offset : ndarray, shape (3,)
        Offset (bias / hard iron) in counts at ``temp_ref_c``.
    matrix : ndarray, shape (3, 3)
        Symmetric matrix in units per count that **multiplies**:
        ``calibrated = (raw - offset) @ matrix.T``.
    noise : float
        White noise, counts rms per axis.
    tempco : ndarray, shape (3,)
        Offset drift in counts per degC.
    gain_tempco : float
        Relative drift of ``matrix`` per degC (``matrix(T) = matrix * (1 + gain_tempco*dT)``).
    temp_ref_c : float
        Temperature (degC) at which ``offset`` and ``matrix`` hold.
    """

    name: str
    units: str
    counts_per_unit: float
    offset: np.ndarray
    matrix: np.ndarray
    noise: float
    tempco: np.ndarray
    gain_tempco: float
    temp_ref_c: float

    @property
    def scale(self) -> np.ndarray:
        """``matrix * counts_per_unit``: the dimensionless correction (identity = nominal)."""
        return self.matrix * self.counts_per_unit

    def offset_at(self, temp_c: Any) -> np.ndarray:
        """Offset in counts at ``temp_c`` (degC), shape ``temp_c.shape + (3,)``."""
        dt = np.asarray(temp_c, dtype=np.float64) - self.temp_ref_c
        return self.offset + dt[..., None] * self.tempco

    def matrix_at(self, temp_c: float) -> np.ndarray:
        """Matrix (units per count, multiplies) at ``temp_c`` degC."""
        return self.matrix * (1.0 + self.gain_tempco * (float(temp_c) - self.temp_ref_c))

    def apply(self, raw: Any, temp_c: Any = None) -> np.ndarray:
        """Calibrate raw counts (N, 3) with the true parameters, in :attr:`units`.

        ``temp_c`` (scalar or (N,), degC) corrects the temperature drift; ``None`` uses the
        parameters at ``temp_ref_c``.
        """
        raw = np.asarray(raw, dtype=np.float64)
        if temp_c is None:
            return (raw - self.offset) @ self.matrix.T
        t = np.broadcast_to(np.asarray(temp_c, dtype=np.float64), raw.shape[:-1])
        factor = 1.0 + self.gain_tempco * (t - self.temp_ref_c)
        return ((raw - self.offset_at(t)) @ self.matrix.T) * factor[..., None]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (lists of floats)."""
        return {
            "name": self.name,
            "units": self.units,
            "counts_per_unit": self.counts_per_unit,
            "offset": self.offset.tolist(),
            "matrix": self.matrix.tolist(),
            "noise": self.noise,
            "tempco": self.tempco.tolist(),
            "gain_tempco": self.gain_tempco,
            "temp_ref_c": self.temp_ref_c,
        }


@dataclass(frozen=True)
class Truth:
    """Everything the simulator knows: three :class:`SensorTruth` and the environment.

    ``field_world_ut`` is the magnetic field in the world frame (x north, y west, z up), in uT;
    ``gravity_world_g`` the specific force at rest, ``(0, 0, 1)`` g.
    """

    accel: SensorTruth
    gyro: SensorTruth
    mag: SensorTruth
    field_ut: float
    inclination_deg: float
    temp_ref_c: float
    temp_noise: float

    @property
    def field_world_ut(self) -> np.ndarray:
        inc = math.radians(self.inclination_deg)
        return self.field_ut * np.array([math.cos(inc), 0.0, -math.sin(inc)])

    @property
    def gravity_world_g(self) -> np.ndarray:
        return np.array([0.0, 0.0, 1.0])

    def sensor(self, name: str) -> SensorTruth:
        """The sensor called ``name`` (``accel``, ``gyro`` or ``mag``)."""
        if name not in ("accel", "gyro", "mag"):
            raise CalibrationError(f"unknown sensor {name!r}: use 'accel', 'gyro' or 'mag'")
        return getattr(self, name)

    def to_dict(self) -> dict[str, Any]:
        return {
            "accel": self.accel.to_dict(),
            "gyro": self.gyro.to_dict(),
            "mag": self.mag.to_dict(),
            "field_ut": self.field_ut,
            "inclination_deg": self.inclination_deg,
            "temp_ref_c": self.temp_ref_c,
            "temp_noise": self.temp_noise,
        }


_DEFAULTS = {
    # name: units, counts/unit, offset range (counts), diag spread, offdiag spread,
    #       noise (counts rms), tempco range (counts/degC)
    "accel": ("g", ACCEL_COUNTS_PER_G, (150.0, 900.0), 0.03, 0.01, 30.0, 3.0),
    "gyro": ("rad/s", GYRO_COUNTS_PER_RAD_S, (60.0, 400.0), 0.03, 0.01, 4.0, 2.0),
    "mag": ("uT", MAG_COUNTS_PER_UT, (100.0, 400.0), 0.08, 0.04, 3.0, 0.5),
}


def _make_sensor(
    name: str, rng: np.random.Generator, over: Mapping[str, Any], temp_ref_c: float
) -> SensorTruth:
    units, cpu, (omin, omax), dspread, ospread, noise, tc = _DEFAULTS[name]
    unknown = set(over) - {"offset", "matrix", "scale", "noise", "tempco", "gain_tempco"}
    if unknown:
        raise CalibrationError(
            f"unknown {name} option(s) {sorted(unknown)}: use offset, matrix, scale, noise, "
            "tempco, gain_tempco"
        )
    # draw everything first so that overriding one value does not change the others
    offset = rng.uniform(omin, omax, 3) * rng.choice([-1.0, 1.0], 3)
    diag = 1.0 + rng.uniform(-dspread, dspread, 3)
    off = rng.uniform(-ospread, ospread, 3)
    scale = np.array(
        [[diag[0], off[0], off[1]], [off[0], diag[1], off[2]], [off[1], off[2], diag[2]]]
    )
    tempco = rng.uniform(-tc, tc, 3)
    if "offset" in over:
        offset = np.asarray(over["offset"], dtype=np.float64).reshape(3)
    if "scale" in over:
        s = np.asarray(over["scale"], dtype=np.float64)
        scale = np.diag(s) if s.shape == (3,) else s.reshape(3, 3)
    matrix = scale / cpu
    if "matrix" in over:
        matrix = np.asarray(over["matrix"], dtype=np.float64).reshape(3, 3)
    if not np.allclose(matrix, matrix.T, rtol=0, atol=1e-15 * np.abs(matrix).max()):
        raise CalibrationError(f"{name} matrix must be symmetric (the fits' model), got {matrix}")
    if np.linalg.det(matrix) <= 0:
        raise CalibrationError(f"{name} matrix must be positive definite, got {matrix}")
    if "tempco" in over:
        tempco = np.broadcast_to(np.asarray(over["tempco"], dtype=np.float64), (3,)).copy()
    return SensorTruth(
        name=name,
        units=units,
        counts_per_unit=cpu,
        offset=_ro(offset),
        matrix=_ro(matrix),
        noise=float(over.get("noise", noise)),
        tempco=_ro(tempco),
        gain_tempco=float(over.get("gain_tempco", 0.0)),
        temp_ref_c=temp_ref_c,
    )


def _ro(a: Any) -> np.ndarray:
    arr = np.array(a, dtype=np.float64)
    arr.setflags(write=False)
    return arr


# --------------------------------------------------------------------------------------------
# scripts


@dataclass(frozen=True)
class Script:
    """A scripted sequence of orientations: hold still, turn, hold still, ...

    Attributes
    ----------
    poses : ndarray, shape (P, 3, 3)
        Body-to-world rotation held during pose ``j``.
    rotvecs : ndarray, shape (P, 3)
        Body-frame rotation vector (axis * angle, rad) of the move *into* pose ``j``
        (``rotvecs[0]`` is zero: the script starts at ``poses[0]``). Angles may exceed pi
        (a full turn about an axis).
    move_s : ndarray, shape (P,)
        Duration of the move into pose ``j`` in seconds (``move_s[0]`` is 0).
    hold_s : ndarray, shape (P,)
        Seconds held still at pose ``j`` (``hold_s[0]`` includes the initial rest).
    labels : tuple of str
        One short description per pose.
    """

    poses: np.ndarray
    rotvecs: np.ndarray
    move_s: np.ndarray
    hold_s: np.ndarray
    labels: tuple[str, ...]

    def __len__(self) -> int:
        return len(self.labels)

    @property
    def duration_s(self) -> float:
        """Total length of the script in seconds."""
        return float(self.move_s.sum() + self.hold_s.sum())

    @classmethod
    def from_moves(
        cls,
        start: Any,
        rotvecs: Any,
        *,
        hold_s: Any,
        move_s: Any = None,
        peak_dps: float = 120.0,
        min_move_s: float = 0.4,
        labels: Sequence[str] | None = None,
    ) -> Script:
        """Build a script from a start orientation and body-frame moves.

        Parameters
        ----------
        start : array_like (3, 3)
            Body-to-world rotation of pose 0.
        rotvecs : array_like (P - 1, 3)
            Body-frame rotation vectors (rad) of the moves into poses 1..P-1.
        hold_s : float or array_like (P,)
            Seconds still at each pose.
        move_s : float or array_like (P - 1,), optional
            Move durations; by default long enough that the peak rate is ``peak_dps``
            (minimum-jerk profile: peak = 1.875 * angle / duration), at least ``min_move_s``.
        """
        start = np.asarray(start, dtype=np.float64).reshape(3, 3)
        rv = np.asarray(rotvecs, dtype=np.float64).reshape(-1, 3)
        p = len(rv) + 1
        angles = np.degrees(np.linalg.norm(rv, axis=1))
        if move_s is None:
            mv = np.maximum(min_move_s, 1.875 * angles / float(peak_dps))
        else:
            mv = np.broadcast_to(np.asarray(move_s, dtype=np.float64), (p - 1,)).copy()
        if np.any(mv <= 0) and len(mv):
            raise CalibrationError("move durations must be > 0 s")
        poses = [start]
        rots = rotvec_to_matrix(rv) if len(rv) else np.zeros((0, 3, 3))
        for r in rots:
            poses.append(poses[-1] @ r)
        hold = np.broadcast_to(np.asarray(hold_s, dtype=np.float64), (p,)).copy()
        if np.any(hold < 0):
            raise CalibrationError("hold durations must be >= 0 s")
        labs = tuple(labels) if labels is not None else tuple(f"pose {i}" for i in range(p))
        if len(labs) != p:
            raise CalibrationError(f"need {p} labels, got {len(labs)}")
        return cls(
            poses=_ro(np.stack(poses)),
            rotvecs=_ro(np.vstack([np.zeros((1, 3)), rv])),
            move_s=_ro(np.concatenate([[0.0], mv])),
            hold_s=_ro(hold),
            labels=labs,
        )

    @classmethod
    def from_poses(
        cls,
        poses: Any,
        *,
        hold_s: Any = 1.0,
        settle_s: float = 2.0,
        peak_dps: float = 120.0,
        min_move_s: float = 0.4,
        labels: Sequence[str] | None = None,
    ) -> Script:
        """Visit body-to-world rotations ``poses`` (P, 3, 3) in order, each by the shortest turn.

        ``settle_s`` seconds of rest are added to the first hold (for detectors that learn the
        noise floor at rest).
        """
        ps = np.asarray(poses, dtype=np.float64).reshape(-1, 3, 3)
        rv = [matrix_to_rotvec(a.T @ b) for a, b in zip(ps[:-1], ps[1:])]
        hold = np.broadcast_to(np.asarray(hold_s, dtype=np.float64), (len(ps),)).copy()
        hold[0] += settle_s
        return cls.from_moves(
            ps[0],
            np.array(rv).reshape(-1, 3),
            hold_s=hold,
            peak_dps=peak_dps,
            min_move_s=min_move_s,
            labels=labels,
        )

    def __add__(self, other: Script) -> Script:
        """Concatenate: after this script's last pose, turn into ``other``'s first pose."""
        if not isinstance(other, Script):
            return NotImplemented
        joint = matrix_to_rotvec(self.poses[-1].T @ other.poses[0])
        angle = math.degrees(float(np.linalg.norm(joint)))
        first = max(0.4, 1.875 * angle / 120.0)
        return Script(
            poses=_ro(np.concatenate([self.poses, other.poses])),
            rotvecs=_ro(np.concatenate([self.rotvecs, [joint], other.rotvecs[1:]])),
            move_s=_ro(np.concatenate([self.move_s, [first], other.move_s[1:]])),
            hold_s=_ro(np.concatenate([self.hold_s, other.hold_s])),
            labels=self.labels + other.labels,
        )


def _frame_from_up(up_body: np.ndarray, heading_rad: float) -> np.ndarray:
    """A body-to-world rotation whose body-frame 'up' is ``up_body``, then turned by heading."""
    up = up_body / np.linalg.norm(up_body)
    # rotation taking body 'up' to world z
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(up, z)
    s, c = np.linalg.norm(axis), float(np.dot(up, z))
    if s < 1e-12:
        base = np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    else:
        base = rotvec_to_matrix(axis / s * math.atan2(s, c))
    return rotvec_to_matrix(np.array([0.0, 0.0, heading_rad])) @ base


def globe_script(
    *,
    latitudes: int = 7,
    turns: int = 12,
    hold_s: float = 1.0,
    settle_s: float = 2.0,
    peak_dps: float = 120.0,
    azimuth_deg: float = 30.0,
    jitter_deg: float = 2.0,
    seed: int = 0,
) -> Script:
    """The seed's globe scheme: ``latitudes`` points on a meridian x ``turns`` twists = poses.

    The board sits flat on a globe at latitude ``phi`` (from +90 to -90 degrees, evenly
    spaced, poles included) on the meridian facing ``azimuth_deg`` (degrees from north towards
    west), body z along the surface normal, and is twisted about its own z axis in
    ``360 / turns`` degree steps, snaking so that each move is one step. The default gives
    7 x 12 = 84 poses; the body-frame 'up' vector is
    ``(cos phi cos psi, cos phi sin psi, sin phi)``. ``jitter_deg`` adds a random tilt to each
    pose, as placing a board by hand does.
    """
    if latitudes < 2 or turns < 1:
        raise CalibrationError("globe_script needs latitudes >= 2 and turns >= 1")
    rng = np.random.default_rng(seed)
    az = math.radians(azimuth_deg)
    poses, labels = [], []
    for i, phi_deg in enumerate(np.linspace(90.0, -90.0, latitudes)):
        phi = math.radians(phi_deg)
        n = np.array([math.cos(phi) * math.cos(az), math.cos(phi) * math.sin(az), math.sin(phi)])
        sp = math.sin(phi)
        e_n = np.array([-sp * math.cos(az), -sp * math.sin(az), math.cos(phi)])
        e_e = np.cross(e_n, n)
        order = range(turns) if i % 2 == 0 else range(turns - 1, -1, -1)
        for j in order:
            psi = 2.0 * math.pi * j / turns
            bx = math.cos(psi) * e_n + math.sin(psi) * e_e
            by = np.cross(n, bx)
            rot = np.column_stack([bx, by, n])  # body axes in world coordinates
            if jitter_deg:
                rot = rot @ rotvec_to_matrix(rng.normal(0.0, math.radians(jitter_deg), 3))
            poses.append(rot)
            labels.append(f"latitude {phi_deg:+.0f} deg, twist {math.degrees(psi):.0f} deg")
    return Script.from_poses(
        np.array(poses), hold_s=hold_s, settle_s=settle_s, peak_dps=peak_dps, labels=labels
    )


def six_face_script(
    *,
    hold_s: float = 2.0,
    settle_s: float = 2.0,
    peak_dps: float = 120.0,
    jitter_deg: float = 2.0,
    seed: int = 0,
) -> Script:
    """Six poses, each body axis pointing up then down: +z, -z, +x, -x, +y, -y up.

    Each pose gets a random heading and a tilt of ``jitter_deg`` (rms).
    """
    rng = np.random.default_rng(seed)
    ups = [(0, 0, 1), (0, 0, -1), (1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0)]
    names = ["+Z up", "-Z up", "+X up", "-X up", "+Y up", "-Y up"]
    poses = []
    for up in ups:
        rot = _frame_from_up(np.array(up, dtype=float), rng.uniform(0, 2 * math.pi))
        if jitter_deg:
            rot = rot @ rotvec_to_matrix(rng.normal(0.0, math.radians(jitter_deg), 3))
        poses.append(rot)
    return Script.from_poses(
        np.array(poses), hold_s=hold_s, settle_s=settle_s, peak_dps=peak_dps, labels=names
    )


def rotation_script(
    axis: str | Sequence[float] = "xyz",
    angle_deg: float = 360.0,
    *,
    hold_s: float = 1.0,
    settle_s: float = 2.0,
    peak_dps: float = 180.0,
    start: Any = None,
) -> Script:
    """Turns about body axes by ``+angle_deg`` then ``-angle_deg``, with rests in between.

    For gyroscope gain calibration: integrating the gyro over each turn must give
    ``angle_deg``. ``axis`` is a string of axis letters (``"x"``, ``"xyz"``, ``"-z"``...) or a
    3-vector (one axis). ``start`` is the body-to-world rotation of the first rest (default:
    flat, body z up). Peak rate ``peak_dps`` (keep below the gyro's 250 deg/s range).
    """
    unit = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}
    axes: list[np.ndarray] = []
    names: list[str] = []
    if isinstance(axis, str):
        sign = 1.0
        for ch in axis.lower():
            if ch in "+-":
                sign = -1.0 if ch == "-" else 1.0
                continue
            if ch not in unit:
                raise CalibrationError(f"axis letters must be x, y or z, got {axis!r}")
            axes.append(sign * np.array(unit[ch]))
            names.append(("-" if sign < 0 else "") + ch)
            sign = 1.0
    else:
        v = np.asarray(axis, dtype=np.float64).reshape(3)
        if not np.linalg.norm(v) > 0:
            raise CalibrationError("rotation axis must be a non-zero 3-vector")
        axes.append(v / np.linalg.norm(v))
        names.append("axis")
    if not axes:
        raise CalibrationError("rotation_script needs at least one axis")
    ang = math.radians(angle_deg)
    rvs, labels = [], ["rest"]
    for a, nm in zip(axes, names):
        rvs += [a * ang, -a * ang]
        labels += [f"after {nm} {angle_deg:+g} deg", f"after {nm} {-angle_deg:+g} deg"]
    hold = np.full(len(rvs) + 1, float(hold_s))
    hold[0] += settle_s
    return Script.from_moves(
        np.eye(3) if start is None else start,
        np.array(rvs),
        hold_s=hold,
        peak_dps=peak_dps,
        labels=labels,
    )


# --------------------------------------------------------------------------------------------
# recording


@dataclass(frozen=True)
class Recording:
    """Samples of a :class:`SimIMU` following a :class:`Script`.

    Attributes
    ----------
    t : ndarray (N,)
        Sample time in seconds from the start of the script.
    accel, gyro, mag : ndarray (N, 3), int32
        Raw readings in counts (int16 range).
    temp_raw : ndarray (N,), int32
        Temperature counts (``T_degC = temp_raw / 340 + 36.53``).
    temp_c : ndarray (N,)
        True die temperature in degC.
    still : ndarray (N,), bool
        True while the board is held still at a pose.
    pose : ndarray (N,), int
        Index of the pose held (``-1`` while turning).
    orientation : ndarray (N, 3, 3)
        True body-to-world rotation.
    accel_g, gyro_rad_s, mag_ut : ndarray (N, 3)
        True physical values in the body frame: specific force (g), angular rate (rad/s),
        magnetic field (uT).
    truth : Truth
    script : Script
    rate_hz : float
    """

    t: np.ndarray
    accel: np.ndarray
    gyro: np.ndarray
    mag: np.ndarray
    temp_raw: np.ndarray
    temp_c: np.ndarray
    still: np.ndarray
    pose: np.ndarray
    orientation: np.ndarray
    accel_g: np.ndarray
    gyro_rad_s: np.ndarray
    mag_ut: np.ndarray
    truth: Truth
    script: Script
    rate_hz: float

    def __len__(self) -> int:
        return len(self.t)

    def frames(self, channels: int = 10) -> np.ndarray:
        """Device frames (N, K) int32 in channel order: K=10 ``ax ay az gx gy gz mx my mz
        temp``, K=9 (MotionCal ``Raw:``, no temperature), K=7 (no magnetometer), K=6, K=3."""
        parts = {
            10: [self.accel, self.gyro, self.mag, self.temp_raw[:, None]],
            9: [self.accel, self.gyro, self.mag],
            7: [self.accel, self.gyro, self.temp_raw[:, None]],
            6: [self.accel, self.gyro],
            3: [self.accel],
        }
        if channels not in parts:
            raise CalibrationError(f"channels must be one of {sorted(parts)}, got {channels}")
        return np.hstack(parts[channels]).astype(np.int32)

    def pose_means(self, sensor: str = "accel") -> np.ndarray:
        """Mean raw counts (P, 3) of ``sensor`` over each pose's still samples."""
        data = getattr(self, sensor)
        n = int(self.pose.max()) + 1
        return np.array([data[self.pose == j].mean(axis=0) for j in range(n)])


class SimIMU:
    """A simulated accelerometer + gyroscope + magnetometer + thermometer with known truth.

    Parameters
    ----------
    seed : int
        Seeds both the drawn calibration parameters and the noise of :meth:`record`.
    accel, gyro, mag : mapping, optional
        Overrides of the drawn truth: ``offset`` (3 counts), ``scale`` (3 or 3x3,
        dimensionless, 1 = nominal: ``matrix = scale / counts_per_unit``), or ``matrix``
        (3x3, units per count), ``noise`` (counts rms), ``tempco`` (counts/degC, scalar or
        3), ``gain_tempco`` (1/degC). Defaults: accel offsets 150-900 counts (0.01-0.05 g),
        scale 1 +- 3 %, cross-axis +- 1 %, noise 30 counts; gyro offsets 60-400 counts
        (0.5-3 deg/s), noise 4 counts; mag hard iron 100-400 counts (10-40 uT), soft iron
        1 +- 8 % / +- 4 %, noise 3 counts.
    field_ut : float
        Magnitude of the magnetic field in uT.
    inclination_deg : float
        Dip of the field below the horizon in degrees.
    temp_ref_c : float
        Temperature (degC) at which the offsets and matrices hold.
    temp_noise : float
        Noise of the temperature channel, counts rms.

    Examples
    --------
    >>> import numpy as np
    >>> from triaxcal.sim import SimIMU, six_face_script
    >>> imu = SimIMU(seed=1)
    >>> rec = imu.record(six_face_script(hold_s=1.0), rate_hz=100)
    >>> g = imu.truth.accel.apply(rec.accel[rec.still])
    >>> bool(abs(np.linalg.norm(g, axis=1).mean() - 1.0) < 1e-3)
    True
    """

    def __init__(
        self,
        seed: int = 0,
        *,
        accel: Mapping[str, Any] | None = None,
        gyro: Mapping[str, Any] | None = None,
        mag: Mapping[str, Any] | None = None,
        field_ut: float = 50.0,
        inclination_deg: float = 60.0,
        temp_ref_c: float = 25.0,
        temp_noise: float = 5.0,
    ) -> None:
        self.seed = int(seed)
        rng = np.random.default_rng([self.seed, 0x7E1A])
        if not field_ut > 0:
            raise CalibrationError(f"field_ut must be > 0 uT, got {field_ut}")
        self.truth = Truth(
            accel=_make_sensor("accel", rng, accel or {}, temp_ref_c),
            gyro=_make_sensor("gyro", rng, gyro or {}, temp_ref_c),
            mag=_make_sensor("mag", rng, mag or {}, temp_ref_c),
            field_ut=float(field_ut),
            inclination_deg=float(inclination_deg),
            temp_ref_c=float(temp_ref_c),
            temp_noise=float(temp_noise),
        )
        self._rng = np.random.default_rng([self.seed, 0x5A17])

    def __repr__(self) -> str:
        return f"SimIMU(seed={self.seed})"

    def with_truth(self, **changes: Any) -> SimIMU:
        """A copy whose :class:`Truth` has ``changes`` applied (``dataclasses.replace``)."""
        new = SimIMU.__new__(SimIMU)
        new.seed = self.seed
        new.truth = replace(self.truth, **changes)
        new._rng = np.random.default_rng([self.seed, 0x5A17])
        return new

    def record(
        self,
        script: Script,
        rate_hz: float = 100.0,
        *,
        temp_c: float | tuple[float, float] = 25.0,
        shake_g: float = 0.0,
    ) -> Recording:
        """Sample the IMU at ``rate_hz`` while it follows ``script``.

        Parameters
        ----------
        script : Script
            From :func:`globe_script`, :func:`six_face_script`, :func:`rotation_script` or
            :meth:`Script.from_moves`.
        rate_hz : float
            Sample rate in Hz.
        temp_c : float or (start, end)
            Die temperature in degC: constant, or a linear ramp over the recording.
        shake_g : float
            Rms of a random linear acceleration (g) added while turning (hand shake).

        Returns
        -------
        Recording
        """
        if not rate_hz > 0:
            raise CalibrationError(f"rate_hz must be > 0, got {rate_hz}")
        tr = self.truth
        rng = self._rng
        starts, kinds, index = [], [], []
        t = 0.0
        for j in range(len(script)):
            if j > 0:
                starts.append(t)
                kinds.append(1)
                index.append(j)
                t += float(script.move_s[j])
            starts.append(t)
            kinds.append(0)
            index.append(j)
            t += float(script.hold_s[j])
        total = t
        n = max(1, math.floor(total * rate_hz + 1e-9))
        ts = np.arange(n) / float(rate_hz)
        seg = np.searchsorted(np.asarray(starts), ts, side="right") - 1
        kinds_a, index_a = np.asarray(kinds)[seg], np.asarray(index)[seg]
        starts_a = np.asarray(starts)[seg]
        moving = kinds_a == 1
        pose = np.where(moving, -1, index_a)
        orient = script.poses[index_a].copy()
        omega = np.zeros((n, 3))
        if moving.any():
            j = index_a[moving]
            dur = script.move_s[j]
            tau = np.clip((ts[moving] - starts_a[moving]) / dur, 0.0, 1.0)
            s = tau**3 * (10 - 15 * tau + 6 * tau**2)
            ds = 30 * tau**2 * (1 - tau) ** 2 / dur
            rv = script.rotvecs[j]
            orient[moving] = script.poses[j - 1] @ rotvec_to_matrix(rv * s[:, None])
            omega[moving] = rv * ds[:, None]
        rt = np.swapaxes(orient, 1, 2)  # world -> body
        accel_g = rt @ tr.gravity_world_g
        if shake_g and moving.any():
            accel_g[moving] += rng.normal(0.0, shake_g, (int(moving.sum()), 3))
        mag_ut = rt @ tr.field_world_ut
        if isinstance(temp_c, (tuple, list)):
            t0, t1 = float(temp_c[0]), float(temp_c[1])
        else:
            t0 = t1 = float(temp_c)
        temp = np.linspace(t0, t1, n)
        raw = {}
        for name, phys in (("accel", accel_g), ("gyro", omega), ("mag", mag_ut)):
            sens = tr.sensor(name)
            factor = 1.0 + sens.gain_tempco * (temp - sens.temp_ref_c)
            counts = (phys @ np.linalg.inv(sens.matrix).T) / factor[:, None]
            counts += sens.offset_at(temp) + rng.normal(0.0, sens.noise, (n, 3))
            raw[name] = _to_int16(counts)
        temp_raw = _to_int16(temp_raw_from_c(temp) + rng.normal(0.0, tr.temp_noise, n))
        return Recording(
            t=ts,
            accel=raw["accel"],
            gyro=raw["gyro"],
            mag=raw["mag"],
            temp_raw=temp_raw,
            temp_c=temp,
            still=~moving,
            pose=pose,
            orientation=orient,
            accel_g=accel_g,
            gyro_rad_s=omega,
            mag_ut=mag_ut,
            truth=tr,
            script=script,
            rate_hz=float(rate_hz),
        )


def _to_int16(x: np.ndarray) -> np.ndarray:
    return np.clip(np.rint(x), INT16_MIN, INT16_MAX).astype(np.int32)



# --------------------------------------------------------------------------------------------
# simulated serial device

#: Mode bytes of the device commands (TEAM.md): streaming protocol switched to by each byte.
MODE_BYTES = {b"P": None, b"B": "binary", b"F": "framed", b"T": "text", b"R": "raw"}
_MODE_OF = {None: "P", "binary": "B", "framed": "F", "text": "T", "raw": "R"}


@dataclass(frozen=True)
class Faults:
    """Faults a :class:`SimDevice` injects into the bytes it sends (at random, at most one
    per frame; damage to a frame's delimiter also spoils the next frame, marked so in the log).

    Attributes
    ----------
    garbage_prob : float
        Chance per frame of 1..``garbage_max`` random bytes just before it. In the text and
        ``Raw:`` modes the junk is line noise (bytes 0x80-0xFF and control characters, never
        digits or signs), and half the time ends with a newline of its own.
    garbage_max : int
        Most garbage bytes in one burst.
    drop_prob : float
        Chance per frame that one of its bytes is lost.
    drop_where : {"any", "structure"}
        Which byte is lost: any, or (text and ``Raw:`` lines) only a separator or the line
        end. A lost digit turns a text number into another number, which no decoder can see.
    flip_prob : float
        Chance per frame that one bit of one of its bytes is flipped.
    seed : int
        Seed of the fault generator.
    """

    garbage_prob: float = 0.0
    garbage_max: int = 8
    drop_prob: float = 0.0
    drop_where: str = "any"
    flip_prob: float = 0.0
    seed: int = 0


@dataclass(frozen=True)
class SentFrame:
    """One frame as the :class:`SimDevice` sent it (its log, for tests).

    ``index`` is the sample index (sim time ``index / rate_hz`` s); ``protocol`` the encoding;
    ``values`` the counts encoded; ``polled`` whether it answered a ``!`` request; ``intact``
    is False when its bytes were damaged (dropped or flipped), cut off by an unplug, or glued
    to garbage in front of it (so that a decoder cannot tell where the frame starts).
    """

    index: int
    protocol: str
    values: tuple[int, ...]
    polled: bool
    intact: bool


class SimDevice:
    """A simulated sensor board on a pseudo-terminal: open :attr:`port` with pyserial.

    The device runs in a background thread. It samples a :class:`SimIMU` following a
    :class:`Script` at ``rate_hz`` of simulated time, ``speed`` times faster than real time,
    and implements the firmware's commands (TEAM.md): ``!`` answers one legacy binary frame of
    the current sample (in any mode); ``P`` stops streaming (the boot default), ``B``
    streams legacy binary frames, ``F`` framed (COBS + CRC-16) frames, ``T`` text lines, ``R``
    MotionCal ``Raw:`` lines; a 68-byte MotionCal calibration packet with a valid CRC is
    answered with ``Cal1:``/``Cal2:`` lines (stored in :attr:`motioncal`).

    Parameters
    ----------
    imu : SimIMU, optional
        The sensor (default ``SimIMU(seed)``).
    script : Script, optional
        The motion (default :func:`globe_script`).
    rate_hz : float
        Samples per second of simulated time.
    speed : float
        Simulated seconds per real second; frames go out at ``rate_hz * speed`` per second.
    channels : {10, 7}
        Values per frame: 10 = ``ax ay az gx gy gz mx my mz temp``, 7 = no magnetometer.
        ``Raw:`` lines always carry 9 (magnetometer zeros when ``channels=7``).
    mode : {"P", "B", "F", "T", "R"}
        Mode at power-on (``"P"``, polled, like the firmware).
    loop : bool
        Start the script again at its end; otherwise hold the last pose and set
        :attr:`finished` (streaming stops).
    faults : Faults, optional
        Bytes to damage, for tests.
    temp_c : float or (start, end)
        Die temperature (see :meth:`SimIMU.record`).
    wrong_baud : bool
        Behave like a board on another baud rate: every byte sent is scrambled and commands
        are not understood (use with a streaming ``mode``).
    link : str or path, optional
        Path of the symlink that :attr:`port` names (default: in a fresh temporary folder,
        made by :meth:`start`). It stays the same across :meth:`unplug`, as ``/dev/ttyUSB0``
        does.
    seed : int
        Seed of the default IMU and of the noise.

    Examples
    --------
    >>> import serial
    >>> from triaxcal.sim import SimDevice
    >>> with SimDevice(speed=10) as dev:
    ...     with serial.Serial(dev.port, 115200, timeout=1) as port:
    ...         _ = port.write(b"!")
    ...         len(port.read(21))
    21
    """

    def __init__(
        self,
        imu: SimIMU | None = None,
        script: Script | None = None,
        *,
        rate_hz: float = 100.0,
        speed: float = 1.0,
        channels: int = 10,
        mode: str = "P",
        loop: bool = True,
        faults: Faults | None = None,
        temp_c: float | tuple[float, float] = 25.0,
        wrong_baud: bool = False,
        link: Any = None,
        seed: int = 0,
    ) -> None:
        if channels not in (10, 7):
            raise CalibrationError(f"SimDevice channels must be 10 or 7, got {channels}")
        if mode.encode() not in MODE_BYTES:
            raise CalibrationError(f"mode must be one of P, B, F, T, R, got {mode!r}")
        if not (rate_hz > 0 and speed > 0):
            raise CalibrationError("rate_hz and speed must be > 0")
        faults = faults or Faults()
        if faults.drop_where not in ("any", "structure"):
            raise CalibrationError("Faults.drop_where must be 'any' or 'structure'")
        self.imu = imu if imu is not None else SimIMU(seed)
        self.script = script if script is not None else globe_script(seed=seed)
        self.recording = self.imu.record(self.script, rate_hz, temp_c=temp_c)
        self.rate_hz = float(rate_hz)
        self.speed = float(speed)
        self.channels = int(channels)
        self.loop = bool(loop)
        self.faults = faults
        self.wrong_baud = bool(wrong_baud)
        self.boot_mode = MODE_BYTES[mode.encode()]
        self.protocol: str | None = self.boot_mode
        self._frames = self.recording.frames(self.channels)
        self._frames9 = (
            self.recording.frames(9)
            if self.channels == 10
            else np.hstack([self._frames[:, :6], np.zeros((len(self._frames), 3), np.int32)])
        )
        self._frng = np.random.default_rng([faults.seed, 0xFA17])
        self._brng = np.random.default_rng([seed, 0xBAD])
        self.sent: list[SentFrame] = []
        self.received = bytearray()
        self.motioncal: dict[str, Any] | None = None
        self.finished = threading.Event()
        self.unplugs = 0
        self._link_dir: str | None = None
        #: Path to open with pyserial (a symlink to the pty; set by :meth:`start` if not given).
        self.port: str = "" if link is None else str(link)
        self._master: int | None = None
        self._slave: int | None = None
        self.pty_path: str | None = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._pending: list[list[Any]] = []  # [bytes, SentFrame, bytes written]
        self._pending_bytes = 0
        self._seq = 0
        self._next = 0  # next sample index to stream
        self._t0 = 0.0
        self._unplug_until = 0.0
        self._silent_until = 0.0
        self._packet: bytearray | None = None
        self._packet_t = 0.0
        self._damage_next = False
        self._requests: list[tuple[float, threading.Event]] = []

    # -- life cycle
    def start(self) -> SimDevice:
        """Open the pseudo-terminal and start the device thread; returns ``self``."""
        if self._thread is not None:
            return self
        if not self.port:
            self._link_dir = tempfile.mkdtemp(prefix="triaxcal-sim-")
            self.port = os.path.join(self._link_dir, "ttySIM0")
        self._stop.clear()
        self._plug()
        self._t0 = time.monotonic()
        self._thread = threading.Thread(target=self._run, name="SimDevice", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop the thread, close the pseudo-terminal and remove the port symlink."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None
        self._unplug_now()
        if self._link_dir is not None:
            with contextlib.suppress(OSError):
                os.rmdir(self._link_dir)
            self._link_dir = None
            self.port = ""

    def __enter__(self) -> SimDevice:  # noqa: PYI034
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def __repr__(self) -> str:
        return (
            f"SimDevice(port={self.port!r}, mode={_MODE_OF[self.protocol]!r}, "
            f"rate_hz={self.rate_hz:g}, speed={self.speed:g}, sent={len(self.sent)})"
        )

    # -- test hooks
    def unplug(self, seconds: float) -> None:
        """Pull the cable for ``seconds`` (real time): the port vanishes, then comes back on
        the same :attr:`port` path with the device rebooted (boot mode, polled)."""
        done = threading.Event()
        self._requests.append((float(seconds), done))
        if self._thread is not None and self._thread.is_alive():
            done.wait(timeout=2.0)

    def silence(self, seconds: float) -> None:
        """Stop answering and streaming for ``seconds`` (real time); commands are ignored."""
        self._silent_until = time.monotonic() + float(seconds)

    @property
    def sim_time_s(self) -> float:
        """Simulated seconds since :meth:`start`."""
        return (time.monotonic() - self._t0) * self.speed

    def frames_sent(self, *, intact_only: bool = False) -> np.ndarray:
        """Values of the frames sent so far, (n, K) int (``intact_only``: undamaged ones)."""
        rows = [f.values for f in list(self.sent) if f.intact or not intact_only]
        k = len(rows[0]) if rows else self.channels
        return np.array(rows, dtype=np.int64).reshape(-1, k)

    # -- pty
    def _plug(self) -> None:
        import tty  # POSIX only: importing triaxcal.sim must work everywhere

        master, slave = os.openpty()
        tty.setraw(slave)
        os.set_blocking(master, False)
        self._master, self._slave = master, slave
        self.pty_path = os.ttyname(slave)
        tmp = self.port + ".new"
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        os.symlink(self.pty_path, tmp)
        os.replace(tmp, self.port)

    def _unplug_now(self) -> None:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(self.port)
        for fd in (self._master, self._slave):
            if fd is not None:
                with contextlib.suppress(OSError):
                    os.close(fd)
        self._master = self._slave = None
        # whatever was half sent is lost; log it as damaged
        for item in self._pending:
            if item[2]:
                self.sent.append(replace(item[1], intact=False))
        self._pending.clear()
        self._pending_bytes = 0
        self._packet = None

    # -- the device loop
    def _sample(self) -> int:
        return int((time.monotonic() - self._t0) * self.speed * self.rate_hz)

    def _run(self) -> None:
        n = len(self._frames)
        while not self._stop.is_set():
            now = time.monotonic()
            while self._requests:  # unplug requests, served here so no fd is closed under us
                seconds, done = self._requests.pop(0)
                self._unplug_until = now + seconds
                self._unplug_now()
                self.unplugs += 1
                done.set()
            with self._lock:
                if self._master is None:
                    if now >= self._unplug_until:
                        self._plug()
                        self.protocol = self.boot_mode  # the board rebooted
                        self._seq = 0
                        self._damage_next = False
                        self._next = self._sample()
                    else:
                        time.sleep(0.005)
                        continue
                master = self._master
            assert master is not None
            try:
                ready, _, _ = select.select([master], [], [], self._wait_s())
                if ready:
                    data = os.read(master, 4096)
                    if now >= self._silent_until and not self.wrong_baud:
                        self._commands(data)
                cur = self._sample()
                if not self.loop and cur >= n:
                    cur = n - 1
                    if self._next >= n:
                        self.finished.set()
                silent = time.monotonic() < self._silent_until
                if self.protocol is not None and not silent:
                    while self._next <= cur and self._pending_bytes < 8192:
                        self._emit(self._next, self.protocol, polled=False)
                        self._next += 1
                    if not self.loop and self._next >= n:
                        self.finished.set()
                if silent or self.protocol is None:
                    self._next = max(self._next, cur + 1)  # no burst of old samples later
                self._flush()
            except OSError:
                # unplugged under our feet (stop() or unplug() from another thread)
                time.sleep(0.002)

    def _wait_s(self) -> float:
        if self._pending:
            return 0.0005
        if self.protocol is None:
            return 0.005
        due = (self._next / (self.rate_hz * self.speed)) - (time.monotonic() - self._t0)
        return min(0.005, max(0.0005, due))

    def _commands(self, data: bytes) -> None:
        self.received += data
        now = time.monotonic()
        for b in data:
            if self._packet is not None:
                if now - self._packet_t > 1.0:
                    self._packet = None
                else:
                    self._packet.append(b)
                    if len(self._packet) == 2 and b != 84:
                        self._packet = None
                        self._command(b)
                    elif len(self._packet) == 68:
                        self._motioncal(bytes(self._packet))
                        self._packet = None
                    continue
            if b == 117:
                self._packet = bytearray([b])
                self._packet_t = now
                continue
            self._command(b)

    def _command(self, b: int) -> None:
        c = bytes([b])
        if c == b"!":
            cur = min(self._sample(), len(self._frames) - 1) if not self.loop else self._sample()
            self._emit(cur, "binary", polled=True)
        elif c in MODE_BYTES:
            new = MODE_BYTES[c]
            if new != self.protocol:
                self.protocol = new
                self._next = self._sample()

    def _motioncal(self, packet: bytes) -> None:
        from .io.protocol import decode_motioncal_packet, format_cal_lines

        cal = decode_motioncal_packet(packet)
        if cal is not None:
            self.motioncal = cal
            self._queue(format_cal_lines(cal), None)

    def _values(self, index: int, protocol: str) -> tuple[int, ...]:
        i = index % len(self._frames)
        row = self._frames9[i] if protocol == "raw" else self._frames[i]
        return tuple(int(v) for v in row)

    def _emit(self, index: int, protocol: str, *, polled: bool) -> None:
        from .io.protocol import encode_binary, encode_framed, encode_raw, encode_text

        values = self._values(index, protocol)
        if protocol == "binary":
            frame = encode_binary(values)
        elif protocol == "framed":
            frame = encode_framed(values, self._seq)
            self._seq = (self._seq + 1) & 0xFF
        elif protocol == "text":
            frame = encode_text(values)
        else:
            frame = encode_raw(values)
        frame, junk, intact = self._damage(frame, protocol, polled)
        if junk:
            self._queue(junk, None)
        self._queue(frame, SentFrame(index, protocol, values, polled, intact))

    def _damage(self, frame: bytes, protocol: str, polled: bool) -> tuple[bytes, bytes, bool]:
        f, rng = self.faults, self._frng
        if self.wrong_baud:
            return bytes(self._brng.integers(0, 256, len(frame), dtype=np.uint8)), b"", False
        intact = not self._damage_next
        self._damage_next = False
        junk = b""
        lines = protocol in ("text", "raw")
        data = bytearray(frame)
        r = rng.random()  # at most one fault per frame
        if r < f.garbage_prob:
            n = int(rng.integers(1, max(1, f.garbage_max) + 1))
            if lines:
                alphabet = np.r_[1:9, 11:13, 14:32, 128:256].astype(np.uint8)
                junk = bytes(rng.choice(alphabet, n))
                if rng.random() < 0.5:
                    junk += b"\n"
                glued = not junk.endswith(b"\n")
            else:
                junk = bytes(rng.integers(0, 256, n, dtype=np.uint8))
                glued = protocol != "framed" or not junk.endswith(b"\x00")
            if glued or polled:
                intact = False
        elif r < f.garbage_prob + f.drop_prob:
            if lines and f.drop_where == "structure":
                where = [i for i, c in enumerate(data) if c in b",\n"]
            else:
                where = list(range(len(data)))
            i = int(rng.choice(where))
            del data[i]
            intact = False
            # a lost delimiter glues the frame to the next one
            self._damage_next = not polled and i == len(frame) - 1
        elif r < f.garbage_prob + f.drop_prob + f.flip_prob:
            i = int(rng.integers(len(data)))
            data[i] ^= 1 << int(rng.integers(8))
            intact = False
            self._damage_next = not polled and i == len(frame) - 1
        return bytes(data), junk, intact

    def _queue(self, data: bytes, entry: SentFrame | None) -> None:
        self._pending.append([data, entry, 0])
        self._pending_bytes += len(data)

    def _flush(self) -> None:
        master = self._master
        while self._pending and master is not None:
            item = self._pending[0]
            data, entry, done = item
            try:
                n = os.write(master, data[done:])
            except BlockingIOError:
                return
            item[2] = done + n
            self._pending_bytes -= n
            if item[2] < len(data):
                return
            self._pending.pop(0)
            if entry is not None:
                self.sent.append(entry)
