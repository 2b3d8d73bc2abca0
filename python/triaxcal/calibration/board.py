"""A board's own calibration record (:mod:`triaxcal.io.board_store`: the 72-byte record the
firmware keeps in its EEPROM) as a calibration file's part, and back.

The board calibrates in counts: its calibrated readings have the record's ``radius`` for 1 g
(16384 for an MPU-6050 at +-2 g). A part in g per count is the record's matrix divided by that
scale; the board's matrix is the part's times it.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..conventions.units import unit_factor
from ..errors import CalibrationError
from ..io.board_store import BoardRecord
from .file import Calibration
from .part import SensorCalibration

__all__ = ["calibration_to_record", "record_to_calibration"]


def record_to_calibration(rec: BoardRecord, *, counts_per_g: float | None = None,
                          source: str | None = None) -> Calibration:
    """A board's record as a calibration file: the accelerometer part in g.

    The board's calibrated counts are at ``counts_per_g`` (default: the record's own radius,
    which is 1 g in the board's calibrated counts): the part's matrix (g per count) is the
    record's divided by it, and so are the radius and the RMS.

    Examples
    --------
    >>> r = BoardRecord(offset=(180, -240, 350), matrix=((0.985, 0, 0), (0, 1.016, 0),
    ...                 (0, 0, 0.996)), radius=16384, model="axis", origin="board", n=60)
    >>> part = record_to_calibration(r).accel
    >>> part.unit, part.radius, round(float(1 / part.matrix[0, 0]))  # counts per g, x axis
    ('g', 1.0, 16634)
    """
    if counts_per_g is None:
        counts_per_g = float(rec.radius)
    m = np.asarray(rec.matrix, dtype=float) / counts_per_g
    radius = rec.radius / counts_per_g
    stats: dict[str, Any] = {
        "origin": rec.origin,
        "converged": not rec.warnings & 0x02,
        "n_poses": rec.n,
        "rms": rec.rms / counts_per_g,
        "rms_pct_of_radius": 100.0 * rec.rms / rec.radius,
        "spread": rec.spread,
        "warnings": rec.warning_texts,
        "board_counts_per_g": counts_per_g,
    }
    part = SensorCalibration(offset=np.asarray(rec.offset, dtype=float), matrix=m,
                             raw_unit="counts", unit="g", radius=radius, model=rec.model,
                             stats=stats, source=source)
    return Calibration(accel=part, extra={"board_record": "fitted on the board"
                                          if rec.origin == "board" else "written by the host"})


def calibration_to_record(cal: Calibration, *,
                          counts_per_g: float) -> BoardRecord:
    """The accelerometer part of a host calibration as the record a board stores.

    The part must be in raw counts, calibrated in an acceleration unit (g, m/s^2) and have
    no temperature terms (the board applies none). The board's calibrated counts are at
    ``counts_per_g``: its matrix is the part's in g per count times that.
    """
    part = cal.part("accel")
    if part.raw_unit != "counts":
        raise CalibrationError(
            f"the accelerometer part's raw unit is {part.raw_unit!r}: a board applies its "
            "calibration to raw counts, so the part must be fitted on counts")
    if part.temperature is not None:
        raise CalibrationError(
            "the accelerometer part has temperature terms, which the board does not apply: "
            "export it as a C header instead (triaxcal export --format c)")
    to_g = unit_factor(part.unit, "g")
    m = np.asarray(part.matrix, dtype=float) * to_g * counts_per_g
    rms = part.stats.get("rms")
    rms_counts = float(rms) * to_g * counts_per_g if isinstance(rms, (int, float)) and \
        math.isfinite(rms) else 0.0
    n = part.stats.get("n")
    return BoardRecord(offset=tuple(part.offset), matrix=tuple(tuple(r) for r in m),
                       radius=counts_per_g, model=part.model if part.model in ("axis", "full")
                       else None, origin="host", n=n if isinstance(n, int) and 0 <= n < 65536
                       else 0, rms=rms_counts)
