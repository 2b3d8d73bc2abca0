"""The Earth's magnetic field expected at a place and date, from the World Magnetic Model.

A magnetometer calibrated in a clean environment should read, in every orientation, a field of
the strength the World Magnetic Model (WMM2025, NOAA NCEI and BGS) gives for the place, dipping
below the horizon by the model's inclination. :func:`expected_field` returns those numbers:

* ``total_ut`` F, ``horizontal_ut`` H, ``north_ut`` X, ``east_ut`` Y, ``down_ut`` Z (uT);
* ``inclination_deg`` I (dip, positive when the field points down, as in the northern
  hemisphere) and ``declination_deg`` D (positive when magnetic north lies east of true north);
* the WMM2025 error model's one-sigma uncertainties (F 138 nT, H 133 nT, I 0.20 deg,
  ``D = sqrt(0.26^2 + (5417 / H[nT])^2)`` deg; WMM2025 Technical Report, error model table);
* warnings where the model says compasses fail: horizontal field below 6000 nT (the WMM's
  "caution zone") or 2000 nT ("blackout zone").

The model is evaluated by NOAA's own ``wmm-calculator`` package (Python >= 3.11) or, where that
cannot be installed, by ``pygeomag`` (a port of NOAA's C code); both reproduce the WMM2025
report's test values to their last printed digit (``tests/test_field.py``). They are the
optional ``geo`` extra: ``pip install 'triaxcal[geo]'``; without either, :func:`expected_field`
raises :class:`~triaxcal.CalibrationError` naming the extra.

Heights are above the WGS 84 ellipsoid (what GNSS receivers report as ellipsoidal height); the
difference to height above sea level, at most about 110 m, changes the field by less than 3 nT.
"""

from __future__ import annotations

import calendar
import datetime as _dt
import math
import numbers
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from .._checks import fields as _schema
from ..errors import CalibrationError
from ..quality.bounds import STRENGTH_TOLERANCE

__all__ = [
    "STRENGTH_TOLERANCE",
    "MODEL",
    "VALID_FROM",
    "VALID_UNTIL",
    "ExpectedField",
    "decimal_year",
    "expected_field",
    "parse_location",
    "strength_check",
]

#: The fitted field strength may differ from the model's by this share before it is warned about.

#: The geomagnetic model evaluated.
MODEL = "WMM2025"
#: First and last date the model may be evaluated for (NOAA's release date; end of its life).
VALID_FROM = _dt.date(2024, 11, 13)
VALID_UNTIL = _dt.date(2029, 12, 31)
#: WMM2025 error model (one sigma): F and H in nT, I in degrees; D = hypot(D_OFFSET, D_COEF/H).
_ERR_F_NT, _ERR_H_NT, _ERR_I_DEG, _ERR_D_OFFSET_DEG, _ERR_D_COEF = 138.0, 133.0, 0.20, 0.26, 5417.0
#: Horizontal field below which the WMM declares compasses unreliable / useless (nT).
CAUTION_NT, BLACKOUT_NT = 6000.0, 2000.0

_FIELDS = ("model", "backend", "date", "decimal_year", "lat_deg", "lon_deg", "alt_m",
           "total_ut", "horizontal_ut", "north_ut", "east_ut", "down_ut", "inclination_deg",
           "declination_deg", "uncertainty", "warnings")
_UNC = ("total_ut", "horizontal_ut", "inclination_deg", "declination_deg")


def _num(value: Any, what: str, lo: float | None = None, hi: float | None = None) -> float:
    if isinstance(value, (bool, str, bytes)) or not isinstance(value, numbers.Real):
        raise CalibrationError(f"{what} must be a number, got {value!r}")
    try:
        v = float(value)
    except OverflowError:  # an int past a double
        v = math.inf
    if not math.isfinite(v):
        raise CalibrationError(f"{what} must be finite, got {v}")
    if (lo is not None and v < lo) or (hi is not None and v > hi):
        raise CalibrationError(f"{what} must lie within {lo:g}..{hi:g}, got {v:g}")
    return v


def _as_date(date: Any) -> _dt.date:
    if date is None:
        return _dt.datetime.now(_dt.timezone.utc).date()
    if isinstance(date, _dt.datetime):
        return date.date()
    if isinstance(date, _dt.date):
        return date
    if isinstance(date, str):
        try:
            return _dt.date.fromisoformat(date.strip())
        except ValueError:
            raise CalibrationError(f"date {date!r} is not a date: write YYYY-MM-DD, e.g. "
                                   "2026-05-17") from None
    raise CalibrationError(f"date must be YYYY-MM-DD text or a datetime.date, got {date!r}")


def decimal_year(date: Any) -> float:
    """The WMM's decimal year of a date: ``year + (day_of_year - 1) / days_in_year``.

    >>> decimal_year("2026-07-02")  # day 183 of 365
    2026.4986301369863
    """
    d = _as_date(date)
    days = 366 if calendar.isleap(d.year) else 365
    return d.year + (d.timetuple().tm_yday - 1) / days


@dataclass(frozen=True)
class ExpectedField:
    """The field the WMM expects at a place and date (see the module docstring for units).

    Attributes
    ----------
    model, backend : str
        ``"WMM2025"``; the package that evaluated it (``"wmm-calculator 1.4.4"``).
    date : str
        ISO date (``YYYY-MM-DD``); ``decimal_year`` the same as the WMM counts it.
    lat_deg, lon_deg, alt_m : float
        Geodetic latitude and longitude (deg, east positive), height above the WGS 84
        ellipsoid (m).
    total_ut, horizontal_ut, north_ut, east_ut, down_ut : float
        F, H, X, Y, Z in uT.
    inclination_deg, declination_deg : float
        I (dip, positive down) and D (positive east) in degrees.
    uncertainty : dict
        One-sigma uncertainties from the WMM2025 error model, keyed ``total_ut``,
        ``horizontal_ut`` (uT), ``inclination_deg``, ``declination_deg`` (deg).
    warnings : tuple of str
        Caution / blackout zone warnings (a weak horizontal field: compass headings unreliable).
    """

    model: str
    backend: str
    date: str
    decimal_year: float
    lat_deg: float
    lon_deg: float
    alt_m: float
    total_ut: float
    horizontal_ut: float
    north_ut: float
    east_ut: float
    down_ut: float
    inclination_deg: float
    declination_deg: float
    uncertainty: dict[str, float] = field(default_factory=dict)
    warnings: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        for name in ("model", "backend", "date"):
            _schema.text(64, nonblank=True)(getattr(self, name), f"field.{name}")
        _as_date(self.date)
        object.__setattr__(self, "lat_deg", _num(self.lat_deg, "field.lat_deg", -90, 90))
        object.__setattr__(self, "lon_deg", _num(self.lon_deg, "field.lon_deg", -180, 360))
        for name in ("decimal_year", "alt_m", "north_ut", "east_ut", "down_ut",
                     "declination_deg"):
            object.__setattr__(self, name, _num(getattr(self, name), f"field.{name}"))
        object.__setattr__(self, "total_ut", _num(self.total_ut, "field.total_ut", 1e-6, 1e4))
        object.__setattr__(self, "horizontal_ut",
                           _num(self.horizontal_ut, "field.horizontal_ut", 0, 1e4))
        object.__setattr__(self, "inclination_deg",
                           _num(self.inclination_deg, "field.inclination_deg", -90, 90))
        comp = math.sqrt(self.north_ut**2 + self.east_ut**2 + self.down_ut**2)
        if abs(comp - self.total_ut) > 1e-3 * self.total_ut + 1e-3:
            raise CalibrationError(
                f"field: |(north, east, down)| = {comp:.6g} uT differs from total_ut "
                f"{self.total_ut:.6g} uT: the file was edited inconsistently")
        if not isinstance(self.uncertainty, Mapping):
            raise CalibrationError("field.uncertainty must be a JSON object")
        unc = {}
        for k, v in self.uncertainty.items():
            if k not in _UNC:
                raise CalibrationError(f"field.uncertainty has unknown key {k!r}; use {_UNC}")
            unc[k] = _num(v, f"field.uncertainty.{k}", 0, 1e4)
        object.__setattr__(self, "uncertainty", unc)
        if isinstance(self.warnings, str) or not isinstance(self.warnings, (list, tuple)):
            raise CalibrationError("field.warnings must be a list of strings")
        warn = _schema.list_of(_schema.text(_schema.MAX_TEXT, plain=False), max_items=32)
        object.__setattr__(self, "warnings", tuple(warn(list(self.warnings), "field.warnings")))

    def vector_ned_ut(self) -> tuple[float, float, float]:
        """``(north, east, down)`` in uT."""
        return (self.north_ut, self.east_ut, self.down_ut)

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON values (the ``field`` object of a calibration part)."""
        d = {k: getattr(self, k) for k in _FIELDS}
        d["uncertainty"] = dict(self.uncertainty)
        d["warnings"] = list(self.warnings)
        return d

    @classmethod
    def from_dict(cls, d: Any) -> ExpectedField:
        """Inverse of :meth:`to_dict`; raises :class:`CalibrationError` when malformed."""
        if not isinstance(d, Mapping):
            raise CalibrationError("field must be a JSON object")
        missing = set(_FIELDS) - {"uncertainty", "warnings"} - set(d)
        if missing:
            raise CalibrationError(f"field lacks {sorted(missing)}: the file is incomplete")
        unknown = set(d) - set(_FIELDS)
        if unknown:
            raise CalibrationError(f"field has unknown key(s) {sorted(unknown)}")
        kw = {k: d[k] for k in _FIELDS if k in d}
        w = kw.get("warnings") or []
        if not isinstance(w, list) or not all(isinstance(x, str) for x in w):
            raise CalibrationError("field.warnings must be a list of strings")
        kw["warnings"] = tuple(w)
        return cls(**kw)

    def text(self) -> str:
        """One line for the console: F, H, I, D with units and where and when."""
        return (f"{self.model} at {self.lat_deg:.4f}, {self.lon_deg:.4f}, {self.alt_m:.0f} m on "
                f"{self.date}: total {self.total_ut:.2f} uT, horizontal "
                f"{self.horizontal_ut:.2f} uT, inclination {self.inclination_deg:.2f} deg, "
                f"declination {self.declination_deg:.2f} deg")


def parse_location(text: str) -> tuple[float, float, float]:
    """``"LAT,LON[,ALT_M]"`` -> ``(lat_deg, lon_deg, alt_m)``; altitude defaults to 0 m.

    >>> parse_location("47.37, 8.54, 408")
    (47.37, 8.54, 408.0)
    """
    if not isinstance(text, str):
        raise CalibrationError(f"--location must be text LAT,LON[,ALT_M], got {text!r}")
    parts = [p.strip() for p in text.split(",")]
    if len(parts) not in (2, 3) or not all(parts):
        raise CalibrationError(
            f"--location {text!r}: give LAT,LON or LAT,LON,ALT_M in degrees and metres, e.g. "
            "47.37,8.54,408 (north and east positive)")
    vals = []
    for p, what in zip(parts, ("latitude", "longitude", "altitude")):
        try:
            vals.append(float(p))
        except ValueError:
            raise CalibrationError(f"--location {text!r}: the {what} {p!r} is not a number"
                                   ) from None
    lat, lon = vals[0], vals[1]
    alt = vals[2] if len(vals) == 3 else 0.0
    _check_place(lat, lon, alt)
    return lat, lon, alt


def _check_place(lat: float, lon: float, alt_m: float) -> None:
    _num(lat, "latitude (deg)", -90, 90)
    _num(lon, "longitude (deg)", -180, 360)
    # the WMM is specified from 1 km below the ellipsoid to 850 km above it
    _num(alt_m, "altitude (m above the WGS 84 ellipsoid)", -1000, 850000)


def _backend() -> tuple[str, Any]:
    try:
        import wmm  # NOAA NCEI's wmm-calculator

        return f"wmm-calculator {getattr(wmm, '__version__', '?')}", wmm
    except ImportError:
        pass
    try:
        import pygeomag

        return f"pygeomag {getattr(pygeomag, '__version__', '?')}", pygeomag
    except ImportError:
        pass
    raise CalibrationError(
        "the expected field needs the World Magnetic Model: pip install 'triaxcal[geo]' "
        "(NOAA's wmm-calculator, or pygeomag on Python < 3.11)")


def _evaluate(name: str, mod: Any, dyear: float, lat: float, lon: float, alt_km: float
              ) -> tuple[float, float, float]:
    """(X, Y, Z) north, east, down in nT."""
    import warnings

    if name.startswith("wmm-calculator"):
        model = mod.wmm_calc()
        with warnings.catch_warnings():
            # it warns (with terminal colour codes) outside the altitudes of its MilSpec
            warnings.simplefilter("ignore", UserWarning)
            model.setup_time(dyear=dyear)
            model.setup_env(lat, lon, alt_km, unit="km", msl=False)
            x, y, z = model.forward_base()
        return float(x[0]), float(y[0]), float(z[0])
    gm = mod.GeoMag(coefficients_file="wmm/WMM_2025.COF")
    r = gm.calculate(glat=lat, glon=lon if lon <= 180 else lon - 360, alt=alt_km, time=dyear,
                     allow_date_outside_lifespan=True, raise_in_warning_zone=False)
    return float(r.x), float(r.y), float(r.z)


def expected_field(lat: float, lon: float, alt_m: float = 0.0, date: Any = None
                   ) -> ExpectedField:
    """The WMM2025 field at a place and date: total, horizontal, inclination, declination.

    Parameters
    ----------
    lat, lon : float
        Geodetic latitude (-90..90) and longitude (-180..360; east positive), degrees.
    alt_m : float
        Height above the WGS 84 ellipsoid in metres (-1000..850000).
    date : str, datetime.date, float or None
        ``YYYY-MM-DD``, or a decimal year (``2027.5``); ``None`` is today (UTC). The model
        holds from 2024-11-13 to 2029-12-31; other dates raise (the field drifts by about
        0.1 % a year).

    Returns
    -------
    ExpectedField

    Raises
    ------
    CalibrationError
        Place or date out of range, or neither ``wmm-calculator`` nor ``pygeomag`` installed
        (``pip install 'triaxcal[geo]'``).

    Examples
    --------
    >>> import triaxcal as tc
    >>> f = tc.expected_field(80.0, 0.0, 0.0, date="2025-01-01")  # doctest: +SKIP
    >>> round(f.total_ut, 2), round(f.inclination_deg, 2)          # doctest: +SKIP
    (55.18, 83.21)
    """
    lat_f = _num(lat, "latitude (deg)")
    lon_f = _num(lon, "longitude (deg)")
    alt_f = _num(alt_m, "altitude (m)")
    _check_place(lat_f, lon_f, alt_f)
    if isinstance(date, (int, float)) and not isinstance(date, bool):
        dyear = _num(date, "date (decimal year)")
        year = int(math.floor(dyear))
        if not 1 <= year <= 9998:
            raise CalibrationError(f"date {date!r} is not a decimal year such as 2027.5")
        days = 366 if calendar.isleap(year) else 365
        day = _dt.date(year, 1, 1) + _dt.timedelta(days=int((dyear - year) * days))
    else:
        day = _as_date(date)
        dyear = decimal_year(day)
    if not VALID_FROM <= day <= VALID_UNTIL:
        raise CalibrationError(
            f"{MODEL} holds from {VALID_FROM} to {VALID_UNTIL}, not on {day}: pass a date "
            "within it (--date; the field changes by about 0.1 % a year), or give the field "
            "strength yourself (--radius 48uT)")
    name, mod = _backend()
    x, y, z = _evaluate(name, mod, dyear, lat_f, lon_f, alt_f / 1000.0)
    h = math.hypot(x, y)
    f = math.sqrt(h * h + z * z)
    inc = math.degrees(math.atan2(z, h))
    dec = math.degrees(math.atan2(y, x))
    warn: list[str] = []
    if h < BLACKOUT_NT:
        warn.append(f"the horizontal field here is only {h / 1000:.2f} uT (the WMM's blackout "
                    "zone, below 2 uT): a magnetic compass cannot give a heading here")
    elif h < CAUTION_NT:
        warn.append(f"the horizontal field here is only {h / 1000:.2f} uT (the WMM's caution "
                    "zone, below 6 uT): compass headings have large errors here")
    unc = {
        "total_ut": _ERR_F_NT / 1000.0,
        "horizontal_ut": _ERR_H_NT / 1000.0,
        "inclination_deg": _ERR_I_DEG,
        "declination_deg": math.hypot(_ERR_D_OFFSET_DEG, _ERR_D_COEF / max(h, 1.0)),
    }
    return ExpectedField(
        model=MODEL, backend=name, date=day.isoformat(), decimal_year=dyear, lat_deg=lat_f,
        lon_deg=lon_f, alt_m=alt_f, total_ut=f / 1000.0, horizontal_ut=h / 1000.0,
        north_ut=x / 1000.0, east_ut=y / 1000.0, down_ut=z / 1000.0, inclination_deg=inc,
        declination_deg=dec, uncertainty=unc, warnings=tuple(warn))


def strength_check(measured_ut: float | None, expected: float, what: str = "field"
                   ) -> str | None:
    """A warning when the field the readings show (uT) is more than 10 % from the model's.

    ``measured_ut`` is the strength in the sensor's own units converted to uT (None when the
    readings are raw counts: nothing to compare). ArduPilot's calibrator refuses a fit whose
    expected-to-fitted ratio leaves 0.85..1.4 ("bad radius", ``CompassCalibrator::fix_radius``);
    triaxcal warns earlier, at 10 %, and keeps the fit.

    >>> strength_check(61.0, 48.4) is not None, strength_check(49.0, 48.4)
    (True, None)
    """
    if measured_ut is None or not math.isfinite(measured_ut):
        return None
    ratio = measured_ut / expected
    if abs(ratio - 1) <= STRENGTH_TOLERANCE:
        return None
    ap = (" (ArduPilot's calibrator would refuse it: 'bad radius')"
          if not 0.85 <= 1 / ratio <= 1.4 else "")
    return (f"the {what} strength the readings show, {measured_ut:.3g} uT, is "
            f"{100 * (ratio - 1):+.0f} % from the World Magnetic Model's {expected:.3g} uT here"
            f"{ap}: a magnetised environment (steel, magnets, motors, cables nearby), a wrong "
            "location, or readings not in the stated unit; calibrate away from metal")
