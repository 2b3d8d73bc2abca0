"""The autopilots' calibration parameter names, in one place for the readers and the writers.

:mod:`triaxcal.io.logs.autopilot` reads these parameters from a log to undo what the autopilot
applied; :mod:`triaxcal.export.ardupilot` and :mod:`triaxcal.export.px4` write them. Both take
every name from here, so a name cannot drift between the side that reads it and the side that
writes it.

ArduPilot (``libraries/AP_InertialSensor/AP_InertialSensor.cpp`` and
``libraries/AP_Compass/AP_Compass.cpp`` ``var_info`` tables) numbers its sensors 1, 2, 3 with
the first one unnumbered (``COMPASS_OFS_X``, ``COMPASS_OFS2_X``, ``COMPASS_OFS3_X``;
``INS_GYROFFS_X``, ``INS_GYR2OFFS_X``); the temperature calibration counts from 1
(``INS_TCAL1_ENABLE``). ``COMPASS_MOTCT`` (one for all compasses) says what ``COMPASS_MOTn_*``
multiplies: 0 nothing, 1 the throttle (0..1), 2 the battery current in A
(``AP_Compass_Backend.cpp`` ``correct_field``).

PX4 (``src/lib/sensor_calibration/*.cpp`` ``ParametersUpdate``, ``src/modules/
temperature_compensation``) numbers slots from 0 (``CAL_MAG0_XOFF``) and thermal terms
``TC_<A|G|M><n>_*``; ``CAL_MAG_COMP_TYP`` says what ``CAL_MAGn_<X|Y|Z>COMP`` multiplies:
0 nothing, 1 the throttle, 2 (3) the current of battery 0 (1) in kA
(``src/modules/sensors/vehicle_magnetometer/VehicleMagnetometer.cpp``
``UpdatePowerCompensation``).

>>> ardupilot_names("mag", 1)["offset"], px4_prefix("mag", 0)
('COMPASS_OFS2_', 'CAL_MAG0_')
"""

from __future__ import annotations

from ..errors import CalibrationError

__all__ = [
    "AP_MOTCT",
    "AP_MOTCT_CURRENT",
    "AP_MOTCT_THROTTLE",
    "PX4_COMP_CURRENT",
    "PX4_COMP_THROTTLE",
    "PX4_COMP_TYPE",
    "PX4_SENSOR",
    "PX4_TC",
    "PX4_TC_ENABLE",
    "ardupilot_names",
    "ardupilot_suffix",
    "px4_prefix",
    "px4_tc_prefix",
]

#: ArduPilot: what ``COMPASS_MOTn_*`` multiplies (``COMPASS_MOTCT``): 1 throttle, 2 current.
AP_MOTCT = "COMPASS_MOTCT"
AP_MOTCT_THROTTLE = 1
AP_MOTCT_CURRENT = 2

#: PX4's sensor part of ``CAL_<S>n_*`` and of ``TC_<T>n_*``.
PX4_SENSOR = {"accel": "ACC", "gyro": "GYRO", "mag": "MAG"}
PX4_TC = {"accel": "A", "gyro": "G", "mag": "M"}
#: ``TC_<T>_ENABLE`` of each sensor.
PX4_TC_ENABLE = {s: f"TC_{t}_ENABLE" for s, t in PX4_TC.items()}
#: PX4: what ``CAL_MAGn_<X|Y|Z>COMP`` multiplies; 1 throttle, 2 current of battery 0 (kA).
PX4_COMP_TYPE = "CAL_MAG_COMP_TYP"
PX4_COMP_THROTTLE = 1
PX4_COMP_CURRENT = 2


def ardupilot_suffix(index: int) -> str:
    """ArduPilot's number of sensor ``index`` (0-based) in a name: ``""``, ``"2"``, ``"3"``."""
    if isinstance(index, bool) or not isinstance(index, int) or not 0 <= index <= 2:
        raise CalibrationError(f"ArduPilot numbers three sensors (0..2), got {index!r}")
    return "" if index == 0 else str(index + 1)


def ardupilot_names(sensor: str, index: int) -> dict[str, str]:
    """ArduPilot parameter names (prefixes end in ``_``; append ``X``/``Y``/``Z``) of
    ``sensor`` number ``index`` (0-based, 0..2).

    accel: ``offset``, ``scale``, ``caltemp``, ``tcal`` (prefix), ``coeff`` (``ACC``); gyro:
    ``offset``, ``caltemp``, ``tcal``, ``coeff`` (``GYR``); mag: ``offset``, ``dia``, ``odi``,
    ``scale``, ``mot``, ``orient``, ``motct``.
    """
    n = ardupilot_suffix(index)
    if sensor == "accel":
        return {"offset": f"INS_ACC{n}OFFS_", "scale": f"INS_ACC{n}SCAL_",
                "caltemp": f"INS_ACC{index + 1}_CALTEMP", "tcal": f"INS_TCAL{index + 1}_",
                "coeff": "ACC"}
    if sensor == "gyro":
        return {"offset": "INS_GYROFFS_" if index == 0 else f"INS_GYR{n}OFFS_",
                "caltemp": f"INS_GYR{index + 1}_CALTEMP", "tcal": f"INS_TCAL{index + 1}_",
                "coeff": "GYR"}
    if sensor == "mag":
        return {"offset": f"COMPASS_OFS{n}_", "dia": f"COMPASS_DIA{n}_",
                "odi": f"COMPASS_ODI{n}_", "scale": f"COMPASS_SCALE{n}",
                "mot": f"COMPASS_MOT{n}_", "orient": f"COMPASS_ORIENT{n}", "motct": AP_MOTCT}
    raise CalibrationError(f"unknown sensor {sensor!r}: accel, gyro or mag")


def px4_prefix(sensor: str, index: int) -> str:
    """``CAL_<S><index>_`` (append ``XOFF``, ``XSCALE``, ``ID``...): PX4 slot ``index``."""
    if sensor not in PX4_SENSOR:
        raise CalibrationError(f"unknown sensor {sensor!r}: accel, gyro or mag")
    if isinstance(index, bool) or not isinstance(index, int) or not 0 <= index <= 3:
        raise CalibrationError(f"PX4 has calibration slots 0..3, got {index!r}")
    return f"CAL_{PX4_SENSOR[sensor]}{index}_"


def px4_tc_prefix(sensor: str, index: int) -> str:
    """``TC_<T><index>_`` (append ``ID``, ``TREF``, ``X1_0``...): PX4 thermal terms."""
    if sensor not in PX4_TC:
        raise CalibrationError(f"unknown sensor {sensor!r}: accel, gyro or mag")
    return f"TC_{PX4_TC[sensor]}{index}_"
