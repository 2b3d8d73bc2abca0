"""Units of the calibrated quantities, and conversions between them.

Every unit string the library writes or accepts is one of :data:`UNITS`'s keys; a conversion
factor always **multiplies** (``value_in_dst = value_in_src * unit_factor(src, dst)``).
"""

from __future__ import annotations

import math

from ..errors import CalibrationError

__all__ = [
    "STANDARD_GRAVITY",
    "UNITS",
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
