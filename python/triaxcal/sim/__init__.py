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

from ..io.protocol import CHANNELS_7, CHANNELS_10
from .device import MODE_BYTES, Faults, SentFrame, SimDevice
from .imu import Recording, SimIMU
from .noise import NoiseTruth, noise_chunks, simulate_noise
from .scripts import Script, globe_script, rotation_script, six_face_script, tumble_script
from .truth import (
    ACCEL_COUNTS_PER_G,
    GYRO_COUNTS_PER_DPS,
    GYRO_COUNTS_PER_RAD_S,
    MAG_COUNTS_PER_UT,
    SIM_COUNTS_PER_UNIT,
    SensorTruth,
    Truth,
    matrix_to_rotvec,
    rotvec_to_matrix,
    temp_c_from_raw,
    temp_raw_from_c,
)
from .wearable import FreeLivingSim, WearableTruth

__all__ = [
    "ACCEL_COUNTS_PER_G",
    "CHANNELS_7",
    "CHANNELS_10",
    "GYRO_COUNTS_PER_DPS",
    "GYRO_COUNTS_PER_RAD_S",
    "MODE_BYTES",
    "MAG_COUNTS_PER_UT",
    "SIM_COUNTS_PER_UNIT",
    "NoiseTruth",
    "Faults",
    "FreeLivingSim",
    "WearableTruth",
    "Recording",
    "Script",
    "SensorTruth",
    "SentFrame",
    "SimDevice",
    "SimIMU",
    "Truth",
    "globe_script",
    "matrix_to_rotvec",
    "noise_chunks",
    "rotation_script",
    "rotvec_to_matrix",
    "simulate_noise",
    "six_face_script",
    "temp_c_from_raw",
    "temp_raw_from_c",
    "tumble_script",
]
