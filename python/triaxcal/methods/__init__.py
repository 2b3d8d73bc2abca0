"""Calibration methods beyond the plain ellipsoid fit, one module per idea.

* :mod:`~triaxcal.methods.gyro` -- gyroscope bias at rest, gains by integrating known turns.
* :mod:`~triaxcal.methods.turntable` -- the gyroscope's matrix from turntable plateaus of known
  rate.
* :mod:`~triaxcal.methods.imu` -- multi-position accelerometer + gyroscope calibration without a
  rig (Tedaldi et al. 2014).
* :mod:`~triaxcal.methods.temperature` -- offsets and gains as polynomials in temperature.
* :mod:`~triaxcal.methods.static` -- methods that need no fit: tilt rig, six-position
  min/max, Ferraris closed form.
* :mod:`~triaxcal.methods.allan` -- overlapping Allan deviation, streamed through the Rust core.
* :mod:`~triaxcal.methods.bootstrap` -- bootstrap confidence intervals of fit coefficients.
* :mod:`~triaxcal.methods.noise` -- noise figures (random walks, bias instability) and Kalibr's
  noise keys; :mod:`~triaxcal.methods.rest` -- whether a sensor was at rest;
  :mod:`~triaxcal.methods.noise_file` -- both from a recording (``triaxcal noise``).
* :mod:`~triaxcal.methods.yaw` -- yaw-only magnetometer calibration (turns about the
  vertical, the vertical part from the World Magnetic Model).
* :mod:`~triaxcal.methods.alignment` -- magnetometer-to-accelerometer alignment, mounting
  rotation, dip angle, tilt-compensated heading.
* :mod:`~triaxcal.methods.field` -- the Earth's field from the World Magnetic Model.
* :mod:`~triaxcal.methods.autocal` -- free-living auto-calibration of wearable accelerometers
  (van Hees et al. 2014), streamed over recordings larger than memory.
"""

from .alignment import (
    AlignmentWarning,
    MagAccelAlignment,
    align_mag_accel,
    axis_heading,
    heading_errors,
)
from .allan import AllanAccumulator, AllanDeviation, allan
from .autocal import AutoCalibration, autocalibrate
from .bootstrap import BootstrapIntervals, bootstrap
from .field import ExpectedField, expected_field
from .gyro import (
    GyroBias,
    GyroGains,
    Rotation,
    find_rotations,
    gyro_bias,
    gyro_gains,
)
from .imu import ImuCalibration, SweepStep, TriadCalibration, calibrate_imu
from .noise import AxisNoise, NoiseFigures, kalibr_noise, noise_figures, plot_allan
from .noise_file import NoiseRequest, NoiseResult, noise_from_file
from .rest import NotAtRestError, RestCheck, check_rest
from .static import (
    FerrarisCalibration,
    SixPosition,
    TiltRig,
    ferraris,
    six_position,
    tilt_rig,
)
from .temperature import TemperatureModel, TemperatureRangeWarning, fit_temperature
from .turntable import TurntableFit, fit_turntable
from .yaw import YawCalibration, fit_yaw

__all__ = [
    "AutoCalibration",
    "ExpectedField",
    "autocalibrate",
    "expected_field",
    "AllanAccumulator",
    "AllanDeviation",
    "AxisNoise",
    "BootstrapIntervals",
    "NoiseFigures",
    "NoiseRequest",
    "NoiseResult",
    "NotAtRestError",
    "RestCheck",
    "allan",
    "bootstrap",
    "check_rest",
    "kalibr_noise",
    "noise_figures",
    "noise_from_file",
    "plot_allan",
    "YawCalibration",
    "fit_yaw",
    "AlignmentWarning",
    "MagAccelAlignment",
    "align_mag_accel",
    "axis_heading",
    "heading_errors",
    "FerrarisCalibration",
    "GyroBias",
    "GyroGains",
    "ImuCalibration",
    "Rotation",
    "SixPosition",
    "SweepStep",
    "TemperatureModel",
    "TemperatureRangeWarning",
    "TiltRig",
    "TriadCalibration",
    "TurntableFit",
    "calibrate_imu",
    "ferraris",
    "find_rotations",
    "fit_temperature",
    "fit_turntable",
    "gyro_bias",
    "gyro_gains",
    "six_position",
    "tilt_rig",
]
