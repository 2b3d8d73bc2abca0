"""Names shared by every layer, kept here once: the sensors, the axes, and the parameters of a
calibration part as they appear in Python, JSON, reports, standard errors and exports (the
names ArduPilot's calibrators use: ``offset``, ``diag``, ``offdiag``, ``radius``)."""

from __future__ import annotations

__all__ = ["AXES", "COEFFICIENTS", "CELL", "LOWER", "PARAM_NAMES", "SENSORS", "UPPER"]

#: The parts a calibration can have: accelerometer, gyroscope, magnetometer.
SENSORS = ("accel", "gyro", "mag")

#: Axis names, in order.
AXES = ("x", "y", "z")

#: The off-diagonal cells of the matrix: the upper triangle ``[xy, xz, yz]`` (``offdiag``) and
#: the lower ``[yx, zx, zy]`` (``offdiag_lower``, for a matrix that is not symmetric).
UPPER = ((0, 1), (0, 2), (1, 2))
LOWER = ((1, 0), (2, 0), (2, 1))

#: The nine coefficients of a part, by name.
COEFFICIENTS = ("offset_x", "offset_y", "offset_z", "diag_x", "diag_y", "diag_z",
                "offdiag_xy", "offdiag_xz", "offdiag_yz")

#: The matrix cell of each gain coefficient.
CELL = {"diag_x": (0, 0), "diag_y": (1, 1), "diag_z": (2, 2), "offdiag_xy": (0, 1),
        "offdiag_xz": (0, 2), "offdiag_yz": (1, 2)}

#: The parameters each fit model determines, in the order of its standard errors
#: (``EllipsoidFit.stderr``); the sphere's one scale is its radius in raw units.
PARAM_NAMES = {
    "sphere": ("offset_x", "offset_y", "offset_z", "data_radius"),
    "axis": COEFFICIENTS[:6],
    "full": COEFFICIENTS,
}
