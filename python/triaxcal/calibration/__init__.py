"""Calibrations: the file (one object, validated on load), the parts made by the methods, what
changed between two calibrations, and a recorded session fitted into a part.

* :mod:`~triaxcal.calibration.file` -- :class:`Calibration`, :class:`SensorCalibration`,
  :class:`TemperatureTerms`, :class:`Alignment`; :mod:`~triaxcal.calibration.schema`: what the
  file may hold.
* :mod:`~triaxcal.calibration.parts` -- calibration parts from the methods' results.
* :mod:`~triaxcal.calibration.diff` -- what changed between two calibrations.
* :mod:`~triaxcal.calibration.request` -- what a fit of a recorded session is asked to do
  (:class:`FitRequest`: typed, validated once); :mod:`~triaxcal.calibration.session` -- the fit
  itself, as ``triaxcal fit`` runs it; :mod:`~triaxcal.calibration.store` -- writing a part
  into a file.
* :mod:`~triaxcal.calibration.gate` -- the validity gate every writer and exporter calls.
"""

from .alignment import Alignment
from .diff import CalibrationDiff, compare
from .file import KNOWN_MODELS, SCHEMA, SCHEMA_NAME, SCHEMA_VERSION, SENSORS, Calibration
from .gate import InvalidCalibrationError, Verdict, check_part
from .part import MAX_PREVIOUS, SensorCalibration, TemperatureTerms, sha256_points
from .parts import (
    fold_asa,
    part_from_center,
    part_from_ferraris,
    part_from_gyro_gains,
    part_from_imu,
    part_from_temperature,
    part_from_tilt_rig,
    part_from_turntable,
    part_from_yaw,
)
from .request import FieldOptions, FitRequest, SourceOptions
from .session import FitOutcome, Saved, fit_session, fit_to_file

#: The public names (``triaxcal.__all__`` gathers them); the file's constants (``SCHEMA``,
#: ``SENSORS`` ...) stay importable from here.
__all__ = [
    "Alignment",
    "Calibration",
    "CalibrationDiff",
    "FieldOptions",
    "FitOutcome",
    "FitRequest",
    "InvalidCalibrationError",
    "Saved",
    "SensorCalibration",
    "SourceOptions",
    "TemperatureTerms",
    "Verdict",
    "check_part",
    "compare",
    "fit_session",
    "fit_to_file",
    "fold_asa",
    "part_from_center",
    "part_from_ferraris",
    "part_from_gyro_gains",
    "part_from_imu",
    "part_from_temperature",
    "part_from_tilt_rig",
    "part_from_turntable",
    "part_from_yaw",
]
