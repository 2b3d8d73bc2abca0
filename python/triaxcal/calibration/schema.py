"""What a calibration file may hold: one validator per field, in tables.

A calibration file is something people download and share, so every value in it is checked
for type and range before it is used (:mod:`triaxcal.calibration` builds its objects only
from values that passed these checks, whether they come from a file or from Python):

* numbers are finite real numbers -- not strings, not booleans, not 5000-digit integers;
* text is bounded in length and, for the short identity fields (units, model, sensor id,
  dates, versions, paths), holds no control or invisible formatting characters;
* nested free-form JSON (``stats``, ``extra``) is bounded in depth.

Adding a field means adding one row to the table of its object (``TOP_FIELDS``,
``PART_FIELDS``, ``TEMPERATURE_FIELDS``, or ``STATS_FIELDS`` for typed statistics) with a
validator built from the functions below.
"""
from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from .._checks.fields import (  # noqa: F401  (re-exported: the file's validators in one place)
    MAX_DEPTH,
    MAX_FILE_BYTES,
    MAX_INT_DIGITS,
    MAX_TEXT,
    Field,
    Validator,
    _short,
    boolean,
    check_fields,
    check_matrix,
    integer,
    json_object,
    json_value,
    list_of,
    nonnegative,
    one_of,
    optional,
    parse_json,
    positive,
    real,
    reals,
    sha256_hex,
    text,
)
from .._checks.options import MAGNITUDE
from ..conventions.names import SENSORS  # noqa: F401
from ..errors import CalibrationError
from ..quality.bounds import DIE_TEMPERATURE_C

#: Model names a part may carry. Fits give ``sphere``, ``axis``, ``full``; the methods give
#: the others. A new method adds its name here.
KNOWN_MODELS = (
    "sphere",
    "axis",
    "full",
    "bias",
    "temperature-poly1",
    "temperature-poly2",
    "temperature-poly3",
    "six-position",
    "tilt-rig",
    "turntable",
    "ferraris",
    "imu",
    "nominal",
    "manual",
    "offset",
    "yaw",
    "autocal-vanhees",  # free-living auto-calibration (triaxcal.autocalibrate)
    "factory",  # a maker's calibration read from a file header (GENEActiv)
    "attitude",  # compass fitted to the Earth's field turned by a flight's attitude
)


#: Highest degree of the temperature polynomials (``offset_poly``/``gain_poly`` rows - 1).
MAX_POLY_DEGREE = 3


def model_name(value: Any, what: str) -> str:
    v = text(32)(value, what)
    if v not in KNOWN_MODELS:
        raise CalibrationError(
            f"{what} {_short(v)} is not a known model: use one of {', '.join(KNOWN_MODELS)}"
        )
    return v



def _norms(value: Any, what: str) -> dict[str, Any]:
    return check_fields(
        value,
        {
            "min": Field(real),
            "max": Field(real),
            "mean": Field(real),
            "std": Field(nonnegative),
            "std_over_mean": Field(optional(real)),
        },
        what,
        open_ended=True,
    )


def _stderr(value: Any, what: str) -> dict[str, float]:
    if not isinstance(value, Mapping):
        raise CalibrationError(f"{what} must be an object of parameter name -> number")
    return {text(64)(k, f"a key of {what}"): nonnegative(v, f"{what}.{k}")
            for k, v in value.items()}


#: Statistics with a known meaning, typed (they are read by the report and the exports);
#: any other key in ``stats`` is free-form JSON.
STATS_FIELDS: dict[str, Field] = {
    "model": Field(optional(text(64))),
    "n": Field(integer),
    "n_input": Field(integer),
    "n_samples": Field(integer),
    "rms": Field(nonnegative),
    "radius": Field(positive),
    "rms_pct_of_radius": Field(nonnegative),
    "iterations": Field(integer),
    "converged": Field(boolean),
    "condition": Field(optional(nonnegative)),
    "stderr": Field(_stderr),
    "warnings": Field(list_of(text(MAX_TEXT, plain=False))),
    "rejected": Field(list_of(integer)),
    "norms": Field(_norms),
    "coverage_pct": Field(optional(nonnegative)),
    "columns": Field(list_of(one_of(integer, text(256)), max_items=3)),
    "poses": Field(boolean),
    "pose_window": Field(integer),
    "units_per_g": Field(positive),
    "sigma": Field(nonnegative),
    "rejection_rounds": Field(integer),
    "model_reason": Field(optional(text(MAX_TEXT, plain=False))),
    "forced": Field(boolean),
    "interference": Field(lambda v, w: _interference(v, w)),
    "undetermined": Field(list_of(text(MAX_TEXT, plain=False), max_items=64)),
    "record_instead": Field(optional(text(MAX_TEXT, plain=False))),
    "intervals": Field(lambda v, w: _intervals(v, w)),
}


def _interval(value: Any, what: str) -> dict[str, Any]:
    return check_fields(value, {k: Field(real, required=k != "boot_std") for k in (
        "estimate", "stderr", "boot_std", "lower", "upper", "tolerance")}, what,
        open_ended=True)


def _intervals(value: Any, what: str) -> dict[str, Any]:
    """Bootstrap intervals (``BootstrapIntervals.as_dict``): the numbers the report and
    ``diff`` print and compare are numbers."""
    v = check_fields(value, {
        "level": Field(real, required=True),
        "n_boot": Field(integer, required=True),
        "n_failed": Field(integer),
        "resample": Field(text(64), required=True),
        "raw_radius": Field(optional(real)),
        "coefficients": Field(lambda c, w: _coefficients(c, w), required=True),
        "flagged": Field(list_of(text(64))),
        "warnings": Field(list_of(text(MAX_TEXT, plain=False))),
    }, what, open_ended=True)
    return v


def _coefficients(value: Any, what: str) -> dict[str, Any]:
    if not isinstance(value, Mapping):
        raise CalibrationError(f"{what} must be an object of coefficient name -> interval")
    return {text(64)(k, f"a key of {what}"): _interval(c, f"{what}.{k}")
            for k, c in value.items()}


def _interference(value: Any, what: str) -> dict[str, Any]:
    """``{"per": "A" | "throttle", "vector": [x, y, z], "unit": ..., "source": ...}``: the
    field (in ``unit``, calibrated frame) ADDED after the matrix per ampere of battery current
    or per unit of throttle (0..1), as ArduPilot's COMPASS_MOT (triaxcal.methods.attitude)."""
    return check_fields(value, {
        "per": Field(lambda v, w: _per(v, w), required=True),
        "vector": Field(lambda v, w: vec3(v, w).tolist(), required=True),
        "unit": Field(UNIT_TEXT, required=True),
        "source": Field(optional(text(128))),
    }, what)


def _per(value: Any, what: str) -> str:
    v = text(16)(value, what)
    if v not in ("A", "throttle"):
        raise CalibrationError(f"{what} must be 'A' or 'throttle', got {_short(v)}")
    return v


def stats_object(value: Any, what: str) -> dict[str, Any]:
    return check_fields(value, STATS_FIELDS, what, open_ended=True)


def _temp_c(value: Any, what: str) -> float:
    v = real(value, what)
    lo, hi = DIE_TEMPERATURE_C
    if v < lo:
        raise CalibrationError(f"{what} is {v} degC, below absolute zero")
    if v > hi:
        raise CalibrationError(f"{what} is {v:g} degC, hotter than any sensor's die ({hi:g} "
                               "degC): the file is damaged or the temperature is in another unit")
    return v


def _bounded(arr: np.ndarray, what: str) -> np.ndarray:
    """Coefficients no larger than :data:`~triaxcal._checks.options.MAGNITUDE` in size: past
    any unit a sensor reads in, and where applying them (squares, products, powers of dT)
    would leave a double's range."""
    hi = MAGNITUDE[1]
    if arr.size and float(np.abs(arr).max()) > hi:
        raise CalibrationError(f"{what} holds {float(np.abs(arr).max()):.3g}, larger than "
                               f"{hi:g} in any unit: the file is damaged")
    return arr


def scale(value: Any, what: str) -> float:
    """A radius or a field strength: positive and within MAGNITUDE."""
    v = positive(value, what)
    lo, hi = MAGNITUDE
    if not lo <= v <= hi:
        raise CalibrationError(f"{what} must lie in [{lo:g}, {hi:g}] in any unit, got {v:g}: "
                               "the file is damaged")
    return v


def temp_range(value: Any, what: str) -> tuple[float, float]:
    rng = reals(value, (2,), what)
    lo, hi = (_temp_c(float(v), what) for v in rng)
    if lo > hi:
        raise CalibrationError(f"{what} must be (lowest, highest), got {[lo, hi]}")
    return lo, hi


def poly(value: Any, what: str) -> np.ndarray:
    """Temperature polynomial coefficients: (degree + 1, 3), degree 0..MAX_POLY_DEGREE."""
    arr = _bounded(reals(value, (-1, 3), what), what)
    if not 1 <= arr.shape[0] <= MAX_POLY_DEGREE + 1:
        raise CalibrationError(
            f"{what} has {arr.shape[0]} rows (degree {arr.shape[0] - 1}); it must have 1 to "
            f"{MAX_POLY_DEGREE + 1} rows of 3 columns, lowest order first: at most degree "
            f"{MAX_POLY_DEGREE}"
        )
    return arr


def vec3(value: Any, what: str) -> np.ndarray:
    return _bounded(reals(value, (3,), what), what)


TEMPERATURE_FIELDS: dict[str, Field] = {
    "temp_ref_c": Field(_temp_c, required=True),
    "temp_range_c": Field(temp_range, required=True),
    "offset_poly": Field(poly, required=True),
    "gain_poly": Field(optional(poly)),
}

#: Units and model names are short identifiers; ``source`` is a path or a description.
UNIT_TEXT = text(32, nonblank=True)
SOURCE_TEXT = text(4096)

PART_FIELDS: dict[str, Field] = {
    "raw_unit": Field(UNIT_TEXT, required=True),
    "unit": Field(UNIT_TEXT, required=True),
    "offset": Field(vec3, required=True),
    "diag": Field(vec3, required=True),
    "offdiag": Field(vec3, required=True),
    "offdiag_lower": Field(optional(vec3)),
    "radius": Field(optional(scale)),
    "model": Field(optional(model_name)),
    "temperature": Field(optional(lambda v, w: check_fields(v, TEMPERATURE_FIELDS, w))),
    "input_sha256": Field(optional(sha256_hex)),
    "source": Field(optional(SOURCE_TEXT)),
    "stats": Field(optional(stats_object)),
    # checked in full by triaxcal.methods.field.ExpectedField and
    # triaxcal.calibration.alignment.Alignment
    "expected_field": Field(optional(json_object)),
    "alignment": Field(optional(json_object)),
    # the validity gate's verdict (triaxcal.calibration.gate): False only when forced
    "valid": Field(optional(boolean)),
    "invalid_reasons": Field(list_of(text(MAX_TEXT, plain=False), max_items=64)),
}

SENSOR_ID_TEXT = text(256)
STAMP_TEXT = text(64)

#: Most summaries of replaced calibrations a part keeps (newest first).
MAX_PREVIOUS = 10


def _vec3_list(value: Any, what: str) -> list[float]:
    return [float(x) for x in vec3(value, what)]


#: One summary of a calibration that a newer one replaced (a part's ``previous`` list).
SUMMARY_FIELDS: dict[str, Field] = {
    "replaced_utc": Field(STAMP_TEXT, required=True),
    "created_utc": Field(optional(STAMP_TEXT)),
    "raw_unit": Field(UNIT_TEXT, required=True),
    "unit": Field(UNIT_TEXT, required=True),
    "offset": Field(_vec3_list, required=True),
    "diag": Field(_vec3_list, required=True),
    "offdiag": Field(_vec3_list, required=True),
    "offdiag_lower": Field(optional(_vec3_list)),
    "radius": Field(optional(scale)),
    "model": Field(optional(model_name)),
    "stderr": Field(_stderr),
    "rms": Field(nonnegative),
    "n": Field(integer),
    "input_sha256": Field(optional(sha256_hex)),
    "source": Field(optional(SOURCE_TEXT)),
}


def summary(value: Any, what: str) -> dict[str, Any]:
    return check_fields(value, SUMMARY_FIELDS, what)


PART_FIELDS["previous"] = Field(optional(list_of(summary, max_items=10 * MAX_PREVIOUS)))

TOP_FIELDS: dict[str, Field] = {
    "schema": Field(text(64), required=True),
    "sensor_id": Field(SENSOR_ID_TEXT),
    "created_utc": Field(STAMP_TEXT),
    "library_version": Field(STAMP_TEXT),
    "parts": Field(lambda v, w: v, required=True),  # checked part by part by the loader
    "extra": Field(optional(json_object)),
}


