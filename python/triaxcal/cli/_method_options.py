"""Options the method commands share: ``--counts-per-unit`` (the export's syntax), ``--bias``
(a gyroscope's bias from a recording at rest), ``--gravity`` and the two-sensor column options.

``--counts-per-unit SENSOR=COUNTS[:UNIT]`` is the one syntax of the command line
(:func:`triaxcal.export._trust.parse_counts_per_unit`, as ``export`` and ``send`` take it): a
sensor's nominal sensitivity, raw counts per unit, as its driver or datasheet gives it
(``gyro=131:deg/s``). A command that reads one sensor also takes it without ``SENSOR=``; the
unit defaults to the sensor's usual one (g, deg/s, uT).
"""

from __future__ import annotations

import argparse
import math
import re
from collections.abc import Callable
from typing import Any

import numpy as np

from ..conventions.units import UNITS, unit_factor
from ..errors import CalibrationError

__all__ = ["IMUCAL_COLUMNS", "add_bias_option", "add_triad_options", "bias_from_args",
           "counts_per_unit", "gravity_type", "nominal", "three_numbers", "time_column",
           "triad_columns"]


def counts_per_unit(sensor: str) -> Callable[[str], tuple[float, str]]:
    """An argparse type for the ``--counts-per-unit`` of a command that reads ``sensor`` only:
    ``[SENSOR=]COUNTS[:UNIT]`` -> (counts, unit).

    >>> parse = counts_per_unit("gyro")
    >>> parse("16.4"), parse("gyro=7505:rad/s")
    ((16.4, 'deg/s'), (7505.0, 'rad/s'))
    """
    from ..export._trust import parse_counts_per_unit

    def parse(text: str) -> tuple[float, str]:
        t = str(text)[:200]
        try:
            scales = parse_counts_per_unit(t if "=" in t else f"{sensor}={t}")
        except CalibrationError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None
        if set(scales) != {sensor}:
            raise argparse.ArgumentTypeError(
                f"{t[:40]!r}: this command reads the {sensor} only: give {sensor}=COUNTS[:UNIT]")
        return scales[sensor]

    return parse


def nominal(scale: tuple[float, str] | None, unit: str) -> float | None:
    """Counts per ``unit`` from a parsed ``--counts-per-unit`` (None when not given).

    >>> round(nominal((7505.0, "rad/s"), "deg/s"), 2)
    130.99
    """
    if scale is None:
        return None
    counts, given = scale
    return counts * unit_factor(unit, given)  # counts per `given` -> counts per `unit`


def three_numbers(text: str) -> np.ndarray | None:
    """``"X,Y,Z"`` as three finite numbers, or None when ``text`` is not that."""
    parts = [s for s in re.split(r"[,\s]+", text.strip()) if s]
    if len(parts) != 3:
        return None
    try:
        v = np.array([float(s) for s in parts])
    except ValueError:
        return None
    return v if np.isfinite(v).all() else None


def add_bias_option(p: Any, what: str | None = None) -> None:
    """``--bias FILE|X,Y,Z``: the gyroscope's bias (required when ``what`` says nowhere else
    it comes from)."""
    p.add_argument("--bias", default=None, metavar="FILE|X,Y,Z", required=what is None,
                   help="the gyroscope's bias, raw units: a recording of the board at rest (the "
                        "mean of its still part, found as the first --rest seconds teach; the "
                        "whole file when it has no t column and no --rate-hz is given; the "
                        "gyroscope's columns as in the data) or three numbers X,Y,Z (written "
                        "--bias=-1.5,2,0.3 when the first is negative)"
                        + (f". Default: from {what}" if what else ""))


def bias_from_args(args: Any, columns: str | None = None, option: str = "columns"
                   ) -> tuple[np.ndarray | None, dict[str, Any]]:
    """The bias ``--bias`` gives (None without it), and what to record about it; ``columns``:
    the gyroscope's columns in the file at rest (as in the data)."""
    from ..io.tables import pick_columns, read_table
    from ..methods.gyro import gyro_bias, sample_rate

    if args.bias is None:
        return None, {}
    v = three_numbers(args.bias)
    if v is not None:
        return v, {"bias": "given"}
    table = read_table(args.bias)
    cols = pick_columns(table, columns, "gyro", option=option)
    g = table.data[:, cols]
    t = table.data[:, table.names.index("t")] if table.names and "t" in table.names else None
    rate = (sample_rate(t, args.rate_hz) if (t is not None or args.rate_hz is not None)
            else None)
    rest = gyro_bias(g, rate_hz=rate, rest_s=args.rest)
    return np.asarray(rest.offset), {
        "bias": {"source": str(table.path), "sha256": table.sha256, "n_samples": rest.n,
                 "std": [float(x) for x in rest.std]}}


def gravity_type(text: str) -> tuple[float, str]:
    """An argparse type for ``--gravity``: local gravity with its unit -- ``9.81m/s^2``,
    ``1g``, or a bare number (m/s^2 from 5 to 15, g from 0.5 to 2): the accelerometer's
    calibrated unit and the magnitude it reads at rest.

    >>> gravity_type("9.81"), gravity_type("1g"), gravity_type("9.80665 m/s^2")
    ((9.81, 'm/s^2'), (1.0, 'g'), (9.80665, 'm/s^2'))
    """
    m = re.fullmatch(r"\s*([0-9]*\.?[0-9]+(?:[eE][-+]?[0-9]+)?)\s*(\S*)\s*", str(text)[:40])
    value = float(m.group(1)) if m else math.nan
    unit = m.group(2) if m else ""
    if not unit and math.isfinite(value):
        unit = "g" if 0.5 <= value <= 2 else "m/s^2" if 5 <= value <= 15 else ""
    if not (math.isfinite(value) and value > 0) or UNITS.get(unit, ("",))[0] != "accel":
        raise argparse.ArgumentTypeError(
            f"{str(text)[:40]!r}: give local gravity with its unit, e.g. 9.81m/s^2 or 1g")
    return value, unit


#: Column names of imucal's recordings, taken when the sensor's own (ax, ay, az...) are absent.
IMUCAL_COLUMNS = {"accel": ("acc_x", "acc_y", "acc_z"), "gyro": ("gyr_x", "gyr_y", "gyr_z")}


def add_triad_options(p: Any) -> None:
    """``--accel-columns``, ``--gyro-columns``, ``--accel-raw-unit``, ``--gyro-raw-unit``: the
    two sensors of a method that calibrates both at once."""
    for sensor, names in (("accel", "ax,ay,az"), ("gyro", "gx,gy,gz")):
        p.add_argument(f"--{sensor}-columns", default=None, metavar="COLUMNS",
                       help=f"the {'accelerometer' if sensor == 'accel' else 'gyroscope'}'s "
                            f"three columns, by name or zero-based index (default {names} or "
                            f"{','.join(IMUCAL_COLUMNS[sensor])} by name)")
    p.add_argument("--accel-raw-unit", default="counts", metavar="UNIT",
                   help="unit of the accelerometer readings (default counts; m/s^2 or g for a "
                        "sensor that reports them)")
    p.add_argument("--gyro-raw-unit", default="counts", metavar="UNIT",
                   help="unit of the gyroscope readings (default counts; deg/s or rad/s for a "
                        "sensor that reports them)")


def triad_columns(table: Any, spec: str | None, sensor: str) -> list[int]:
    """The three columns of ``sensor`` (``--accel-columns`` / ``--gyro-columns``)."""
    from ..io.tables import SENSOR_COLUMNS, pick_columns

    names = table.names or ()
    if (spec is None and not all(c in names for c in SENSOR_COLUMNS[sensor])
            and all(c in names for c in IMUCAL_COLUMNS[sensor])):
        return [names.index(c) for c in IMUCAL_COLUMNS[sensor]]
    return pick_columns(table, spec, sensor, option=f"{sensor}_columns")


def time_column(table: Any, spec: str | None) -> np.ndarray | None:
    """The time stamps (s): ``--time-column`` by name or index, else a column named t."""
    names = table.names or ()
    if spec is None:
        return table.data[:, names.index("t")] if "t" in names else None
    s = spec.strip()
    if s.isdigit() and int(s) < table.data.shape[1]:
        return table.data[:, int(s)]
    if s in names:
        return table.data[:, names.index(s)]
    raise CalibrationError(f"--time-column {spec[:40]!r}: no such column in {table.path} "
                           f"({table.data.shape[1]} columns)")
