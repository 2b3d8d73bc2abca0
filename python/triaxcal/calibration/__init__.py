"""Calibrations: the file (one object, validated on load), the parts made by the methods, what
changed between two calibrations, and a recorded session fitted into a part.

* :mod:`~triaxcal.calibration.file` -- :class:`Calibration`, :class:`SensorCalibration`,
  :class:`TemperatureTerms`, :class:`Alignment`; :mod:`~triaxcal.calibration.schema`: what the
  file may hold.
* :mod:`~triaxcal.calibration.parts` -- calibration parts from the methods' results.
* :mod:`~triaxcal.calibration.diff` -- what changed between two calibrations.
* :mod:`~triaxcal.calibration.session` -- one sensor of a recorded session fitted as
  ``triaxcal fit`` fits it.
"""

from .alignment import Alignment
from .file import KNOWN_MODELS, SCHEMA, SCHEMA_NAME, SCHEMA_VERSION, SENSORS, Calibration
from .part import MAX_PREVIOUS, SensorCalibration, TemperatureTerms, sha256_points

__all__ = [
    "KNOWN_MODELS",
    "MAX_PREVIOUS",
    "SCHEMA",
    "SCHEMA_NAME",
    "SCHEMA_VERSION",
    "SENSORS",
    "Alignment",
    "Calibration",
    "SensorCalibration",
    "TemperatureTerms",
    "sha256_points",
]
