"""triaxcal: calibrate three-axis accelerometers, gyroscopes and magnetometers.

Fits run in Rust (``triaxcal._core``), large ones with the GIL released; capture, export and
the CLI are Python. Calibrated readings are ``(raw - offset) @ matrix.T``: the matrix *multiplies*.
"""

from . import sim
from ._core import __version__
from .calibration.alignment import Alignment
from .calibration.diff import CalibrationDiff, compare
from .calibration.file import Calibration
from .calibration.part import SensorCalibration, TemperatureTerms
from .calibration.parts import (
    fold_asa,
    part_from_center,
    part_from_gyro_gains,
    part_from_temperature,
    part_from_tilt_rig,
)
from .conventions import rotations
from .detect import (
    Pose,
    PoseDetection,
    PoseDetector,
    Rejection,
    StillDetection,
    detect_poses,
    detect_still,
    still_intervals,
)
from .detect.session import PoseSettings, session_poses
from .errors import CalibrationError, DegenerateDataError, NonFiniteError, TooFewPointsError
from .export import (
    adafruit_calib_json,
    ardupilot_parm,
    c_fixed_header,
    c_header,
    decode_motioncal,
    encode_motioncal,
    js_module,
    kalibr_imu_yaml,
    motioncal_packet,
    px4_params_file,
    write_outputs,
)
from .fit.ellipsoid import (
    MODELS,
    BatchFit,
    Descent,
    EllipsoidFit,
    LinearSphere,
    descend_center,
    fit_batch,
    fit_ellipsoid,
    fit_sphere,
    fit_sphere_linear,
    grid_center,
    sphere_error,
)
from .fit.select import AutoFit, RobustFit, fit_auto, fit_robust
from .io.logs import read_log
from .io.recording import LogRecording, Stream
from .io.tables import Table, read_table
from .methods.alignment import (
    AlignmentWarning,
    MagAccelAlignment,
    align_mag_accel,
    axis_heading,
    heading_errors,
)
from .methods.allan import AllanAccumulator, AllanDeviation, allan
from .methods.autocal import AutoCalibration, autocalibrate
from .methods.bootstrap import BootstrapIntervals, bootstrap
from .methods.field import ExpectedField, expected_field
from .methods.gyro import (
    GyroBias,
    GyroGains,
    Rotation,
    TurntableFit,
    find_rotations,
    fit_turntable,
    gyro_bias,
    gyro_gains,
)
from .methods.imu import (
    ImuCalibration,
    SweepStep,
    TriadCalibration,
    calibrate_imu,
)
from .methods.noise import AxisNoise, NoiseFigures, kalibr_noise, noise_figures, plot_allan
from .methods.static import (
    FerrarisCalibration,
    SixPosition,
    TiltRig,
    ferraris,
    six_position,
    tilt_rig,
)
from .methods.temperature import TemperatureModel, TemperatureRangeWarning, fit_temperature
from .methods.yaw import YawCalibration, fit_yaw
from .report import QualityReport, plot_report, quality_report

__all__ = [
    "AllanAccumulator",
    "AllanDeviation",
    "AxisNoise",
    "BootstrapIntervals",
    "CalibrationDiff",
    "NoiseFigures",
    "allan",
    "bootstrap",
    "compare",
    "kalibr_noise",
    "noise_figures",
    "plot_allan",
    "PoseSettings",
    "session_poses",
    "fold_asa",
    "part_from_center",
    "part_from_gyro_gains",
    "part_from_temperature",
    "part_from_tilt_rig",
    "js_module",
    "YawCalibration",
    "fit_yaw",
    "Alignment",
    "AlignmentWarning",
    "MagAccelAlignment",
    "align_mag_accel",
    "axis_heading",
    "heading_errors",
    "rotations",
    "ExpectedField",
    "expected_field",
    "LogRecording",
    "Stream",
    "adafruit_calib_json",
    "ardupilot_parm",
    "kalibr_imu_yaml",
    "px4_params_file",
    "read_log",
    "read_table",
    "Table",
    "fit_temperature",
    "TemperatureRangeWarning",
    "TemperatureModel",
    "tilt_rig",
    "six_position",
    "ferraris",
    "TiltRig",
    "SixPosition",
    "FerrarisCalibration",
    "calibrate_imu",
    "TriadCalibration",
    "SweepStep",
    "ImuCalibration",
    "gyro_gains",
    "gyro_bias",
    "fit_turntable",
    "find_rotations",
    "TurntableFit",
    "Rotation",
    "GyroGains",
    "GyroBias",
    "TemperatureTerms",
    "SensorCalibration",
    "Calibration",
    "MODELS",
    "BatchFit",
    "CalibrationError",
    "DegenerateDataError",
    "Descent",
    "EllipsoidFit",
    "LinearSphere",
    "NonFiniteError",
    "Pose",
    "PoseDetection",
    "PoseDetector",
    "Rejection",
    "StillDetection",
    "TooFewPointsError",
    "__version__",
    "descend_center",
    "detect_poses",
    "detect_still",
    "fit_batch",
    "fit_ellipsoid",
    "fit_sphere",
    "fit_sphere_linear",
    "grid_center",
    "sim",
    "sphere_error",
    "still_intervals",
    "AutoFit",
    "QualityReport",
    "RobustFit",
    "c_fixed_header",
    "c_header",
    "decode_motioncal",
    "encode_motioncal",
    "fit_auto",
    "fit_robust",
    "motioncal_packet",
    "plot_report",
    "quality_report",
    "write_outputs",
    "AutoCalibration",
    "autocalibrate",
]
