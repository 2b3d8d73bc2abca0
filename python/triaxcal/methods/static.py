"""Calibration methods that need no fit: tilt rig, six-position min/max, Ferraris closed form.

Error model (per axis unless stated): ``calibrated = (raw - offset) * gain`` where ``gain``
**multiplies** and is in calibrated units per raw unit (g per count, or g per g for a sensor
already in g). :class:`SixPosition` also reports the inverse (raw units per g), the quantity the
min/max method measures directly. The Ferraris method (Ferraris et al. 1995, as in imucal)
gives full 3x3 matrices: ``calibrated = (raw - offset) @ matrix.T``.

Ferraris, and how imucal's names map onto ours (imucal ``FerrarisCalibration.compute`` and
``FerrarisCalibrationInfo._calibrate_acc`` / ``_calibrate_gyr``, mad-lab-fau/imucal 2.6):

* imucal calibrates ``acc_cal = inv(R_a) @ inv(K_a) @ (acc - b_a)``, so
  ``accel.offset = b_a`` and ``accel.matrix = inv(R_a) @ inv(K_a) = inv(K_a @ R_a)``;
  ``K_a @ R_a`` (raw units per unit of ``gravity``; column i = response to +1 along i) is
  ``inv(accel.matrix)``, and ``K_a`` (diagonal) holds its row norms, ``accel_counts_per_g``
  divided by ``gravity``.
* ``gyr_cal = inv(R_g) @ inv(K_g) @ (gyr - b_g - K_ga @ acc_cal)`` in deg/s, so
  ``gyro.offset = b_g``, ``g_sensitivity = K_ga`` and
  ``gyro.matrix = inv(R_g) @ inv(K_g) * pi / 180`` (ours is in rad/s). imucal's
  ``expected_angle`` is signed (-360 by default: a clockwise turn); ours is the size of the turn
  and the sense is read from the data (``rotation_sign``), so imucal with
  ``expected_angle = rotation_sign * angle_deg`` gives the same matrices.

Tilt rig (the two-tilt method), with the algebra checked: a reading ``s`` taken
with an axis tilted down by ``theta`` and ``s'`` tilted up by ``theta`` see ``+-sin(theta)`` g,
so ``gain * (s - offset) = sin(theta)`` and ``gain * (s' - offset) = -sin(theta)``, giving

    offset = (s + s') / 2,        gain = 2 sin(theta) / |s - s'|.

The published tilt-rig algebra writes ``g = sin(theta) / (s + o)``, i.e. it adds the offset it
should subtract; its
published x and y gains (1.2856, 1.3334) are therefore ~12-15 % too high. The vertical axis sees
``cos(theta)`` in every tilt, so its offset cannot be told from its gain without an upside-down
reading: it is taken as 0 (or given) and ``gain_z = cos(theta) / (mean(s_z) - offset_z)``.

The tilt angle the data imply: if the horizontal and vertical axes have the same gain, the
half-span of the tilted axis over the vertical reading is ``tan(theta)``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._checks import options as opt
from .._checks.arrays import as_samples, finite_result
from ..errors import CalibrationError
from ..io.sections import FERRARIS_SECTIONS, TILT_SECTIONS
from ..quality.bounds import sample_rate
from .imu import TriadCalibration

__all__ = [
    "FerrarisCalibration",
    "SixPosition",
    "TiltRig",
    "ferraris",
    "six_position",
    "tilt_rig",
]

AXES = "xyz"
#: The four tilts (their names, like the Ferraris sections', live where their files are read:
#: :mod:`triaxcal.io.sections`).
TILT_KEYS = TILT_SECTIONS


def _ro(a: Any) -> np.ndarray:
    arr = np.array(a, dtype=np.float64)
    arr.setflags(write=False)
    return arr


def _readings(x: Any, name: str) -> np.ndarray:
    try:
        arr = np.asarray(x) if not isinstance(x, (str, bytes)) else np.asarray([x])
    except (TypeError, ValueError):  # ragged lists: refused below, with what to pass
        return as_samples(x, name)
    if arr.ndim == 1:
        arr = arr[None]
    if arr.ndim == 2 and arr.shape[0] == 0:
        raise CalibrationError(f"{name} must have shape (3,) or (N, 3), got {arr.shape}")
    return as_samples(arr, name, finite=True)


# --- tilt rig -------------------------------------------------------------------------------


@dataclass(frozen=True)
class TiltRig:
    """The result of :func:`tilt_rig`.

    Attributes
    ----------
    offset : ndarray (3,)
        Raw units; ``offset[2]`` is the assumed (given) z offset, not a measurement.
    gain : ndarray (3,)
        g per raw unit, **multiplies**: ``calibrated_g = (raw - offset) * gain``.
    gain_z_pairs : ndarray (2,)
        The z gain from the fore/aft pair and from the left/right pair (they should agree).
    implied_angle_deg : ndarray (2,)
        Tilt angle implied by the fore/aft and the left/right pair (equal gains assumed).
    angle_error_deg : ndarray (2,)
        ``implied - stated``.
    angle_deg : float
        The stated tilt angle.
    """

    offset: np.ndarray
    gain: np.ndarray
    gain_z_pairs: np.ndarray
    implied_angle_deg: np.ndarray
    angle_error_deg: np.ndarray
    angle_deg: float

    def apply(self, raw: Any) -> np.ndarray:
        """Calibrated readings in g: ``(raw - offset) * gain``."""
        return (np.asarray(raw, dtype=np.float64) - self.offset) * self.gain


def tilt_rig(
    readings: Mapping[str, Any], *, angle_deg: float, z_offset: float = 0.0
) -> TiltRig:
    """Offsets and gains from readings on a rig tilted by a known angle (the two-tilt method).

    Parameters
    ----------
    readings : mapping
        ``fore_down``, ``aft_down`` (x axis tilted down / up by ``angle_deg``), ``left_down``,
        ``right_down`` (y axis tilted ...): each a reading (3,) or several (N, 3), in g (or
        counts). Fewer keys: the pair that is complete is used and the error names the rest.
    angle_deg : float
        The rig's tilt, degrees (the first published rig: 10).
    z_offset : float
        Offset of the vertical axis, which these tilts cannot measure (raw units).

    Returns
    -------
    TiltRig

    Examples
    --------
    >>> import numpy as np, triaxcal as tc
    >>> s, c = np.sin(np.radians(10)), np.cos(np.radians(10))
    >>> rig = tc.tilt_rig({"fore_down": [-s + 0.01, 0.02, c], "aft_down": [s + 0.01, 0.02, c],
    ...                    "left_down": [0.01, -s + 0.02, c], "right_down": [0.01, s + 0.02, c]},
    ...                   angle_deg=10)
    >>> rig.offset.round(6).tolist(), rig.gain.round(6).tolist()
    ([0.01, 0.02, 0.0], [1.0, 1.0, 1.0])
    """
    ang = opt.number(angle_deg, "angle_deg", gt=0, lt=90, hint="the rig's tilt in degrees")
    z_off = opt.number(z_offset, "z_offset", hint="raw units")
    if not isinstance(readings, Mapping):
        raise CalibrationError(
            f"readings must be a mapping of {', '.join(TILT_KEYS)} -> readings, got "
            f"{type(readings).__name__}"
        )
    missing = [k for k in TILT_KEYS if k not in readings]
    if missing:
        raise CalibrationError(
            f"tilt readings missing: {', '.join(missing)} (need fore_down and aft_down for x, "
            "left_down and right_down for y)"
        )
    m = {k: _readings(readings[k], k).mean(axis=0) for k in TILT_KEYS}
    th = np.radians(ang)
    offset = np.zeros(3)
    gain = np.zeros(3)
    implied = np.zeros(2)
    gz = np.zeros(2)
    for j, (down, up) in enumerate((("fore_down", "aft_down"), ("left_down", "right_down"))):
        s, s2 = m[down], m[up]
        span = abs(s[j] - s2[j]) / 2
        if span <= 0:
            raise CalibrationError(
                f"{down} and {up} read the same on {AXES[j]}: the rig was not tilted; tilt it by "
                f"{ang:g} deg one way and then the other"
            )
        offset[j] = (s[j] + s2[j]) / 2
        gain[j] = np.sin(th) / span
        zmean = 0.5 * (s[2] + s2[2]) - z_off
        if zmean == 0:
            raise CalibrationError("the vertical axis reads zero: is z pointing up on the rig?")
        gz[j] = np.cos(th) / zmean
        # the other horizontal axis may change a little too (the rig is not square to the
        # sensor): the tilt is the whole horizontal half-span over the vertical reading
        k = 1 - j
        horiz = np.hypot(span, abs(s[k] - s2[k]) / 2)
        implied[j] = np.degrees(np.arctan2(horiz, abs(zmean)))
    offset[2] = z_off
    gain[2] = gz.mean()
    return TiltRig(
        offset=_ro(offset),
        gain=_ro(gain),
        gain_z_pairs=_ro(gz),
        implied_angle_deg=_ro(implied),
        angle_error_deg=_ro(implied - ang),
        angle_deg=ang,
    )


# --- six-position min/max ---------------------------------------------------------------------


@dataclass(frozen=True)
class SixPosition:
    """The result of :func:`six_position`.

    Attributes
    ----------
    offset : ndarray (3,)
        ``(max + min) / 2`` per axis, raw units.
    counts_per_g : ndarray (3,)
        ``(max - min) / 2`` per axis: raw units per g (divides).
    matrix : ndarray (3, 3)
        ``diag(gravity / counts_per_g)``: multiplies, ``calibrated = (raw - offset) @ matrix.T``
        in the units of ``gravity``.
    faces : dict
        Index of the pose used for each face (``"+x"``, ``"-x"``, ...).
    """

    offset: np.ndarray
    counts_per_g: np.ndarray
    matrix: np.ndarray
    faces: dict

    def apply(self, raw: Any) -> np.ndarray:
        """``(raw - offset) @ matrix.T``."""
        return (np.asarray(raw, dtype=np.float64) - self.offset) @ self.matrix.T


def six_position(points: Any, *, gravity: float = 1.0) -> SixPosition:
    """Offset and gain per axis from the six faces of a cube (min/max method).

    Parameters
    ----------
    points : array_like (M, 3), M >= 6
        Still-pose means (e.g. :attr:`PoseDetection.points`) including each axis pointing up
        and down. For each axis the largest and smallest reading are used.
    gravity : float
        Magnitude calibrated readings should have (1.0 for g, 9.80665 for m/s^2).

    Raises
    ------
    CalibrationError
        If a face is missing: the message names it (e.g. "-y (y axis pointing down)").

    Examples
    --------
    >>> import triaxcal as tc
    >>> faces = [[16500, 10, 0], [-16300, 10, 0], [100, 16484, 0], [100, -16284, 0],
    ...          [100, 10, 16600], [100, 10, -16000]]
    >>> six = tc.six_position(faces)
    >>> six.offset.tolist(), six.counts_per_g.tolist()
    ([100.0, 100.0, 300.0], [16400.0, 16384.0, 16300.0])
    """
    p = _readings(points, "points")
    grav = opt.magnitude(gravity, "gravity", hint="1.0 for g, 9.80665 for m/s^2")
    if p.shape[0] < 6:
        raise CalibrationError(f"six_position needs the six faces, got {p.shape[0]} poses")
    hi, lo = p.max(axis=0), p.min(axis=0)
    center = 0.5 * (hi + lo)
    d = p - center
    dom = np.argmax(np.abs(d), axis=1)
    faces = {}
    missing = []
    for i in range(3):
        for sign, name in ((1, "+"), (-1, "-")):
            cand = np.flatnonzero((dom == i) & (np.sign(d[:, i]) == sign))
            if cand.size == 0:
                word = "up" if sign > 0 else "down"
                missing.append(f"{name}{AXES[i]} ({AXES[i]} axis pointing {word})")
            else:
                faces[f"{name}{AXES[i]}"] = int(cand[np.argmax(sign * d[cand, i])])
    if missing:
        raise CalibrationError(
            f"faces missing: {', '.join(missing)}; place the sensor on each of its six sides"
        )
    top = np.array([p[faces[f"+{a}"], i] for i, a in enumerate(AXES)])
    bot = np.array([p[faces[f"-{a}"], i] for i, a in enumerate(AXES)])
    off = (top + bot) / 2
    cpg = (top - bot) / 2
    _spans(cpg, np.abs(p).max(), "the six faces")
    return SixPosition(_ro(off), _ro(cpg), _ro(np.diag(grav / cpg)), faces)


def _spans(span: np.ndarray, size: float, what: str) -> None:
    """Refuse a response ``span`` (raw units per unit, per axis or the singular values of a
    matrix) that is zero or lost in the round-off of readings of ``size``: ``what`` does not
    tell the axes apart (a reading repeated, or poses mislabelled)."""
    if not (np.all(span > 1e-9 * size) and np.all(span >= opt.MAGNITUDE[0])):
        raise CalibrationError(
            f"{what} do not span three axes (their responses "
            f"{[float(f'{v:.3g}') for v in np.asarray(span)]} are zero or lost in the readings' "
            "round-off): check that each pose or turn is about the axis it is labelled with, "
            "and that the readings change between them")


# --- Ferraris closed form ---------------------------------------------------------------------


@dataclass(frozen=True)
class FerrarisCalibration:
    """The result of :func:`ferraris`.

    Attributes
    ----------
    accel : TriadCalibration
        ``(acc - offset) @ matrix.T`` in the units of ``gravity``.
    gyro : TriadCalibration
        ``(gyro - offset - g_sensitivity @ acc_cal) @ matrix.T`` in rad/s.
    g_sensitivity : ndarray (3, 3)
        Gyro counts per unit of calibrated acceleration (linear-acceleration sensitivity).
    accel_counts_per_g : ndarray (3,)
        Row norms of ``inv(accel.matrix)`` times ``gravity``: raw units per g (imucal's
        ``diag(K_a)`` times ``gravity``).
    gyro_counts_per_dps : ndarray (3,)
        Row norms of ``inv(gyro.matrix)`` in raw units per deg/s (imucal's ``diag(K_g)``).
    rotation_sign : ndarray (3,)
        The sense (+1 ccw, -1 cw) assumed for each 360 deg turn, chosen so that the diagonal
        of the gyro matrix is positive (the recordings do not say which way they turned).
    """

    accel: TriadCalibration
    gyro: TriadCalibration
    g_sensitivity: np.ndarray
    accel_counts_per_g: np.ndarray
    gyro_counts_per_dps: np.ndarray
    rotation_sign: np.ndarray

    def apply_gyro(self, gyro: Any, acc: Any) -> np.ndarray:
        """Calibrated rates (rad/s), removing the linear-acceleration sensitivity."""
        a = self.accel.apply(acc)
        return (np.asarray(gyro, dtype=np.float64) - self.gyro.offset
                - a @ self.g_sensitivity.T) @ self.gyro.matrix.T


def ferraris(
    sections: Mapping[str, tuple[Any, Any]],
    *,
    rate_hz: float,
    gravity: float = 9.81,
    angle_deg: float = 360.0,
) -> FerrarisCalibration:
    """Closed-form Ferraris calibration from six static faces and three full turns.

    Parameters
    ----------
    sections : mapping of name -> (acc (N, 3), gyro (N, 3))
        ``x_p, x_a, y_p, y_a, z_p, z_a``: still, that axis pointing up (``_p``, accelerometer
        reads +1 g) and down (``_a``); ``x_rot, y_rot, z_rot``: a turn of ``angle_deg`` about
        that axis (uniformly sampled; the whole section is integrated).
    rate_hz : float
        Sampling rate, Hz.
    gravity : float
        Local gravity in the units wanted for the accelerometer.
    angle_deg : float
        Size of each turn, degrees (> 0); the sense of turning is found from the data and
        reported as :attr:`FerrarisCalibration.rotation_sign`.

    Returns
    -------
    FerrarisCalibration
        Equal to imucal's ``FerrarisCalibration(grav=gravity, expected_angle=rotation_sign *
        angle_deg)`` (see the module notes for the names). The accelerometer offset of each
        axis comes from the two poses with that axis vertical (Ferraris eq. 20); the gyro
        offset is the mean over all six static poses; the Earth's rotation is ignored.

    Examples
    --------
    A simulated sensor: offset (10, -20, 30) counts, 2048 counts per g, 16.4 counts per deg/s.

    >>> import numpy as np, triaxcal as tc
    >>> g, n = 9.81, 200
    >>> off, cpg, cpd = np.array([10.0, -20.0, 30.0]), 2048.0, 16.4
    >>> still = lambda v: (np.tile(off + cpg * np.array(v), (n, 1)), np.zeros((n, 3)))
    >>> spin = lambda i: (np.tile(off + cpg * np.eye(3)[i], (n, 1)),
    ...                   np.tile(cpd * 360 / (n / 100) * np.eye(3)[i], (n, 1)))
    >>> sec = {"x_p": still([1, 0, 0]), "x_a": still([-1, 0, 0]), "y_p": still([0, 1, 0]),
    ...        "y_a": still([0, -1, 0]), "z_p": still([0, 0, 1]), "z_a": still([0, 0, -1]),
    ...        "x_rot": spin(0), "y_rot": spin(1), "z_rot": spin(2)}
    >>> fer = tc.ferraris(sec, rate_hz=100.0, gravity=g)
    >>> fer.accel.offset.tolist(), fer.accel_counts_per_g.round(6).tolist()
    ([10.0, -20.0, 30.0], [2048.0, 2048.0, 2048.0])
    >>> fer.gyro_counts_per_dps.round(6).tolist(), fer.rotation_sign.tolist()
    ([16.4, 16.4, 16.4], [1.0, 1.0, 1.0])
    """
    if not isinstance(sections, Mapping):
        raise CalibrationError(
            f"sections must be a mapping of name -> (acc, gyro), got {type(sections).__name__}"
        )
    missing = [k for k in FERRARIS_SECTIONS if k not in sections]
    if missing:
        poses = [k for k in missing if not k.endswith("_rot")]
        rots = [k for k in missing if k.endswith("_rot")]
        parts = []
        if poses:
            parts.append(f"static poses missing: {', '.join(poses)}")
        if rots:
            parts.append(f"rotations missing: {', '.join(rots)}")
        raise CalibrationError(
            "; ".join(parts) + " (x_p = x axis up, x_a = x axis down, x_rot = a full turn about x)"
        )
    rate = sample_rate(rate_hz)
    grav = opt.magnitude(gravity, "gravity", hint="9.81 for m/s^2, 1.0 for g")
    ang = opt.magnitude(angle_deg, "angle_deg", hint="the size of each turn; the sense "
                        "is read from the data")
    for k in FERRARIS_SECTIONS:
        if isinstance(sections[k], (str, bytes)) or len(sections[k]) != 2:
            raise CalibrationError(f"sections[{k!r}] must be a pair (acc (N, 3), gyro (N, 3))")
    acc = {k: _readings(sections[k][0], f"{k} acc") for k in FERRARIS_SECTIONS}
    gyr = {k: _readings(sections[k][1], f"{k} gyro") for k in FERRARIS_SECTIONS}
    for k in FERRARIS_SECTIONS:
        if acc[k].shape != gyr[k].shape:
            raise CalibrationError(f"{k}: acc and gyro have different lengths")
    static = FERRARIS_SECTIONS[:6]
    up = np.column_stack([acc[f"{a}_p"].mean(axis=0) for a in AXES])
    down = np.column_stack([acc[f"{a}_a"].mean(axis=0) for a in AXES])
    # Offset of axis i from the two poses in which axis i is vertical (Ferraris eq. 20, imucal's
    # ``b_a = diag(B_a)``). Not the mean over all six poses: in the four poses where axis i is
    # horizontal it reads ``offset + g sin(tilt)``, and a hand-held pose is tilted by a degree
    # or two, a first-order error that the up/down pair does not cancel when the two tilts
    # differ (7.7 counts on imucal's annotated session); along the vertical axis the tilt
    # enters as ``g cos(tilt)``, second order, and the up/down pair cancels the offset exactly.
    b_a = np.diag(up + down) / 2
    a_mat = (up - down) / (2 * grav)  # raw per unit; column i = response to +1 unit along i
    size = max(float(np.abs(up).max()), float(np.abs(down).max()))
    _spans(np.linalg.svd(a_mat * grav, compute_uv=False), size, "the six static poses")
    m_a = np.linalg.inv(a_mat)
    accel = TriadCalibration(_ro(b_a), _ro(m_a), "gravity units")
    b_g = np.vstack([gyr[k] for k in static]).mean(axis=0)
    g_up = np.column_stack([gyr[f"{a}_p"].mean(axis=0) for a in AXES])
    g_down = np.column_stack([gyr[f"{a}_a"].mean(axis=0) for a in AXES])
    k_ga = (g_up - g_down) / (2 * grav)
    w = np.zeros((3, 3))
    for i, a in enumerate(AXES):
        cal_a = accel.apply(acc[f"{a}_rot"])
        cor = gyr[f"{a}_rot"] - b_g - cal_a @ k_ga.T
        w[:, i] = cor.sum(axis=0) / rate  # raw * s
    sign = np.sign(np.diag(w))
    sign[sign == 0] = 1
    g_mat = w / (ang * sign)  # raw per deg/s, column i = response to +1 deg/s about i
    small = [f"{a}_rot" for i, a in enumerate(AXES)
             if not abs(g_mat[i, i]) >= 0.5 * np.median(np.abs(np.diag(g_mat)))
             or g_mat[i, i] == 0]
    if small:
        raise CalibrationError(
            f"rotations too small in {', '.join(small)}: each section must hold a full "
            f"{ang:g} deg turn about its axis"
        )
    # A turn about axis i reads mostly on gyro axis i (one package's cross-axis terms are a few
    # percent): a section without a turn (only the bias left after subtracting the static one)
    # or with a turn about another axis gives columns that point elsewhere, and the inverse of
    # their matrix is a finite but meaningless gain matrix. More than 0.71 of the column on its
    # own axis (under 45 deg off it) can hold for one column of any direction only.
    share = np.abs(np.diag(w)) / np.maximum(np.linalg.norm(w, axis=0), np.finfo(float).tiny)
    off = [i for i in range(3) if not share[i] > 0.71]
    if off:
        raise CalibrationError(
            "the turns in " + ", ".join(
                f"{AXES[i]}_rot ({np.degrees(np.arccos(min(share[i], 1.0))):.0f} deg off its axis)"
                for i in off)
            + " do not read mostly on the gyro axis they are named after: each _rot section must "
            f"hold one {ang:g} deg turn about its own axis (a section without a turn, or with a "
            "turn about another axis, cannot give the gyro's gains)")
    sv = np.linalg.svd(w, compute_uv=False)
    _spans(sv, float(sv[0]), "the three turns")
    m_g = np.linalg.inv(g_mat) * (np.pi / 180)  # rad/s per raw
    finite_result({"accel matrix": m_a, "gyro matrix": m_g, "g_sensitivity": k_ga},
                  "ferraris", "the readings, gravity and turn angle are out of proportion "
                  "(check their units)")
    return FerrarisCalibration(
        accel=accel,
        gyro=TriadCalibration(_ro(b_g), _ro(m_g), "rad/s"),
        g_sensitivity=_ro(k_ga),
        accel_counts_per_g=_ro(np.linalg.norm(a_mat, axis=1) * grav),
        gyro_counts_per_dps=_ro(np.linalg.norm(g_mat, axis=1)),
        rotation_sign=_ro(sign),
    )
