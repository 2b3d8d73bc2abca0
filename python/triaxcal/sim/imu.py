"""The simulated IMU: samples its truth along a script into a :class:`Recording`."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from .._checks.options import seed as seed_of
from ..errors import CalibrationError
from .scripts import Script
from .truth import (
    INT16_MAX,
    INT16_MIN,
    Truth,
    _make_sensor,
    rotvec_to_matrix,
    temp_raw_from_c,
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
        self.seed = seed_of(seed)
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
