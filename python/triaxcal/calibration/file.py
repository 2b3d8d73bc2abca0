"""Calibration files: one object for the accelerometer, gyroscope and magnetometer parts.

Error model (the same as :mod:`triaxcal.fit`): a raw reading ``raw`` (in ``raw_unit``, usually
counts) becomes ``calibrated = (raw - offset) @ matrix.T`` (in ``unit``). ``offset`` is the bias
/ hard iron in raw units; ``matrix`` **multiplies** and carries calibrated units per raw unit
(scale, cross-axis, soft iron). Optional temperature terms, in ``dT = T - temp_ref_c`` (deg C):

* ``offset(T) = offset + sum_k offset_poly[k] * dT**k``  (raw units; row 0 is usually zero);
* ``gain(T) = 1 + sum_k gain_poly[k] * dT**k``, per raw axis, which **multiplies** the
  offset-corrected raw reading before the matrix:
  ``calibrated = ((raw - offset(T)) * gain(T)) @ matrix.T``.

The JSON file (``"schema": "triaxcal.calibration/1"``) keeps the autopilots' parameter names:
``offset``, ``diag``, ``offdiag`` (``[xy, xz, yz]``, the upper triangle; a non-symmetric matrix
adds ``offdiag_lower`` ``[yx, zx, zy]``) and ``radius``. Floats are written with ``repr`` (the
shortest text that reads back to the same double), so ``load(save(cal)) == cal`` exactly.

A part that replaced an earlier calibration of the same sensor keeps a ``previous`` list of
summaries (newest first, at most :data:`MAX_PREVIOUS`): when it was replaced, the coefficients,
units, standard errors and provenance -- enough for ``triaxcal diff`` to say what changed.

A magnetometer part may also hold the field the World Magnetic Model expects where it was
calibrated (``expected_field``, :class:`triaxcal.methods.field.ExpectedField`) and its alignment
with the accelerometer (``alignment``, :class:`Alignment`: ``v_accel = rotation @ v_mag`` for
calibrated readings; :meth:`SensorCalibration.apply_aligned`).
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .._core import __version__
from ..errors import CalibrationError
from ..io.files import read_bounded, write_file
from . import schema as _schema
from .part import (
    SensorCalibration,
    _now_utc,
)

__all__ = ["KNOWN_MODELS", "SCHEMA", "SCHEMA_NAME", "SCHEMA_VERSION", "SENSORS", "Calibration"]

SCHEMA_NAME = "triaxcal.calibration"
SCHEMA_VERSION = 1
SCHEMA = f"{SCHEMA_NAME}/{SCHEMA_VERSION}"
SENSORS = _schema.SENSORS
#: Model names a part may carry (see :mod:`triaxcal.calibration.schema`).
KNOWN_MODELS = _schema.KNOWN_MODELS


@dataclass(frozen=True, eq=False)
class Calibration:
    """Calibration of a board: any of the ``accel``, ``gyro`` and ``mag`` parts, with provenance.

    Attributes
    ----------
    accel, gyro, mag : SensorCalibration, optional
        The parts present.
    sensor_id : str
        Which board / sensor this belongs to (free text, e.g. a serial number).
    created_utc : str
        Creation time, UTC, ISO 8601 (``2026-01-02T03:04:05Z``).
    library_version : str
        ``triaxcal.__version__`` that made it.
    extra : dict
        Free-form JSON metadata.

    Examples
    --------
    >>> import numpy as np, triaxcal as tc
    >>> part = tc.SensorCalibration(offset=[10, 0, 0], matrix=np.eye(3) / 16384, unit="g")
    >>> cal = tc.Calibration(accel=part, sensor_id="board-1")
    >>> cal.apply([[16394, 0, 0]], sensor="accel").tolist()
    [[1.0, 0.0, 0.0]]
    >>> tc.Calibration.from_json(cal.to_json()) == cal
    True
    """

    accel: SensorCalibration | None = None
    gyro: SensorCalibration | None = None
    mag: SensorCalibration | None = None
    sensor_id: str = ""
    created_utc: str = field(default_factory=_now_utc)
    library_version: str = __version__
    extra: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for name in SENSORS:
            part = getattr(self, name)
            if part is not None and not isinstance(part, SensorCalibration):
                raise CalibrationError(
                    f"{name} must be a SensorCalibration (or None), got {type(part).__name__}"
                )
        if not any(getattr(self, s) is not None for s in SENSORS):
            raise CalibrationError("a Calibration needs at least one of accel, gyro, mag")
        for name in SENSORS:
            part = getattr(self, name)
            if part is not None and part.alignment is not None and part.alignment.to == name:
                raise CalibrationError(f"{name}.alignment.to is {name}: a part cannot be aligned "
                                       "to itself")
        for name in ("sensor_id", "created_utc", "library_version"):
            _schema.TOP_FIELDS[name].check(getattr(self, name), name)
        if not isinstance(self.extra, Mapping):
            raise CalibrationError(f"extra must be a mapping, got {type(self.extra).__name__}")
        object.__setattr__(self, "extra", _schema.json_object(dict(self.extra), "extra"))

    @property
    def sensors(self) -> tuple[str, ...]:
        """Names of the parts present, in the order accel, gyro, mag."""
        return tuple(s for s in SENSORS if getattr(self, s) is not None)

    def part(self, sensor: str) -> SensorCalibration:
        """The part for ``sensor``; a clear error if it is missing."""
        if sensor not in SENSORS:
            raise CalibrationError(f"unknown sensor {sensor!r}: use one of {SENSORS}")
        p = getattr(self, sensor)
        if p is None:
            raise CalibrationError(
                f"this calibration has no {sensor} part (it has: {', '.join(self.sensors)})"
            )
        return p

    def apply(self, raw: Any, sensor: str = "accel", temperature: Any = None) -> np.ndarray:
        """Calibrate ``raw`` (N, 3) readings of ``sensor``; see :meth:`SensorCalibration.apply`."""
        return self.part(sensor).apply(raw, temperature=temperature)

    def replace(self, **changes: Any) -> Calibration:
        """A copy with some fields changed (e.g. ``cal.replace(mag=part)``)."""
        d = {k: getattr(self, k) for k in (*SENSORS, "sensor_id", "created_utc",
                                            "library_version", "extra")}
        d.update(changes)
        return Calibration(**d)

    # -- JSON -----------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        return {
            "schema": SCHEMA,
            "sensor_id": self.sensor_id,
            "created_utc": self.created_utc,
            "library_version": self.library_version,
            "parts": {s: getattr(self, s).to_dict() for s in self.sensors},
            "extra": self.extra,
        }

    def to_json(self) -> str:
        """JSON text (2-space indent, floats as ``repr``: exact round trip)."""
        return json.dumps(self.to_dict(), indent=2, allow_nan=False) + "\n"

    @classmethod
    def from_dict(cls, d: Any) -> Calibration:
        """Inverse of :meth:`to_dict`; raises :class:`CalibrationError` when malformed."""
        if not isinstance(d, Mapping):
            raise CalibrationError("a calibration file must hold a JSON object")
        _check_schema(d.get("schema"))
        v = _schema.check_fields(d, _schema.TOP_FIELDS, "calibration")
        parts = v["parts"]
        if not isinstance(parts, Mapping):
            raise CalibrationError("'parts' must be a JSON object keyed by accel/gyro/mag")
        unknown = [str(k)[:40] for k in parts if k not in SENSORS]
        if unknown:
            raise CalibrationError(f"unknown sensor part(s) {sorted(unknown)}: use {SENSORS}")
        kw = {s: SensorCalibration.from_dict(parts[s], s) for s in SENSORS if s in parts}
        return cls(
            **kw,
            sensor_id=v.get("sensor_id", ""),
            created_utc=v.get("created_utc", ""),
            library_version=v.get("library_version", ""),
            extra=v.get("extra") or {},
        )

    @classmethod
    def from_json(cls, text: str) -> Calibration:
        """Parse calibration JSON text (see :meth:`load`)."""
        try:
            d = _schema.parse_json(text)
        except CalibrationError as exc:
            raise CalibrationError(
                f"not a calibration file: {exc}; write it with cal.save(path) or `triaxcal fit`"
            ) from None
        return cls.from_dict(d)

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> Calibration:
        """Read a calibration file written by :meth:`save` (or by ``triaxcal fit``).

        Every value is validated (see :mod:`triaxcal.calibration.schema`): numbers are finite
        numbers, the matrix is invertible, the model is a known name, text is bounded and free of
        control characters. Anything else -- a folder, a pipe or a device (only a regular file
        is read), a file that is not UTF-8 JSON, one larger than 16 MiB
        (``MAX_FILE_BYTES``), nested too deeply -- raises :class:`CalibrationError`.
        """
        p = Path(path)
        data = read_bounded(p, limit=_schema.MAX_FILE_BYTES, what="calibration file")
        try:
            text = data.decode("utf-8-sig")
        except UnicodeDecodeError as exc:
            raise CalibrationError(
                f"{p} is not a calibration file: byte {exc.start} is not UTF-8 text (a "
                "calibration file is JSON)"
            ) from None
        try:
            return cls.from_json(text)
        except CalibrationError as exc:
            raise CalibrationError(f"{p}: {exc}") from None

    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write the calibration as JSON to ``path`` (atomically: temp file, then rename).

        Raises :class:`CalibrationError` (saying why) when the file cannot be written.
        """
        return write_file(path, self.to_json(), what="calibration file")

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Calibration) and self.to_dict() == other.to_dict()

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        parts = ", ".join(f"{s}={getattr(self, s)!r}" for s in self.sensors)
        return f"Calibration(sensor_id={self.sensor_id!r}, {parts})"


def _check_schema(schema: Any) -> None:
    if not isinstance(schema, str) or not schema.startswith(SCHEMA_NAME + "/"):
        raise CalibrationError(
            f"not a triaxcal calibration file: 'schema' is {schema!r}, expected {SCHEMA!r}"
        )
    ver = schema[len(SCHEMA_NAME) + 1:]
    if not ver.isdigit():
        raise CalibrationError(f"malformed schema version in {schema!r}, expected {SCHEMA!r}")
    if int(ver) > SCHEMA_VERSION:
        raise CalibrationError(
            f"this file uses schema {schema!r}, newer than this triaxcal ({__version__}) reads "
            f"({SCHEMA!r}): upgrade triaxcal (pip install -U triaxcal)"
        )
    if int(ver) < 1:
        raise CalibrationError(f"unknown schema version in {schema!r}")
