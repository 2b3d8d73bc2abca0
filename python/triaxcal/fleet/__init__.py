"""Many boards and many recordings.

* :mod:`~triaxcal.fleet.batch` -- the production line: fit every board's session, judge it
  against documented limits (:class:`Limits`), write its calibration and ``summary.csv``
  (``triaxcal batch``).
* :mod:`~triaxcal.fleet.dask` (also importable as ``triaxcal.dask``) -- the same fits over
  Dask collections, on whatever scheduler the user has (needs ``pip install 'triaxcal[dask]'``).

Free-living auto-calibration of wearable accelerometers (van Hees et al. 2014) is a method:
:mod:`triaxcal.methods.autocal`.
"""

from __future__ import annotations

from .batch import REASONS, BoardResult, Limits, batch_fit, batch_request, judge

__all__ = [
    "REASONS",
    "BoardResult",
    "Limits",
    "batch_fit",
    "batch_request",
    "judge",
]
