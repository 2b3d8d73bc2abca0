"""Every physical bound and quality threshold, in one place.

The Rust core checks its fits against its own bounds (``rust/bounds.rs``); they are read from
the compiled module here (:data:`CORE`), not written again. The bounds the Python side adds --
what the validity gate (:mod:`triaxcal.calibration.gate`) refuses, what the report warns about
-- are below, each with the reason for its value. Where an autopilot applies the same kind of
check, its bound is used and cited, so that a calibration triaxcal accepts is one the autopilot
accepts too.
"""

from __future__ import annotations

from types import MappingProxyType
from typing import Any

from .._checks import options as _options
from .._core import BOUNDS as _CORE_BOUNDS
from ..conventions.units import STANDARD_GRAVITY, UNITS
from ..errors import CalibrationError

__all__ = [
    "ADC_MIDSCALE_COUNTS",
    "ATTITUDE_MAX_RESIDUAL_PCT",
    "ATTITUDE_MIN_SCATTER_GAIN",
    "ATTITUDE_TOLERANCE",
    "CORE",
    "DIE_TEMPERATURE_C",
    "GYRO_SATURATION_COUNTS",
    "LOW_COVERAGE_PCT",
    "MAX_ACCEL_OFFSET_G",
    "MAX_CLOCK_STEP_BACK_S",
    "MAX_COMPASS_OFFSET_MG",
    "MAX_HARD_IRON_TO_FIELD",
    "MAX_MEAN_DIRECTION",
    "MAX_RESIDUAL_PCT",
    "MAX_TIME_GAP_SHARE",
    "MAX_YAW_HEADING_GAP_DEG",
    "MIN_COVERAGE_PCT",
    "MIN_DIRECTION_SPREAD",
    "PHYSICAL_DIAG",
    "PLAUSIBLE_RADIUS",
    "REST_FLOOR",
    "REST_HORIZON_S",
    "REST_MAX_CHANGE_SIGMAS",
    "REST_MAX_WINDOW_SAMPLES",
    "REST_MIN_WINDOW_SAMPLES",
    "REST_WHITE_CORRELATION",
    "REST_WINDOW_S",
    "SAMPLE_RATE_HZ",
    "STRENGTH_TOLERANCE",
    "implausible_radius",
    "sample_rate",
]

#: The core's bounds (``rust/bounds.rs``) by name: ``MAX_AXIS_RATIO`` (largest ratio between
#: the largest and smallest gain), ``MAX_UNCONVERGED_OFFSET_SE``, ``WARN_OFFSET_SE``,
#: ``WARN_RMS_FRACTION``, ``WARN_MIN_SPREAD``, ``EMPTY_FACE``.
CORE = MappingProxyType(dict(_CORE_BOUNDS))

# ------------------------------------------------------------------------------ the sphere

#: Share of the sphere's 24 equal-area cells below which a fit gets a coverage warning, and
#: the default pass/fail limit of ``triaxcal batch`` (%).
LOW_COVERAGE_PCT = 50.0

#: Least share of the 24 cells (%) a fit needs to determine its model, per model: the sphere
#: (offset and one scale) is determined by readings round a cap of the sphere's directions;
#: three gains need the six faces (6 of 24 cells: 25 %), cross-axis terms as much again.
MIN_COVERAGE_PCT = MappingProxyType({"sphere": 0.0, "axis": 25.0, "full": 25.0})

#: A fit is not a calibration when its calibrated directions all lie within a cap this small:
#: the length of their mean unit vector (0 for readings all round the sphere, 1 for one point;
#: 0.9 is a cap of about 37 deg radius) ...
MAX_MEAN_DIRECTION = 0.9
#: ... or in a band this thin: the smallest eigenvalue of mean(d d^T) (1/3 for readings all
#: round the sphere or the six faces, 0 for a ring about one axis).
MIN_DIRECTION_SPREAD = 0.02

# ------------------------------------------------------------------------------ the fit

#: Residual RMS (% of the radius) above which the readings do not lie on the fitted surface at
#: all and the fit is not a calibration: the core warns from the same value
#: (``WARN_RMS_FRACTION``). MEMS noise and unmodelled distortion stay at a few percent (the real
#: sessions the tests use: 1.3-6 %), a sphere fitted to strong soft iron at about 15 %.
MAX_RESIDUAL_PCT = 100.0 * CORE["WARN_RMS_FRACTION"]

#: Gains (``diag``) a part may have when its raw and calibrated units measure the same quantity
#: (a log's m/s^2 to m/s^2, mG to uT): ArduPilot's acceptance bounds, AccelCalibrator.cpp
#: ``accept_result()`` (0.8 to 1.2) and CompassCalibrator.cpp ``fit_acceptable()`` (0.2 to
#: 5.0), applied to the gain with the unit conversion taken out.
PHYSICAL_DIAG = MappingProxyType({"accel": (0.8, 1.2), "mag": (0.2, 5.0), "gyro": (0.8, 1.2)})

#: Largest accelerometer offset, in g (calibrated): ArduPilot's AccelCalibrator.cpp
#: ``accept_result()`` refuses an offset above GRAVITY_MSS on any axis. MEMS zero-g offsets are
#: tens of mg (MPU-6050: +-50 mg on X/Y, +-80 mg on Z).
MAX_ACCEL_OFFSET_G = 1.0

#: Zero codes of offset-binary ADCs (unsigned output, 0 g at mid-scale ``2**(bits - 1)``) of 8
#: to 24 bits: an accelerometer in raw counts whose offsets all lie near one of them (the Xsens
#: MTi of imu_tk's recording: 33123, 33276, 32360 counts, zero at 32768) has its offset judged
#: from that code, not from 0.
ADC_MIDSCALE_COUNTS = tuple(float(2 ** (bits - 1)) for bits in range(8, 25))

#: Largest compass offset ArduPilot accepts by default, mG (``COMPASS_OFFS_MAX``, 1800;
#: CompassCalibrator.cpp ``fit_acceptable()``), per axis.
MAX_COMPASS_OFFSET_MG = 1800.0

#: Largest hard iron relative to the field, for a magnetometer whose calibrated unit is not a
#: field unit: ``COMPASS_OFFS_MAX`` (1800 mG) over the 500 mG of a typical field.
MAX_HARD_IRON_TO_FIELD = MAX_COMPASS_OFFSET_MG / 500.0

# ------------------------------------------------------------------------------ the gyroscope

#: Raw gyro reading (counts, magnitude) taken as saturated: 99.5 % of a signed 16-bit
#: register's full scale (32767), where every MEMS gyro the methods meet clips. A turn that reached
#: it was integrated short, and its gain reads low (``triaxcal gyro-gains`` says so).
GYRO_SATURATION_COUNTS = 32767 * 0.995

# ------------------------------------------------------------------------------ radius, field

#: Magnitudes a calibrated reading can have on Earth, per sensor, in the base unit of its
#: quantity (m/s^2, uT), with the words that explain the range. Local gravity is 9.76-9.84
#: m/s^2 (poles to equator, sea level to high mountains); the geomagnetic field at the
#: surface is 25-65 uT (World Magnetic Model), wider indoors near steel.
PLAUSIBLE_RADIUS = MappingProxyType({
    "accel": (0.95 * STANDARD_GRAVITY, 1.05 * STANDARD_GRAVITY,
              "gravity is about 1 g (9.81 m/s^2) everywhere on Earth"),
    "mag": (20.0, 70.0, "the Earth's field is 25-65 uT at the surface"),
})

#: Relative difference between the field strength the readings show and the World Magnetic
#: Model's above which a warning says the surroundings distort the field.
STRENGTH_TOLERANCE = 0.10

# ------------------------------------------------------------------------------ yaw-only

#: Widest arc of headings (deg) a yaw-only calibration may leave unvisited: beyond it the
#: horizontal ellipse is not determined (poses every 20 deg leave 20 deg gaps; a vehicle that
#: turned a full circle leaves a few degrees).
MAX_YAW_HEADING_GAP_DEG = 45.0

# ------------------------------------------------------------------------------ flight (attitude)

#: Largest standard error a flight calibration (:mod:`triaxcal.methods.attitude`) may leave on a
#: parameter it reports as determined: offsets and the interference's largest effect 2 % of the
#: field (a tenth of the 20 % hard iron a bad compass carries, and about 1 deg of heading);
#: soft-iron terms 0.02 (ArduPilot's calibrator accepts ``|ODI| < 1``; 0.02 changes the field by
#: 2 %); a fitted field's components 3.5 % of the field (2 deg of its direction; the WMM's
#: declination is good to about 0.5 deg).
ATTITUDE_TOLERANCE = MappingProxyType({
    "offset_of_field": 0.02,
    "interference_of_field": 0.02,
    "soft_iron": 0.02,
    "field_of_field": 0.035,
})

#: Residual RMS (% of the field) above which the field did not hold still during the flight (or
#: the attitude does not belong to the compass): the fit is not a calibration. A good flight
#: leaves 2-5 % (the attitude's own error of 1-2 deg is 2-3 % of the field).
ATTITUDE_MAX_RESIDUAL_PCT = 12.0

#: How much a flight calibration must shrink the scatter of the field turned to NED by the
#: logged attitude, on readings it was not fitted to, against what the log's own calibration
#: gives, before it counts as an improvement (factor).
ATTITUDE_MIN_SCATTER_GAIN = 2.0


def implausible_radius(sensor: str, value: float, unit: str) -> str | None:
    """A warning when ``value`` ``unit`` cannot be the magnitude of ``sensor`` readings on
    Earth (see :data:`PLAUSIBLE_RADIUS`), else ``None``. Units of another quantity raise
    :class:`CalibrationError`; raw units (counts) and the gyroscope are not judged.

    >>> implausible_radius("mag", 48.0, "uT") is None
    True
    >>> for line in implausible_radius("mag", 48.0, "mT").split(": "):
    ...     print(line)
    a magnetometer radius of 48 mT (48000 uT) is not plausible
    the Earth's field is 25-65 uT at the surface; did you mean 48 uT?
    """
    if unit not in UNITS:
        return None
    quantity, factor = UNITS[unit]
    names = {"accel": "an acceleration", "gyro": "a rotation rate", "mag": "a magnetic field"}
    if sensor in names and quantity != sensor:
        raise CalibrationError(
            f"a radius in {unit} is {names[quantity]}, but the {sensor} sensor measures "
            f"{names[sensor]}: give the radius in its units"
        )
    limits = PLAUSIBLE_RADIUS.get(sensor)
    if limits is None:
        return None
    lo, hi, why = limits
    base = value * factor
    if lo <= base <= hi:
        return None
    ref = "g" if quantity == "accel" else "uT"
    conv = "" if unit == ref else f" ({base / UNITS[ref][1]:.6g} {ref})"
    hint = ""
    for cand in ("g", "m/s^2") if quantity == "accel" else ("uT", "nT", "mT", "gauss", "mG"):
        if cand != unit and lo <= value * UNITS[cand][1] <= hi:
            hint = f"; did you mean {value:g} {cand}?"
            break
    what = "an accelerometer" if sensor == "accel" else "a magnetometer"
    return f"{what} radius of {value:g} {unit}{conv} is not plausible: {why}{hint}"


# ------------------------------------------------------------------------------ at rest (noise)

#: The at-rest test of ``triaxcal noise`` (:mod:`triaxcal.methods.rest`) averages the readings
#: over windows of this many seconds ...
REST_WINDOW_S = 1.0
#: ... of at least this many samples (a log at a few Hz gets longer windows) ...
REST_MIN_WINDOW_SAMPLES = 8
#: ... and at most this many: a stream faster than 1 kHz gets shorter windows (at 4 kHz,
#: 0.26 s), still long beside a sensor's filter -- the noise estimate needs 8 blocks of up to 128
#: samples in a window -- and short beside a hand's motion. The demo's session, whose host time
#: runs 40 times faster than its simulated board, gets 12 windows instead of 3, and its
#: gyroscope's change is 30 times what rest allows instead of 1.2 times.
REST_MAX_WINDOW_SAMPLES = 1024
#: It compares every window mean with those of the windows up to this many seconds before it:
#: a hand moving or turning the board changes the mean within seconds, while a sensor at rest
#: changes its bias by far less than its noise in this time (temperature drift and random walk
#: show over minutes to hours), so a long log's drift is not taken for motion.
REST_HORIZON_S = 10.0
#: A window mean may change by this many times the noise of a window mean (the norm over the
#: three axes; see :data:`REST_WHITE_CORRELATION` for how the noise is estimated). At rest the
#: largest change is a few times the noise: 2.5 to 5.4 on the real recordings at rest (PX4
#: ``sample_log_small.ulg``, the three ``sunsided unmoved-*``, the first 45 s of the imu_tk
#: Xsens log), 4.5 on a simulated day at 100 Hz (white noise, with or without a random walk),
#: 4.3 to 4.9 on a 1 kHz stream through a second-order low-pass filter of 20 to 500 Hz.
#: Moving, it is 33.7 or more (every moving real recording: the bags, the flights, turns, tilts
#: and pans by hand, the turntable; the gyroscopes 49 or more).
REST_MAX_CHANGE_SIGMAS = 20.0
#: The noise of a window mean is extrapolated from the shortest block of samples whose
#: consecutive means look like white noise: the correlation of consecutive differences of block
#: means is -1/2 for white noise and nearer +1 within a low-pass filter's time constant (a 1 kHz
#: stream through a 42 Hz second-order filter: +0.56 for single samples, -0.41 for blocks of
#: 32); at most this, on every axis. When no block length of at most an eighth of a window looks
#: white -- the readings move at every scale, or a stream is sampled over 50 times faster than
#: its filter (1 kHz through 10 Hz) -- single samples are used, which motion disturbs least but
#: which undercount such an oversampled sensor's noise: there the floor below decides.
REST_WHITE_CORRELATION = -0.35
#: ... or by this much, in the base unit of its quantity, when its unit is known (rad/s for a
#: gyroscope, m/s^2 for an accelerometer): a tolerance for sensors quieter than anything that
#: disturbs a bench. 0.01 rad/s (0.57 deg/s) and 0.01 g (0.098 m/s^2, a tilt of 0.6 deg) are
#: about ten times the largest change seen at rest (0.0012 rad/s, 0.0024 g) and below the
#: slowest motion in the real recordings (0.29 rad/s panning by hand; 0.039 g in the Phidgets
#: bag, which turns about the vertical, where gravity stays put; 0.15 g otherwise).
REST_FLOOR = MappingProxyType({"gyro": 0.01, "accel": 0.01 * STANDARD_GRAVITY})

#: Temperatures (degC) a sensor's die may report: from absolute zero to 1000 degC (MEMS parts
#: are specified from -40 to 125 degC; anything past these is a wrong column or unit, and
#: near the edge of a double it would overflow the temperature polynomials).
DIE_TEMPERATURE_C = (-273.15, 1000.0)

#: Sample rates (Hz) a recording may have: no inertial sensor is read slower than one sample in
#: 1000 s or faster than 1 MHz. A rate outside is a typo (``--rate-hz 1e300``) or a t column
#: in another unit, and the durations and sums made from it would overflow (a noise model's
#: tau^2 and 1/tau^2, a turn integrated over 1e-300 s steps).
SAMPLE_RATE_HZ = (1e-3, 1e6)


def sample_rate(rate_hz: Any, what: str = "rate_hz") -> float:
    """``rate_hz`` as a float within :data:`SAMPLE_RATE_HZ` (every method that takes a sample
    rate checks it here: a rate near the edge of a double, ``1e-300`` or ``1e300``, would
    overflow the durations and sums made from it).

    >>> sample_rate(100)
    100.0
    >>> sample_rate(1e300)
    Traceback (most recent call last):
    ...
    triaxcal.CalibrationError: rate_hz must be a finite number in [0.001, 1e+06], got 1e+300 (a \
sample rate in Hz: no inertial sensor is read slower than one sample in 1000 s or faster than \
1 MHz)
    """
    lo, hi = SAMPLE_RATE_HZ
    return _options.number(rate_hz, what, ge=lo, le=hi,
                           hint="a sample rate in Hz: no inertial sensor is read slower than "
                                f"one sample in {1 / lo:g} s or faster than {hi / 1e6:g} MHz")

#: A session's time stamps (host time) may step back this far (s) when the host's clock is
#: corrected (NTP slews and steps by milliseconds); a t column that goes back further is not
#: the time of the rows.
MAX_CLOCK_STEP_BACK_S = 1.0

#: Share of a session's span that one gap in its time stamps may leave without rows before the
#: noise figures warn that samples were lost (the Allan deviation assumes even sampling).
MAX_TIME_GAP_SHARE = 0.01
