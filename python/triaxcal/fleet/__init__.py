"""Many boards and many recordings.

* :mod:`~triaxcal.fleet.batch` -- the production line: fit every board's session, judge it
  against documented limits (:class:`Limits`), write its calibration and ``summary.csv``
  (``triaxcal batch``).
* :mod:`~triaxcal.fleet.dask` (also importable as ``triaxcal.dask``) -- the same fits over
  Dask collections, on whatever scheduler the user has (needs ``pip install 'triaxcal[dask]'``).
* :mod:`~triaxcal.methods.autocal` -- free-living auto-calibration of wearable accelerometers
  (van Hees et al. 2014), streamed over recordings larger than memory.
"""

from __future__ import annotations

from ..methods.autocal import (
    AutoCalibration,
    StillWindows,
    WindowStats,
    autocalibrate,
    fit_still_windows,
)
from .batch import REASONS, BoardResult, Limits, batch_fit, fit_options, judge

__all__ = [
    "REASONS",
    "AutoCalibration",
    "BoardResult",
    "Limits",
    "StillWindows",
    "WindowStats",
    "autocalibrate",
    "batch_fit",
    "fit_options",
    "fit_still_windows",
    "judge",
]
