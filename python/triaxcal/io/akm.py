"""The factory sensitivity adjustment of AKM magnetometers (AK8963, AK8975, AK09911, AK09912).

Each chip stores one byte per axis in its fuse ROM (``ASAX``, ``ASAY``, ``ASAZ``; on the
AK8963 at 0x10-0x12, read in fuse-ROM access mode). The datasheets' adjusted reading is

    H_adj = H * ((ASA - 128) * 0.5 / 128 + 1) = H * k,      k = (ASA - 128) / 256 + 1,

the factor ArduPilot's ``AP_Compass_AK8963::_calibrate`` computes and multiplies into every raw
sample before its offsets (``_make_factory_sensitivity_adjustment``). ``k`` lies between 0.5
(ASA 0) and 1.498 (ASA 255). The AK09916 (inside the ICM-20948) has no such registers: its
readings need no factor (ArduPilot's AK09916 driver applies none).

:func:`apply_asa` adjusts readings before fitting; :func:`triaxcal.calibration.parts.fold_asa`
writes the resulting calibration for the register counts the chip reports, so that firmware applies
one calibration and no separate factor.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .._checks.arrays import as_points
from ..errors import CalibrationError

__all__ = ["apply_asa", "asa_factors"]


def asa_factors(asa: Any) -> np.ndarray:
    """The factors ``k = (ASA - 128) / 256 + 1`` (3,) of the three fuse-ROM bytes ``asa``.

    >>> asa_factors([176, 177, 165]).tolist()
    [1.1875, 1.19140625, 1.14453125]
    """
    if isinstance(asa, (list, tuple)) and any(isinstance(v, (bool, np.bool_)) for v in asa):
        raise CalibrationError(f"asa must be 3 register values 0..255, got {asa!r}")
    try:
        a = np.asarray(asa)
    except (TypeError, ValueError):
        raise CalibrationError(f"asa must be 3 register values 0..255, got {asa!r}") from None
    if a.shape != (3,) or a.dtype.kind not in "iuf" or a.dtype == np.bool_:
        raise CalibrationError(f"asa must be 3 register values 0..255 (ASAX, ASAY, ASAZ), got "
                               f"{asa!r}")
    f = a.astype(np.float64)
    if not (np.isfinite(f).all() and np.all(f == np.round(f)) and np.all((f >= 0) & (f <= 255))):
        raise CalibrationError(
            f"asa must be whole register values 0..255 (one byte each), got {a.tolist()}"
        )
    k = (f - 128.0) / 256.0 + 1.0
    k.setflags(write=False)
    return k


def apply_asa(raw: Any, asa: Any) -> np.ndarray:
    """Readings (N, 3) multiplied per axis by the factors of :func:`asa_factors`.

    >>> apply_asa([[100, 100, 100]], [128, 192, 64]).tolist()
    [[100.0, 125.0, 75.0]]
    """
    return as_points(raw, name="raw") * asa_factors(asa)
