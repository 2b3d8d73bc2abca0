"""Gyroscope calibration on a turntable: constant-rate plateaus of known magnitude.

Error model (:mod:`triaxcal.methods.gyro`): ``rate = (w - offset) @ matrix.T``, the matrix
**multiplies**. With the sensor placed on a turntable (a record player) in several orientations,
each orientation gives a plateau: a constant body-frame rate vector ``w`` whose true magnitude
is the table's rate. With the bias known from a recording at rest, the plateaus determine the
symmetric matrix (or per-axis scales), as the accelerometer's still poses determine its matrix
with gravity as the known magnitude.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._checks import options as opt
from .._checks.arrays import as_samples
from ..detect import detect_poses
from ..errors import CalibrationError

__all__ = ["TurntableFit", "fit_turntable", "turntable_plateaus"]


def _ro(a: Any) -> np.ndarray:
    arr = np.array(a, dtype=np.float64)
    arr.setflags(write=False)
    return arr


def _as_rate(gyro: Any, name: str = "gyro") -> np.ndarray:
    arr = as_samples(gyro, name, finite=True)
    if arr.shape[0] < 2:
        raise CalibrationError(f"{name} needs at least 2 samples, got {arr.shape[0]}")
    return arr


def turntable_plateaus(
    gyro: Any,
    *,
    min_rate: float,
    window: int = 50,
    threshold: float | None = None,
    min_windows: int = 4,
) -> tuple[np.ndarray, np.ndarray]:
    """Constant-rate plateaus of a turntable recording: means (M, 3) and sample counts (M,).

    A plateau is a run of windows whose mean rate vector stays within ``threshold`` (input
    units; default 1 % of ``min_rate``) -- the sphere-centre method's stillness test applied to
    the gyro -- with a magnitude of at least ``min_rate`` (spin-up, spin-down and reorientation
    pauses are dropped).
    """
    g = _as_rate(gyro)
    low = opt.number(min_rate, "min_rate", gt=0, hint="the slowest plateau, gyro units")
    thr = 0.01 * low if threshold is None else opt.number(threshold, "threshold", gt=0)
    det = detect_poses(g, window=window, threshold=thr, min_separation=0.0,
                       min_windows=min_windows, max_std=10 * thr)
    keep = [p for p in det.poses if np.linalg.norm(p.mean[:3]) >= low]
    if not keep:
        return np.zeros((0, 3)), np.zeros(0, dtype=int)
    return np.array([p.mean[:3] for p in keep]), np.array([p.n for p in keep])


@dataclass(frozen=True)
class TurntableFit:
    """Gyro calibration from turntable plateaus of known rate.

    ``calibrated = (raw - offset) @ matrix.T`` is in the units of ``rates`` (rad/s if the rates
    were given in rad/s); ``matrix`` multiplies. ``measured`` lists each recording's plateau
    magnitudes after calibration (mean over its plateaus), ``raw_measured`` the same before
    (offset removed only), ``rel_error`` = measured / rate - 1 per recording.
    """

    offset: np.ndarray
    matrix: np.ndarray
    rates: np.ndarray
    measured: np.ndarray
    raw_measured: np.ndarray
    rel_error: np.ndarray
    n_plateaus: tuple[int, ...]
    rms_rel: float

    def apply(self, raw: Any) -> np.ndarray:
        """``(raw - offset) @ matrix.T``."""
        return (np.asarray(raw, dtype=np.float64) - self.offset) @ self.matrix.T


def fit_turntable(
    recordings: Sequence[Any],
    rates: Sequence[float],
    *,
    offset: Any,
    model: str = "full",
    window: int = 50,
    min_fraction: float = 0.9,
) -> TurntableFit:
    """Fit the gyro gain matrix from turntable recordings of known rate.

    With the sensor placed on a turntable in several orientations, each orientation gives a
    plateau: a constant body-frame rate vector ``w`` whose true magnitude is the table's rate.
    With the bias ``offset`` known (from a recording at rest), ``u = (w - offset) / rate``
    satisfies ``u.T @ A @ u = 1`` with ``A = matrix.T @ matrix``: linear least squares in the
    six entries of ``A`` (three for ``model="axis"``), then ``matrix`` is the symmetric square
    root of ``A``.

    Parameters
    ----------
    recordings : sequence of array_like (Ni, 3)
        Gyro readings, one array per turntable speed.
    rates : sequence of float
        The true rate of each recording (rad/s for a result in rad/s; 33 1/3 rpm = 3.4907 rad/s).
    offset : array_like (3,)
        Gyro bias, in the readings' units (see :func:`gyro_bias`).
    model : {"full", "axis"}
        Symmetric 3x3 matrix or per-axis scales.
    window : int
        Samples per averaging window of the plateau detection.
    min_fraction : float
        Plateaus slower than ``min_fraction * rate`` are spin-up/down and are dropped.

    Returns
    -------
    TurntableFit
    """
    opt.choice(model, "model", ("full", "axis"))
    rr_list = opt.numbers_list(rates, "rates", min_len=0, gt=0, hint="the table's rate, rad/s")
    if (isinstance(recordings, (str, bytes)) or not isinstance(recordings, Sequence)
            or len(recordings) != len(rr_list) or not rr_list):
        raise CalibrationError("give one rate per recording (and at least one recording)")
    off = opt.vector3(offset, "offset", hint="gyro bias, in the readings' units")
    win = opt.integer(window, "window", ge=1, hint="samples per averaging window")
    frac = opt.number(min_fraction, "min_fraction", gt=0, le=1)
    us, which, counts = [], [], []
    for i, (rec, rate) in enumerate(zip(recordings, rr_list)):
        g = _as_rate(rec, name=f"recordings[{i}]") - off
        means, _ = turntable_plateaus(g, min_rate=frac * rate, window=win)
        if len(means) == 0:
            raise CalibrationError(
                f"recordings[{i}]: no constant-rate plateau near {rate:g}; is the table turning, "
                "and is the rate in the gyro's units?"
            )
        us.append(means / rate)
        which += [i] * len(means)
        counts.append(len(means))
    u = np.vstack(us)
    need = 6 if model == "full" else 3
    if u.shape[0] < need:
        raise CalibrationError(
            f"{u.shape[0]} plateaus found, the {model!r} model needs at least {need} orientations "
            "of the sensor on the table (tilt it differently for each)"
        )
    if model == "full":
        design = np.column_stack([u[:, 0] ** 2, u[:, 1] ** 2, u[:, 2] ** 2, 2 * u[:, 0] * u[:, 1],
                                  2 * u[:, 0] * u[:, 2], 2 * u[:, 1] * u[:, 2]])
    else:
        design = u**2
    sv = np.linalg.svd(design / np.linalg.norm(design, axis=0), compute_uv=False)
    if sv[-1] < 1e-6 * sv[0]:
        raise CalibrationError(
            "the plateaus do not span enough directions of the rate vector for the "
            f"{model!r} model: place the sensor on the table in more varied orientations"
        )
    coef, *_ = np.linalg.lstsq(design, np.ones(u.shape[0]), rcond=None)
    if model == "full":
        a = np.array([[coef[0], coef[3], coef[4]], [coef[3], coef[1], coef[5]],
                      [coef[4], coef[5], coef[2]]])
    else:
        a = np.diag(coef)
    ev, evec = np.linalg.eigh(a)
    if ev.min() <= 0:
        raise CalibrationError("the fitted gain matrix is not positive definite: check the data")
    m = (evec * np.sqrt(ev)) @ evec.T
    which_a = np.array(which)
    cal = np.linalg.norm(u @ m.T, axis=1)
    rawn = np.linalg.norm(u, axis=1)
    rr = np.asarray(rates, dtype=np.float64)
    meas = np.array([cal[which_a == i].mean() for i in range(len(rates))]) * rr
    rawm = np.array([rawn[which_a == i].mean() for i in range(len(rates))]) * rr
    return TurntableFit(
        offset=_ro(off),
        matrix=_ro(m),
        rates=_ro(rr),
        measured=_ro(meas),
        raw_measured=_ro(rawm),
        rel_error=_ro(meas / rr - 1),
        n_plateaus=tuple(counts),
        rms_rel=float(np.sqrt(np.mean((cal - 1) ** 2))),
    )


