"""Units of the calibrated quantities, and conversions between them.

Every unit string the library writes or accepts is one of :data:`UNITS`'s keys; a conversion
factor always **multiplies** (``value_in_dst = value_in_src * unit_factor(src, dst)``).
"""

from __future__ import annotations

import math

from ..errors import CalibrationError

__all__ = [
    "DEVICE_COUNTS_PER_UNIT",
    "PLAUSIBLE_RADIUS",
    "UNITS",
    "implausible_radius",
    "per_unit",
    "unit_factor",
]

# Unit -> (quantity, factor to the SI-ish base unit of that quantity).
UNITS: dict[str, tuple[str, float]] = {
    "g": ("accel", 9.80665),
    "m/s^2": ("accel", 1.0),
    "m/s2": ("accel", 1.0),
    "mg": ("accel", 9.80665e-3),
    "deg/s": ("gyro", math.pi / 180.0),
    "dps": ("gyro", math.pi / 180.0),
    "rad/s": ("gyro", 1.0),
    "uT": ("mag", 1.0),
    "nT": ("mag", 1e-3),
    "mT": ("mag", 1e3),
    "gauss": ("mag", 100.0),
    "G": ("mag", 100.0),
    "mG": ("mag", 0.1),
}

#: Device scales of the project's simulator and AVR firmware: counts per unit.
DEVICE_COUNTS_PER_UNIT: dict[str, tuple[float, str]] = {
    "accel": (16384.0, "g"),
    "gyro": (131.0, "deg/s"),
    "mag": (10.0, "uT"),
}


def unit_factor(src: str, dst: str) -> float:
    """Factor that converts a value in ``src`` to ``dst`` (it multiplies).

    >>> round(unit_factor("g", "m/s^2"), 5)
    9.80665
    """
    if src == dst:
        return 1.0
    if src not in UNITS or dst not in UNITS or UNITS[src][0] != UNITS[dst][0]:
        raise CalibrationError(
            f"cannot convert {src!r} to {dst!r}: known units are {sorted(UNITS)}"
        )
    return UNITS[src][1] / UNITS[dst][1]


#: Standard gravity, m/s^2 (the ``g`` of :data:`UNITS`).
STANDARD_GRAVITY = 9.80665

#: Magnitudes a calibrated reading can have on Earth, per sensor, in the base unit of its
#: quantity (m/s^2, uT), with the words that explain the range. Local gravity is 9.76-9.84
#: m/s^2 (poles to equator, sea level to high mountains); the geomagnetic field at the
#: surface is 25-65 uT (World Magnetic Model), wider indoors near steel.
PLAUSIBLE_RADIUS: dict[str, tuple[float, float, str]] = {
    "accel": (0.95 * STANDARD_GRAVITY, 1.05 * STANDARD_GRAVITY,
              "gravity is about 1 g (9.81 m/s^2) everywhere on Earth"),
    "mag": (20.0, 70.0, "the Earth's field is 25-65 uT at the surface"),
}


def per_unit(unit: str, raw_unit: str, *, short: bool = False) -> str:
    """Words for a quantity in ``unit`` per ``raw_unit``: ``"g per count"``.

    The raw unit is singular after "per" ("g per count", never "g per counts"); the same unit
    on both sides is called a ratio. ``short`` gives ``"g/count"``.

    >>> per_unit("g", "counts"), per_unit("uT", "counts", short=True)
    ('g per count', 'uT/count')
    >>> per_unit("counts", "counts")
    'counts per count (a ratio)'
    """
    raw = _singular(raw_unit)
    if short:
        return "(ratio)" if unit == raw_unit else f"{unit}/{raw}"
    return f"{unit} per {raw}" + (" (a ratio)" if unit == raw_unit else "")


def _singular(unit: str) -> str:
    return {"counts": "count", "lsbs": "lsb", "LSBs": "LSB"}.get(unit, unit)


def implausible_radius(sensor: str, value: float, unit: str) -> str | None:
    """A warning when ``value`` ``unit`` cannot be the magnitude of ``sensor`` readings on
    Earth (see :data:`PLAUSIBLE_RADIUS`), else ``None``. Units of another quantity raise
    :class:`CalibrationError`; raw units (counts) and the gyroscope are not judged.

    >>> implausible_radius("mag", 48.0, "uT") is None
    True
    >>> for line in implausible_radius("mag", 48.0, "mT").split(": "):
    ...     print(line)
    a magnetometer radius of 48 mT (48000 uT) is not plausible
    the Earth's field is 25-65 uT at the surface; did you mean 48 uT?
    """
    if unit not in UNITS:
        return None
    quantity, factor = UNITS[unit]
    names = {"accel": "an acceleration", "gyro": "a rotation rate", "mag": "a magnetic field"}
    if sensor in names and quantity != sensor:
        raise CalibrationError(
            f"a radius in {unit} is {names[quantity]}, but the {sensor} sensor measures "
            f"{names[sensor]}: give the radius in its units"
        )
    bounds = PLAUSIBLE_RADIUS.get(sensor)
    if bounds is None:
        return None
    lo, hi, why = bounds
    base = value * factor
    if lo <= base <= hi:
        return None
    ref = "g" if quantity == "accel" else "uT"
    conv = "" if unit == ref else f" ({base / UNITS[ref][1]:.6g} {ref})"
    hint = ""
    for cand in ("g", "m/s^2") if quantity == "accel" else ("uT", "nT", "mT", "gauss", "mG"):
        if cand != unit and lo <= value * UNITS[cand][1] <= hi:
            hint = f"; did you mean {value:g} {cand}?"
            break
    what = "an accelerometer" if sensor == "accel" else "a magnetometer"
    return f"{what} radius of {value:g} {unit}{conv} is not plausible: {why}{hint}"
