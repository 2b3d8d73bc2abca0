"""Stationary detection: find the still poses in a stream of three-axis readings.

Two detectors, both vectorised over numpy arrays (millions of samples per second):

* :func:`detect_poses` / :class:`PoseDetector` -- the window method of the sphere-centre note,
  extended to every sensor on the board. Consecutive windows of ``window`` samples are
  averaged; a window is *steady* when no sensor says the board moved:

  - accelerometer: every axis of its window mean changed by at most ``threshold`` from the
    previous window's (the original method's rule, 0.07 g);
  - gyroscope (``gyro_columns``): every axis of its window-mean rate is within
    ``gyro_threshold`` of the rate at the last still window (the bias), and changed by at
    most that much from the previous window -- this sees the twists about the vertical that
    leave the accelerometer unchanged. The first bias is provisional (a twist at the start of a
    recording looks still to the accelerometer): it is confirmed when the board rests at it
    again after a move, and replaced by a rate the board rests at after different moves (see
    :data:`REANCHOR_WINDOWS`);
  - magnetometer (``mag_columns``): every axis of its window mean changed by at most
    ``mag_threshold`` from the previous window's.

  Without explicit thresholds the gyroscope's and magnetometer's are learnt from the sensors'
  own noise (see :data:`NOISE_Z`). A run of steady windows is a candidate pose; its mean is
  registered as a point unless the candidate is rejected as "too short", "too noisy" or "too
  close to an earlier pose" (close in the accelerometer *and* in the magnetometer, when it is
  used). After each registered pose, ``holdoff_samples`` samples are ignored (the original method's
  2-second pause after its beep). The offline function and the online detector share one
  state machine, so they register the same poses on the same data however the stream is cut
  into chunks.
* :func:`still_intervals` / :func:`detect_still` -- the variance detector of imu_tk (Tedaldi,
  Pretto, Menegatti, ICRA 2014): the magnitude of the per-axis variance over a sliding window
  of ``window_s`` seconds is compared with ``k`` times the same quantity measured over an
  initial rest period of ``rest_s`` seconds.

Indices are sample indices into the array given (or into the whole stream, online); ``end`` is
exclusive, Python-slice style.
"""

from __future__ import annotations

from ._segmenter import (
    BIAS_WINDOWS,
    NOISE_MIN_WINDOWS,
    NOISE_WINDOWS,
    NOISE_Z,
    REANCHOR_MAX,
    REANCHOR_WINDOWS,
    TOO_CLOSE,
    TOO_NOISY,
    TOO_SHORT,
    Pose,
    PoseDetection,
    Rejection,
)
from .poses import PoseDetector, detect_poses
from .session import PoseSettings, session_poses
from .still import StillDetection, detect_still, still_intervals

#: The public names (``triaxcal.__all__`` gathers them); the detector's tuning constants above
#: stay importable from here.
__all__ = [
    "Pose",
    "PoseDetection",
    "PoseDetector",
    "PoseSettings",
    "Rejection",
    "StillDetection",
    "detect_poses",
    "detect_still",
    "session_poses",
    "still_intervals",
]
