"""The scale of common MEMS parts: counts per unit at each full-scale setting, from the datasheets.

A calibration fitted on raw counts knows nothing of the driver that will apply it. A consumer
that works in physical units (ArduPilot, PX4, Kalibr, Adafruit_Sensor_Calibration, MotionCal)
needs the driver's scale, and triaxcal never assumes one: the user gives it
(``--counts-per-unit SENSOR=COUNTS[:UNIT]``) or names the part (``--sensor-model ICM-20948``),
and this table supplies the datasheet's sensitivity.

Each :class:`Setting` keeps the datasheet's own number in the datasheet's own form (LSB per
unit, or unit per LSB), the document and table it comes from, and the full scale it belongs
to. The sensitivities are the datasheets' *typical* values: a part's own gain differs by up to
a few per cent (the datasheets' sensitivity tolerance), which is exactly what the calibration's
matrix then corrects.

>>> s = model_scale("ICM-20948", "mag")
>>> round(s.counts_per_unit, 4), s.unit, s.setting
(6.6667, 'uT', '16bit')
>>> model_scale("MPU-6050:4g", "accel").counts_per_unit
8192.0
>>> try:
...     model_scale("mpu6050", "accel")
... except CalibrationError as exc:
...     print(str(exc)[:67])
the MPU-6050 accel has 4 full-scale settings (2g, 4g, 8g, 16g): nam
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field

from ..errors import CalibrationError
from .units import UNITS

__all__ = ["SENSOR_MODELS", "Scale", "SensorModel", "Setting", "find_model", "known_models",
           "model_scale"]


@dataclass(frozen=True)
class Setting:
    """One full-scale setting of one sensor of a part.

    ``value`` is the datasheet's number as printed: ``per == "count"`` means ``value`` counts
    (LSB) per ``unit`` (e.g. 16384 LSB/g); ``per == "unit"`` means ``value`` ``unit`` per count
    (e.g. 0.061 mg/LSB).
    """

    name: str
    value: float
    unit: str
    per: str
    full_scale: str
    source: str

    @property
    def counts_per_unit(self) -> float:
        """Counts per :attr:`unit` (what ``--counts-per-unit`` takes)."""
        return self.value if self.per == "count" else 1.0 / self.value


@dataclass(frozen=True)
class SensorModel:
    """A part and the settings of each of its sensors (``accel``, ``gyro``, ``mag``)."""

    name: str
    sensors: Mapping[str, tuple[Setting, ...]]
    aliases: tuple[str, ...] = ()
    note: str = ""


@dataclass(frozen=True)
class Scale:
    """A driver's scale for one sensor: ``counts_per_unit`` counts per ``unit``, and where it
    came from (``source``: the datasheet citation, or the command line)."""

    counts_per_unit: float
    unit: str
    source: str
    setting: str = ""
    extra: Mapping[str, str] = field(default_factory=dict)


def _lsb(pairs: Iterable[tuple[str, float]], unit: str, fs_unit: str, source: str,
         per: str = "count") -> tuple[Setting, ...]:
    out = []
    for fs, v in pairs:
        name = f"{fs}{fs_unit}".replace(" ", "")
        out.append(Setting(name=name, value=float(v), unit=unit, per=per,
                           full_scale=f"+-{fs} {fs_unit}", source=source))
    return tuple(out)


_ACC4 = (("2", 16384), ("4", 8192), ("8", 4096), ("16", 2048))
_GYR4 = (("250", 131), ("500", 65.5), ("1000", 32.8), ("2000", 16.4))
_GYR_BOSCH = (("125", 262.4), ("250", 131.2), ("500", 65.6), ("1000", 32.8), ("2000", 16.4))

_MPU6050 = "InvenSense PS-MPU-6000A-00 rev 3.4, section 6.{n} ({what} specifications table)"
_MPU9250 = "InvenSense PS-MPU-9250A-01 rev 1.1, Table {n} ({what} specifications)"
_ICM20948 = "TDK InvenSense DS-000189 rev 1.3, Table {n} ({what} specifications)"
_LSM9DS1 = "ST DocID025715 rev 3 (LSM9DS1), Table 3 (sensor characteristics, {what})"
_LSM6DSO = "ST DS12140 (LSM6DSO), Table 2 (mechanical characteristics, {what})"
_BMI160 = "Bosch BST-BMI160-DS000 (BMI160), Table 1 (electrical parameter specification, {what})"
_BMI270 = "Bosch BST-BMI270-DS000 (BMI270), Table 2 (electrical parameter specification, {what})"

SENSOR_MODELS: tuple[SensorModel, ...] = (
    SensorModel("MPU-6050", {
        "accel": _lsb(_ACC4, "g", "g", _MPU6050.format(n=2, what="accelerometer")),
        "gyro": _lsb(_GYR4, "deg/s", "dps", _MPU6050.format(n=1, what="gyroscope")),
    }, aliases=("MPU-6000",)),
    SensorModel("MPU-9250", {
        "accel": _lsb(_ACC4, "g", "g", _MPU9250.format(n=2, what="accelerometer")),
        "gyro": _lsb(_GYR4, "deg/s", "dps", _MPU9250.format(n=1, what="gyroscope")),
        "mag": (
            Setting("16bit", 0.15, "uT", "unit", "+-4800 uT, 16-bit output (BIT = 1)",
                    _MPU9250.format(n=3, what="magnetometer, AK8963")),
            Setting("14bit", 0.6, "uT", "unit", "+-4800 uT, 14-bit output (BIT = 0)",
                    _MPU9250.format(n=3, what="magnetometer, AK8963")),
        ),
    }, aliases=("MPU-9255",), note="its magnetometer is the AK8963"),
    SensorModel("AK8963", {
        "mag": (
            Setting("16bit", 0.15, "uT", "unit", "+-4800 uT, 16-bit output (BIT = 1)",
                    _MPU9250.format(n=3, what="magnetometer, AK8963")),
            Setting("14bit", 0.6, "uT", "unit", "+-4800 uT, 14-bit output (BIT = 0)",
                    _MPU9250.format(n=3, what="magnetometer, AK8963")),
        ),
    }),
    SensorModel("ICM-20948", {
        "accel": _lsb(_ACC4, "g", "g", _ICM20948.format(n=2, what="accelerometer")),
        "gyro": _lsb(_GYR4, "deg/s", "dps", _ICM20948.format(n=1, what="gyroscope")),
        "mag": (Setting("16bit", 0.15, "uT", "unit", "+-4900 uT",
                        _ICM20948.format(n=3, what="magnetometer, AK09916")),),
    }, note="its magnetometer is the AK09916"),
    SensorModel("AK09916", {
        "mag": (Setting("16bit", 0.15, "uT", "unit", "+-4900 uT",
                        _ICM20948.format(n=3, what="magnetometer, AK09916")),),
    }),
    SensorModel("LSM9DS1", {
        "accel": _lsb((("2", 0.061), ("4", 0.122), ("8", 0.244), ("16", 0.732)), "mg", "g",
                      _LSM9DS1.format(what="LA_So"), per="unit"),
        "gyro": (
            *_lsb((("245", 8.75e-3), ("500", 17.50e-3), ("2000", 70e-3)), "deg/s", "dps",
                  _LSM9DS1.format(what="G_So, mdps/LSB"), per="unit"),
        ),
        "mag": _lsb((("4", 0.14e-3), ("8", 0.29e-3), ("12", 0.43e-3), ("16", 0.58e-3)),
                    "gauss", "gauss", _LSM9DS1.format(what="M_GN, mgauss/LSB"), per="unit"),
    }),
    SensorModel("LSM6DSx", {
        "accel": _lsb((("2", 0.061), ("4", 0.122), ("8", 0.244), ("16", 0.488)), "mg", "g",
                      _LSM6DSO.format(what="LA_So"), per="unit"),
        "gyro": _lsb((("125", 4.375e-3), ("250", 8.75e-3), ("500", 17.50e-3),
                      ("1000", 35e-3), ("2000", 70e-3)), "deg/s", "dps",
                     _LSM6DSO.format(what="G_So, mdps/LSB"), per="unit"),
    }, aliases=("LSM6DSO", "LSM6DSOX", "LSM6DSL", "LSM6DSM", "LSM6DS3", "LSM6DS3TR-C",
                "LSM6DS33"),
        note="the LSM6DS3/DSL/DSM/DSO/DSOX datasheets give the same sensitivities"),
    SensorModel("BMI160", {
        "accel": _lsb(_ACC4, "g", "g", _BMI160.format(what="accelerometer sensitivity")),
        "gyro": _lsb(_GYR_BOSCH, "deg/s", "dps", _BMI160.format(what="gyroscope sensitivity")),
    }),
    SensorModel("BMI270", {
        "accel": _lsb(_ACC4, "g", "g", _BMI270.format(what="accelerometer sensitivity")),
        "gyro": _lsb(_GYR_BOSCH, "deg/s", "dps", _BMI270.format(what="gyroscope sensitivity")),
    }),
    SensorModel("BMM150", {
        "mag": (Setting("raw", 0.3, "uT", "unit", "+-1300 uT (x, y), +-2500 uT (z)",
                        "Bosch BST-BMM150-DS001 (BMM150), Table 2 (magnetic field resolution)"),),
    }, note="the raw registers; Bosch's temperature compensation changes the output's form"),
    SensorModel("HMC5883L", {
        "mag": _lsb((("0.88", 1370), ("1.3", 1090), ("1.9", 820), ("2.5", 660), ("4.0", 440),
                     ("4.7", 390), ("5.6", 330), ("8.1", 230)), "gauss", "gauss",
                    "Honeywell HMC5883L datasheet, Form #900405 rev E, Table 9 (gain settings, "
                    "LSb/gauss)"),
    }),
    SensorModel("QMC5883L", {
        "mag": _lsb((("2", 12000), ("8", 3000)), "gauss", "gauss",
                    "QST QMC5883L datasheet rev C, Table 2 (specifications: sensitivity)"),
    }),
    SensorModel("LIS3MDL", {
        "mag": _lsb((("4", 6842), ("8", 3421), ("12", 2281), ("16", 1711)), "gauss", "gauss",
                    "ST DocID024204 rev 5 (LIS3MDL), Table 3 (sensor characteristics, GN)"),
    }),
    SensorModel("MMC5983MA", {
        "mag": (
            Setting("18bit", 16384, "gauss", "count", "+-8 gauss, 18-bit output",
                    "MEMSIC MMC5983MA rev A datasheet, electrical characteristics table "
                    "(sensitivity)"),
            Setting("16bit", 4096, "gauss", "count", "+-8 gauss, 16-bit output",
                    "MEMSIC MMC5983MA rev A datasheet, electrical characteristics table "
                    "(sensitivity)"),
        ),
    }, note="its output is unsigned (null field at 131072 / 32768 counts): the fitted offset "
            "holds that"),
    SensorModel("IST8310", {
        "mag": (Setting("raw", 0.3, "uT", "unit", "+-1600 uT (x, y), +-2500 uT (z)",
                        "iSentek IST8310 datasheet, specifications table (sensitivity "
                        "0.3 uT/LSB)"),),
    }),
)


def _key(name: str) -> str:
    return re.sub(r"[\s_\-]", "", str(name)).upper()


_BY_KEY: dict[str, SensorModel] = {}
for _m in SENSOR_MODELS:
    for _n in (_m.name, *_m.aliases):
        _BY_KEY[_key(_n)] = _m


def known_models() -> str:
    """The known part names, for messages."""
    return ", ".join(m.name + (f" ({', '.join(m.aliases)})" if m.aliases else "")
                     for m in SENSOR_MODELS)


def find_model(name: str) -> SensorModel:
    """The :class:`SensorModel` called ``name`` (case, ``-``, ``_`` and spaces ignored)."""
    if not isinstance(name, str) or not name.strip():
        raise CalibrationError(f"a sensor model is a part name such as ICM-20948, got {name!r}")
    m = _BY_KEY.get(_key(name))
    if m is None:
        raise CalibrationError(f"unknown sensor model {name[:40]!r}: known ones are "
                               f"{known_models()}; for another part give its scale with "
                               "--counts-per-unit SENSOR=COUNTS:UNIT (counts_per_unit=)")
    return m


def _parse(spec: str) -> tuple[str | None, str, tuple[str, ...]]:
    """``[SENSOR=]MODEL[:SETTING[,SETTING...]]`` -> (sensor, model, settings)."""
    if not isinstance(spec, str):
        raise CalibrationError(f"a sensor model is text such as 'ICM-20948', got {spec!r}")
    sensor = None
    text = spec.strip()
    if "=" in text:
        sensor, text = (s.strip() for s in text.split("=", 1))
        if sensor not in ("accel", "gyro", "mag"):
            raise CalibrationError(f"sensor model {spec[:60]!r}: the sensor before '=' must be "
                                   "accel, gyro or mag")
    model, _, settings = text.partition(":")
    return sensor, model.strip(), tuple(s.strip() for s in settings.split(",") if s.strip())


def model_scale(spec: str, sensor: str) -> Scale:
    """The scale of ``sensor`` from a sensor-model spec ``[SENSOR=]MODEL[:SETTING,...]``.

    ``SETTING`` names a full-scale setting as the table does (``2g``, ``500dps``, ``1.3gauss``,
    ``16bit``); it is needed only when the sensor has more than one. A model without that
    sensor, an unknown setting, or a missing one is refused with the choices.
    """
    want, name, settings = _parse(spec)
    m = find_model(name)
    if want is not None and want != sensor:
        raise CalibrationError(f"sensor model {spec!r} is for the {want}, not the {sensor}")
    if sensor not in m.sensors:
        raise CalibrationError(f"the {m.name} has no {sensor} (it has: "
                               f"{', '.join(m.sensors)}): name the {sensor}'s part too, e.g. "
                               f"{sensor}=<PART>")
    choices = m.sensors[sensor]
    names = {_key(s.name): s for s in choices}
    mine = [names[_key(s)] for s in settings if _key(s) in names]
    unknown = [s for s in settings if _key(s) not in names and not _other_sensor(m, sensor, s)]
    if unknown:
        raise CalibrationError(f"the {m.name} {sensor} has no setting {unknown[0]!r}: its "
                               f"settings are {', '.join(s.name for s in choices)}")
    if len(mine) > 1:
        raise CalibrationError(f"sensor model {spec!r} names two {sensor} settings")
    if mine:
        s = mine[0]
    elif len(choices) == 1:
        s = choices[0]
    else:
        raise CalibrationError(
            f"the {m.name} {sensor} has {len(choices)} full-scale settings "
            f"({', '.join(c.name for c in choices)}): name the one its driver sets, e.g. "
            f"{m.name}:{choices[0].name}")
    if s.unit not in UNITS:  # pragma: no cover - the table uses known units only
        raise CalibrationError(f"internal: unit {s.unit!r} of {m.name}")
    shown = f"{s.value:g} LSB/{s.unit}" if s.per == "count" else f"{s.value:g} {s.unit}/LSB"
    return Scale(counts_per_unit=s.counts_per_unit, unit=s.unit, setting=s.name,
                 source=f"{m.name} {sensor} at {s.full_scale}: {shown} ({s.source})")


def _other_sensor(m: SensorModel, sensor: str, setting: str) -> bool:
    """Whether ``setting`` names a setting of another sensor of ``m`` (``MPU-6050:2g,250dps``
    names both the accelerometer's and the gyroscope's)."""
    return any(_key(setting) == _key(s.name) for other, ss in m.sensors.items()
               if other != sensor for s in ss)
