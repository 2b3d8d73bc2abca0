"""What a fit of a recorded session is asked to do, as typed, validated objects.

:class:`FitRequest` is what travels from every front end to :func:`~triaxcal.calibration.session.
fit_session`: ``triaxcal fit`` and ``report`` parse their options into one, ``triaxcal batch``
and :func:`triaxcal.fleet.batch.batch_fit` build one per run, the live page builds one from its
settings, and Python callers construct it directly. It is checked once, when it is made: every
field's type and range, and the combinations that cannot work together (``yaw_only`` for an
accelerometer, ``radius="wmm"`` without a location ...). Nothing below the command line sees
an :mod:`argparse` namespace.

* :class:`SourceOptions` -- which readings of a table or log to fit (columns, still poses, log
  instance or topics, undoing an autopilot's calibration).
* :class:`FieldOptions` -- the magnetometer's surroundings: where and when it was recorded
  (the World Magnetic Model's field), yaw-only data, alignment with the accelerometer.
* :class:`FitRequest` -- the fit: sensor, model, radius and units, outlier rejection, held
  parameters, bootstrap intervals, and the two above.

Examples
--------
>>> req = FitRequest(sensor="mag", radius="48uT", source=SourceOptions(columns="mx,my,mz"))
>>> req.radius_value, req.radius_unit
(48.0, 'uT')
>>> FitRequest(sensor="accel", field=FieldOptions(yaw_only=True))  # doctest: +ELLIPSIS
Traceback (most recent call last):
    ...
triaxcal.CalibrationError: yaw_only applies to the magnetometer: ...not accel
"""

from __future__ import annotations

import datetime as _dt
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from dataclasses import field as _field
from typing import Any

from .._checks import options
from .._checks.spelling import opt
from ..conventions.names import SENSORS
from ..detect.session import PoseSettings
from ..errors import CalibrationError
from ..fit.ellipsoid import MODELS
from ..methods.bootstrap import MAX_BOOTSTRAP

__all__ = [
    "FIT_METHODS",
    "MAX_BOOTSTRAP",
    "OUTLIER_RULES",
    "REJECTION_RULES",
    "FieldOptions",
    "FitRequest",
    "SourceOptions",
    "parse_radius",
]


#: How a session is fitted: ``"ellipsoid"`` (the readings alone) or ``"attitude"`` (a flight
#: log's compass against the Earth's field turned by the logged attitude,
#: :mod:`triaxcal.calibration.flight`).
FIT_METHODS = ("ellipsoid", "attitude")

#: Most reject-and-refit rounds.
MAX_ROUNDS = 1000

#: How outliers are judged: ``"calibrated"`` lengths (the default, after a first fit) or
#: ``"raw"`` lengths in the first round (exactly Magneto's rule).
REJECTION_RULES = ("calibrated", "raw")

#: Outlier rules: ``"robust"`` (modified z-score of the calibrated lengths above 3.5; keeps clean
#: data), ``"sigma"`` (more than ``sigma`` standard deviations from the mean length, iterated),
#: ``"magneto"`` (exactly Magneto's: one pass of 2 sigma on raw lengths), ``"none"``.
OUTLIER_RULES = ("robust", "sigma", "magneto", "none")

_UNITS_EXACT = ("g", "mg", "m/s^2", "uT", "nT", "mT", "gauss", "mG", "deg/s", "rad/s", "counts")
_UNIT_ALIASES = {"m/s2": "m/s^2", "mps2": "m/s^2", "ut": "uT", "µt": "uT", "dps": "deg/s",
                 "lsb": "counts", "G": "gauss"}


def parse_radius(text: str, sensor: str) -> tuple[float, str]:
    """``"1g"`` -> (1.0, "g"); ``"48uT"`` -> (48.0, "uT"); a bare number gets a unit by size.

    Bare numbers: accelerometer 0.5..2 -> g, 5..15 -> m/s^2, else counts; magnetometer
    10..100 -> uT, else counts; gyroscope -> deg/s.

    >>> (parse_radius("1g", "accel"), parse_radius("9.80665", "accel"),
    ...  parse_radius("16384", "accel"))
    ((1.0, 'g'), (9.80665, 'm/s^2'), (16384.0, 'counts'))
    >>> parse_radius("48uT", "mag")
    (48.0, 'uT')
    """
    if not isinstance(text, str) or len(text) > 64:
        raise CalibrationError(f"{opt('radius')} must be text such as 1g or 48uT, got "
                               f"{str(text)[:64]!r}")
    m = re.fullmatch(r"\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*([^\s\d].*)?\s*", text)
    if not m:
        raise CalibrationError(
            f"{opt('radius')} {text!r}: give a number with an optional unit, e.g. 1g, "
            "9.80665, 48uT, 16384"
        )
    value = float(m.group(1))
    if not (math.isfinite(value) and value > 0):
        raise CalibrationError(f"{opt('radius')} must be a finite number greater than zero, "
                               f"got {text!r}")
    suffix = (m.group(2) or "").strip()
    if suffix:
        unit = (suffix if suffix in _UNITS_EXACT
                else _UNIT_ALIASES.get(suffix) or _UNIT_ALIASES.get(suffix.lower()))
        if unit is None:
            raise CalibrationError(
                f"{opt('radius')} {text!r}: unknown unit {suffix!r}; use one of {_UNITS_EXACT}"
            )
        return value, unit
    if sensor == "accel":
        return value, "g" if 0.5 <= value <= 2 else "m/s^2" if 5 <= value <= 15 else "counts"
    if sensor == "mag":
        return value, "uT" if 10 <= value <= 100 else "counts"
    return value, "deg/s"


def _flag(value: Any, what: str) -> bool:
    if not isinstance(value, bool):
        raise CalibrationError(f"{what} must be True or False, got {value!r}")
    return value


def _whole(value: Any, what: str, lo: int, hi: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
        raise CalibrationError(f"{what} must be a whole number from {lo} to {hi}, got {value!r}")
    return value


def _text(value: Any, what: str, max_len: int = 256) -> str:
    if not isinstance(value, str) or not value.strip() or len(value) > max_len or any(
            ord(c) < 32 or ord(c) == 127 for c in value):
        raise CalibrationError(f"{what} must be plain text of 1 to {max_len} characters, got "
                               f"{str(value)[:64]!r}")
    return value


@dataclass(frozen=True)
class SourceOptions:
    """Which readings of a session table or a log a fit takes.

    Attributes
    ----------
    columns : str, optional
        Three columns of a table by name or zero-based index, ``"ax,ay,az"`` or ``"0,1,2"``
        (``--columns``). Default: the sensor's named columns, or the first three.
    poses : bool
        Reduce a raw time series (a capture session, a log) to still-pose means first
        (``--poses``), a pose ending when any sensor says the board moved.
    detection : PoseSettings
        How still poses are found (the pose-detection options).
    instance : int, optional
        Log: which sensor (``--instance``): PX4 per-sensor topic instance, ArduPilot IMU/MAG
        number.
    topics : tuple of str, optional
        ROS bag: the topics to read (``--topic``).
    undo_autopilot_cal : bool
        Autopilot log: remove the calibration the autopilot applied before fitting
        (``--undo-autopilot-cal``).
    skip_bad_lines : bool
        Table: skip lines that are not a row of numbers, and count them
        (``--skip-bad-lines``).
    """

    columns: str | None = None
    poses: bool = False
    detection: PoseSettings = _field(default_factory=PoseSettings)
    instance: int | None = None
    topics: tuple[str, ...] | None = None
    undo_autopilot_cal: bool = False
    skip_bad_lines: bool = False

    def __post_init__(self) -> None:
        if self.columns is not None:
            cols = self.columns
            if not isinstance(cols, str):
                if isinstance(cols, Sequence) and len(cols) == 3:
                    cols = ",".join(str(c) for c in cols)
                else:
                    raise CalibrationError(f"{opt('columns')} must be three column names or "
                                           f"indices, e.g. ax,ay,az or 0,1,2, got {cols!r}")
            _text(cols, f"{opt('columns')}", 256)
            if len([c for c in cols.split(",") if c.strip()]) != 3:
                raise CalibrationError(f"{opt('columns')} needs three columns (x,y,z), got "
                                       f"{cols[:64]!r}")
            object.__setattr__(self, "columns", cols)
        _flag(self.poses, f"{opt('poses')}")
        if not isinstance(self.detection, PoseSettings):
            raise CalibrationError("detection must be a triaxcal.PoseSettings")
        if self.instance is not None:
            _whole(self.instance, f"{opt('instance')}", 0, 255)
        if self.topics is not None:
            topics = (self.topics,) if isinstance(self.topics, str) else self.topics
            if not isinstance(topics, Sequence) or not topics or len(topics) > 64:
                raise CalibrationError(f"{opt('topics')} must be one to 64 topic names")
            flat = tuple(t.strip() for item in topics
                         for t in _text(item, f"{opt('topics')}").split(",") if t.strip())
            object.__setattr__(self, "topics", flat)
        _flag(self.undo_autopilot_cal, f"{opt('undo_autopilot_cal')}")
        _flag(self.skip_bad_lines, f"{opt('skip_bad_lines')}")

    @property
    def for_logs(self) -> bool:
        """Whether any option that only a log can honour is set."""
        return self.instance is not None or bool(self.topics) or self.undo_autopilot_cal


@dataclass(frozen=True)
class FieldOptions:
    """The magnetometer's surroundings.

    Attributes
    ----------
    location : (lat_deg, lon_deg, alt_m), optional
        Where the data were recorded (WGS 84; ``--location``): the World Magnetic Model's field
        there is recorded, compared with the fit and, with ``radius="wmm"``, used as the
        radius.
    date : datetime.date, optional
        Date of the recording for the World Magnetic Model (``--date``; default today).
    yaw_only : bool
        The magnetometer was turned about the vertical only (``--yaw-only``).
    align : bool
        Also find the magnetometer's rotation into the accelerometer's frame (``--align``).
    """

    location: tuple[float, float, float] | None = None
    date: _dt.date | None = None
    yaw_only: bool = False
    align: bool = False

    def __post_init__(self) -> None:
        if self.location is not None:
            from ..methods.field import _check_place, parse_location

            loc = self.location
            if isinstance(loc, str):
                loc = parse_location(loc)
            if not isinstance(loc, Sequence) or len(loc) not in (2, 3) or any(
                    isinstance(v, bool) or not isinstance(v, (int, float)) for v in loc):
                raise CalibrationError(f"{opt('location')} must be LAT,LON[,ALT_M] in degrees "
                                       "and metres")
            lat, lon, alt = float(loc[0]), float(loc[1]), float(loc[2]) if len(loc) == 3 else 0.0
            _check_place(lat, lon, alt)
            object.__setattr__(self, "location", (lat, lon, alt))
        if self.date is not None:
            d = self.date
            if isinstance(d, str):
                try:
                    d = _dt.date.fromisoformat(d.strip())
                except ValueError:
                    raise CalibrationError(
                        f"{opt('date')} {d[:32]!r}: give the date as YYYY-MM-DD") from None
            if not isinstance(d, _dt.date):
                raise CalibrationError(f"{opt('date')} must be a date (YYYY-MM-DD)")
            object.__setattr__(self, "date", d)
            if self.location is None:
                raise CalibrationError(f"{opt('date')} needs {opt('location', 'LAT,LON[,ALT_M]')}")
        _flag(self.yaw_only, f"{opt('yaw_only')}")
        _flag(self.align, f"{opt('align')}")


@dataclass(frozen=True)
class FitRequest:
    """One sensor of a recorded session to fit, and how (see the module notes).

    Attributes
    ----------
    sensor : {"accel", "gyro", "mag"}
        Which sensor the columns hold (``--sensor``).
    model : {"sphere", "axis", "full", "auto"}
        Fit model (``--model``); ``"auto"`` chooses by BIC.
    radius : str or float, optional
        Magnitude of calibrated readings with its unit (``--radius``): ``"1g"``, ``"9.80665"``,
        ``"48uT"``, ``16384`` (counts), or ``"wmm"`` (the World Magnetic Model's field at
        ``field.location``). Default: 1 g for an accelerometer, the data's own for the others.
    unit : str, optional
        Calibrated unit to record (``--unit``; default: from the radius).
    raw_unit : str, optional
        Unit of the raw readings (``--raw-unit``; default: counts, or a log's own unit).
    outliers : {"robust", "sigma", "magneto", "none"}
        The outlier rule (``--outliers``; see :data:`OUTLIER_RULES` and
        :func:`triaxcal.fit_robust`). The default, ``"robust"``, keeps clean data and drops
        gross errors; ``"magneto"`` reproduces Magneto exactly.
    sigma : float
        The sigma rule's threshold: readings whose length is more than ``sigma`` standard
        deviations from the mean are rejected, iterated (``--sigma``); 0 disables.
    rounds : int
        Most reject-and-refit rounds (``--rounds``); 1 = a single pass, like Magneto.
    reject_on : {"calibrated", "raw"}
        Judge the first round on calibrated or raw lengths (``--reject-on``).
    asa : (int, int, int), optional
        AK8963-family fuse-ROM sensitivity bytes (``--asa``), applied before fitting.
    bootstrap : int
        Bootstrap resamples for 95 % intervals of every coefficient (``--bootstrap``); 0: none.
    fixed : mapping of str to float
        Parameters held at a value instead of fitted (``--fix NAME=VALUE``).
    source : SourceOptions
    field : FieldOptions
    method : {"ellipsoid", "attitude"}
        ``"attitude"`` fits a flight log's compass to the Earth's field turned by the logged
        attitude, with battery-current or throttle interference (``--method``;
        :mod:`triaxcal.calibration.flight`).
    """

    sensor: str = "accel"
    model: str = "auto"
    radius: str | float | None = None
    unit: str | None = None
    raw_unit: str | None = None
    outliers: str = "robust"
    sigma: float = 2.0
    rounds: int = 10
    reject_on: str = "calibrated"
    asa: tuple[int, int, int] | None = None
    bootstrap: int = 0
    fixed: Mapping[str, float] = _field(default_factory=dict)
    source: SourceOptions = _field(default_factory=SourceOptions)
    field: FieldOptions = _field(default_factory=FieldOptions)
    method: str = "ellipsoid"

    def __post_init__(self) -> None:
        if self.sensor not in SENSORS:
            raise CalibrationError(f"{opt('sensor')} must be one of {', '.join(SENSORS)}, got "
                                   f"{str(self.sensor)[:32]!r}")
        if self.model not in (*MODELS, "auto"):
            raise CalibrationError(f"{opt('model')} must be one of "
                                   f"{', '.join((*MODELS, 'auto'))}, got {str(self.model)[:32]!r}")
        if self.radius is not None:
            r = self.radius
            if not isinstance(r, str):
                if isinstance(r, bool) or not isinstance(r, (int, float)):
                    raise CalibrationError(f"{opt('radius')} must be a number or text such as "
                                           f"1g, got {r!r}")
                r = repr(options.magnitude(r, "radius"))
            if r.strip().lower() != "wmm":
                parse_radius(r, self.sensor)  # raises with what to pass
            object.__setattr__(self, "radius", r)
        for name in ("unit", "raw_unit"):
            v = getattr(self, name)
            if v is not None:
                _text(v, opt(name), 32)
        object.__setattr__(self, "sigma", options.number(
            self.sigma, "sigma", ge=0, finite=False, hint="standard deviations; 0: no rejection"))
        _whole(self.rounds, f"{opt('rounds')}", 0, MAX_ROUNDS)
        if self.outliers not in OUTLIER_RULES:
            raise CalibrationError(f"{opt('outliers')} must be one of "
                                   f"{', '.join(OUTLIER_RULES)}, got {str(self.outliers)[:32]!r}")
        if self.reject_on not in REJECTION_RULES:
            raise CalibrationError(f"{opt('reject_on')} must be one of "
                                   f"{', '.join(REJECTION_RULES)}, got {self.reject_on!r}")
        if self.asa is not None:
            a = self.asa
            if not isinstance(a, Sequence) or len(a) != 3 or any(
                    isinstance(v, bool) or not isinstance(v, int) or not 0 <= v <= 255 for v in a):
                raise CalibrationError(f"{opt('asa')} must be the three fuse-ROM bytes 0..255, got "
                                       f"{a!r}")
            object.__setattr__(self, "asa", tuple(int(v) for v in a))
        _whole(self.bootstrap, f"{opt('bootstrap')}", 0, MAX_BOOTSTRAP)
        if not isinstance(self.fixed, Mapping):
            raise CalibrationError(f"{opt('fixed')} must map parameter names to numbers")
        fixed = {}
        for k, v in self.fixed.items():
            _text(k, f"a parameter's name in {opt('fixed')}", 32)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise CalibrationError(f"{opt('fixed')} {k}={v!r}: give a finite number")
            fixed[k] = float(v)
        object.__setattr__(self, "fixed", fixed)
        if not isinstance(self.source, SourceOptions):
            raise CalibrationError("source must be a SourceOptions")
        if not isinstance(self.field, FieldOptions):
            raise CalibrationError("field must be a FieldOptions")
        self._check_combinations()

    def _check_combinations(self) -> None:
        f, mag = self.field, self.sensor == "mag"
        for flag, name in ((f.yaw_only, "yaw_only"), (f.align, "align"),
                           (f.location is not None, "location"), (self.asa is not None, "asa")):
            if flag and not mag:
                raise CalibrationError(f"{opt(name)} applies to the magnetometer: it applies to "
                                       f"{opt('sensor', 'mag')}, not {self.sensor}")
        if self.radius_is_wmm and f.location is None:
            raise CalibrationError(f"{opt('radius', 'wmm')} needs "
                                   f"{opt('location', 'LAT,LON[,ALT_M]')} (and "
                                   f"{opt('date', 'YYYY-MM-DD')} of the recording; default today)")
        if f.yaw_only and self.radius is not None and not self.radius_is_wmm:
            raise CalibrationError(f"{opt('yaw_only')} takes the field from the location "
                                   f"({opt('location')}, the World Magnetic Model): drop "
                                   f"{opt('radius')}")
        if f.yaw_only and self.source.poses:
            raise CalibrationError(f"{opt('yaw_only')} fits the turning readings themselves: "
                                   f"drop {opt('poses')}")
        if f.align and self.source.poses:
            raise CalibrationError(f"{opt('align')} finds the still poses itself: drop "
                                   f"{opt('poses')}")
        if self.method not in FIT_METHODS:
            raise CalibrationError(f"{opt('method')} must be one of {', '.join(FIT_METHODS)}, got "
                                   f"{str(self.method)[:32]!r}")
        if self.method == "attitude":
            if not mag:
                raise CalibrationError(f"{opt('method', 'attitude')} calibrates the compass: it "
                                       f"needs {opt('sensor', 'mag')}, not {self.sensor}")
            for flag, name in ((f.yaw_only, "yaw_only"), (f.align, "align"),
                               (self.source.poses, "poses"), (self.asa is not None, "asa"),
                               (bool(self.bootstrap), "bootstrap"), (bool(self.fixed), "fixed"),
                               (self.radius is not None, "radius")):
                if flag:
                    raise CalibrationError(f"{opt('method', 'attitude')} does not take "
                                           f"{opt(name)}: drop it")
        if self.bootstrap and self.asa is not None:
            raise CalibrationError(f"{opt('bootstrap')} with {opt('asa')} is not supported: the "
                                   "intervals would describe the ASA-adjusted coefficients")

    @property
    def radius_is_wmm(self) -> bool:
        """Whether the radius is the World Magnetic Model's field at the location."""
        return isinstance(self.radius, str) and self.radius.strip().lower() == "wmm"

    @property
    def radius_value(self) -> float | None:
        """The radius as a number (None when not given, or ``"wmm"``)."""
        if self.radius is None or self.radius_is_wmm:
            return None
        return parse_radius(str(self.radius), self.sensor)[0]

    @property
    def radius_unit(self) -> str | None:
        """The radius's unit (None when not given, or ``"wmm"``)."""
        if self.radius is None or self.radius_is_wmm:
            return None
        return parse_radius(str(self.radius), self.sensor)[1]

    def replace(self, **changes: Any) -> FitRequest:
        """A copy with some fields changed (validated again)."""
        return replace(self, **changes)

    def rejection(self) -> dict[str, Any]:
        """The keyword arguments of :func:`triaxcal.fit_robust` that carry the outlier rule."""
        if self.outliers == "magneto":
            return {"rule": "sigma", "sigma": 2.0, "max_rounds": 1, "lengths": "raw"}
        return {"rule": self.outliers, "sigma": self.sigma, "max_rounds": self.rounds,
                "lengths": self.reject_on}
