"""``triaxcal.dask``: fits over Dask collections (see :mod:`triaxcal.fleet.dask`).

Needs ``pip install 'triaxcal[dask]'``; importing it without Dask raises a
:class:`~triaxcal.CalibrationError` that names the extra.
"""

from __future__ import annotations

from .fleet.dask import GroupFit, autocalibrate_many, fit_batch, fit_groups

__all__ = ["GroupFit", "autocalibrate_many", "fit_batch", "fit_groups"]
