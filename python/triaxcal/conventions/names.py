"""Names shared by every layer, kept here once: the sensors, the axes, and the parameters of a
calibration part as they appear in Python, JSON, reports and exports."""

from __future__ import annotations

__all__ = ["AXES", "SENSORS"]

#: The parts a calibration can have: accelerometer, gyroscope, magnetometer.
SENSORS = ("accel", "gyro", "mag")

#: Axis names, in order.
AXES = ("x", "y", "z")
