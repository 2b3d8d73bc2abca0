"""The true calibration of a simulated IMU: offsets, matrices, noise, temperature drift;
frames and rotations."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import CalibrationError

#: Nominal scales of the simulated device (MPU-6050 style at +-2 g, +-250 deg/s).
ACCEL_COUNTS_PER_G = 16384.0
GYRO_COUNTS_PER_DPS = 131.0
GYRO_COUNTS_PER_RAD_S = GYRO_COUNTS_PER_DPS * 180.0 / math.pi
MAG_COUNTS_PER_UT = 10.0
INT16_MIN, INT16_MAX = -32768, 32767

#: The simulated device's scale per sensor, in the form the exports take it
#: (``export(..., counts_per_unit=SIM_COUNTS_PER_UNIT)``): the simulator's own, which no
#: export assumes for any other device.
SIM_COUNTS_PER_UNIT: dict[str, tuple[float, str]] = {
    "accel": (ACCEL_COUNTS_PER_G, "g"),
    "gyro": (GYRO_COUNTS_PER_DPS, "deg/s"),
    "mag": (MAG_COUNTS_PER_UT, "uT"),
}


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
