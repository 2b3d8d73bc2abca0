"""Still poses: :func:`detect_poses` (offline) and :class:`PoseDetector` (online), the
sphere-centre method's window rule on every sensor of the board."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from .._checks import options as opt
from ..errors import CalibrationError
from ._segmenter import Pose, PoseDetection, Rejection, _as_samples, _Segmenter


def _columns(value: Any, what: str, n_channels: int | None) -> tuple[int, int, int]:
    bad = CalibrationError(
        f"{what} must name 3 channels (x, y, z) by whole-number index >= 0, got {value!r}"
    )
    if isinstance(value, (str, bytes)) or not hasattr(value, "__len__") or len(value) != 3:
        raise bad
    try:
        a, b, c = (opt.integer(v, what, ge=0) for v in value)
    except CalibrationError:
        raise bad from None
    cols = (a, b, c)
    if n_channels is not None and not all(0 <= k < n_channels for k in cols):
        raise CalibrationError(f"{what} {cols} out of range for {n_channels} channels")
    return cols


def _positive(value: Any, what: str) -> float | None:
    return opt.optional_number(value, what, gt=0, hint="in the sensor's units, or None: learn it")


def _options(
    window: int,
    threshold: float | None,
    units_per_g: float,
    min_separation: float | None,
    min_windows: int,
    max_std: float | None,
    max_windows: int | None,
    columns: Sequence[int],
    n_channels: int | None = None,
    *,
    gyro_columns: Sequence[int] | None = None,
    gyro_threshold: float | None = None,
    mag_columns: Sequence[int] | None = None,
    mag_threshold: float | None = None,
    holdoff_samples: int = 0,
) -> dict:
    win = opt.integer(window, "window", ge=1, hint="samples per averaging window")
    min_w = opt.integer(min_windows, "min_windows", ge=2, hint="two windows to compare")
    max_w = None if max_windows is None else opt.integer(max_windows, "max_windows",
                                                         ge=min_w, hint="or None")
    upg = opt.number(units_per_g, "units_per_g", gt=0, hint="16384 for counts at +-2 g")
    thr = 0.07 * upg if threshold is None else opt.number(
        threshold, "threshold", gt=0, hint="in the sensor's units")
    sep = thr if min_separation is None else opt.number(
        min_separation, "min_separation", ge=0, hint="0 disables it")
    mstd = thr if max_std is None else opt.number(max_std, "max_std", gt=0)
    cols = _columns(columns, "columns", n_channels)
    gcols = None if gyro_columns is None else _columns(gyro_columns, "gyro_columns", n_channels)
    mcols = None if mag_columns is None else _columns(mag_columns, "mag_columns", n_channels)
    used = [c for cs in (cols, gcols, mcols) if cs for c in cs]
    if len(set(used)) != len(used):
        raise CalibrationError(
            f"columns, gyro_columns and mag_columns overlap ({cols}, {gcols}, {mcols}): each "
            "sensor needs its own three channels"
        )
    holdoff = opt.integer(holdoff_samples, "holdoff_samples", ge=0, hint="samples")
    return {
        "window": win,
        "threshold": thr,
        "min_windows": min_w,
        "min_separation": sep,
        "max_std": mstd,
        "max_windows": max_w,
        "columns": cols,
        "gyro_columns": gcols,
        "gyro_threshold": _positive(gyro_threshold, "gyro_threshold"),
        "mag_columns": mcols,
        "mag_threshold": _positive(mag_threshold, "mag_threshold"),
        "holdoff_samples": holdoff,
    }


def detect_poses(
    samples: Any,
    *,
    window: int = 25,
    threshold: float | None = None,
    units_per_g: float = 1.0,
    min_separation: float | None = None,
    min_windows: int = 2,
    max_std: float | None = None,
    max_windows: int | None = None,
    columns: Sequence[int] = (0, 1, 2),
    gyro_columns: Sequence[int] | None = None,
    gyro_threshold: float | None = None,
    mag_columns: Sequence[int] | None = None,
    mag_threshold: float | None = None,
    holdoff_samples: int = 0,
) -> PoseDetection:
    """Find still poses by the sphere-centre note's window-average method, with every sensor "
    "(offline).

    Parameters
    ----------
    samples : array_like, shape (N, K), K >= 3
        Readings, one row per sample; ``columns`` name the accelerometer's three. Other
        channels (gyro, magnetometer, temperature) are averaged too and appear in
        :attr:`Pose.mean`.
    window : int
        Samples per averaging window (25 = 0.25 s at 100 Hz).
    threshold : float, optional
        Largest change of any accelerometer axis of the window mean, from one window to the
        next, for the board to count as still, in the input's units. ``None``:
        ``0.07 * units_per_g`` (the original method's 0.07 g).
    units_per_g : float
        Accelerometer units per g: 1 for g, 9.80665 for m/s^2, 16384 for counts at +-2 g.
    min_separation : float, optional
        Smallest accelerometer distance (input units, Euclidean) between a new pose and every
        registered one; a candidate closer than this to an earlier pose -- and, when
        ``mag_columns`` are given, closer than ``mag_threshold`` to it in the magnetometer --
        is rejected as "too close to an earlier pose". ``None``: ``threshold``; 0 disables
        the check.
    min_windows : int
        Fewest windows a still run needs (2 = one steady comparison, the original method's rule);
        shorter runs are rejected as "too short".
    max_std : float, optional
        Largest standard deviation of any accelerometer axis about the run's mean (noise
        plus slow drift); noisier runs are rejected as "too noisy". ``None``: ``threshold``.
    max_windows : int, optional
        Decide on a run as soon as it has this many windows (the sphere-centre note's beep: the
        pose is
        registered, or rejected, on those windows' mean, and :meth:`PoseDetector.update` returns
        it then); a registered pose goes on averaging until the board moves, and
        :attr:`PoseDetection.poses` hold the whole run's mean. ``None``: decide when the motion
        resumes, on the whole run.
    columns : sequence of 3 ints
        The accelerometer's channels, for detection and for :attr:`PoseDetection.points`.
    gyro_columns : sequence of 3 ints, optional
        The gyroscope's channels. A window whose mean rate on any axis is more than
        ``gyro_threshold`` away from the bias (the median rate of the last still windows), or
        from the previous window's, is motion. The first bias is provisional until the board
        rests at it again after a move; until then, ``REANCHOR_WINDOWS`` steady windows at
        another rate, after two different moves, replace it (a twist about the vertical at the
        start of a recording looks still to the accelerometer).
    gyro_threshold : float, optional
        In the gyroscope's input units (counts, deg/s...). ``None``: learnt from its noise,
        ``NOISE_Z`` standard deviations of the change of a window mean between still windows
        (the first ``NOISE_WINDOWS`` windows the accelerometer calls steady).
    mag_columns : sequence of 3 ints, optional
        The magnetometer's channels. A window whose mean changed on any axis by more than
        ``mag_threshold`` from the previous window's is motion.
    mag_threshold : float, optional
        In the magnetometer's input units. ``None``: learnt from its noise, as for the gyro.
    holdoff_samples : int
        Samples ignored after each registered pose before a new run can start (the original method's
        2-second pause after its beep: ``2 * rate_hz``). 0: none.

    Returns
    -------
    PoseDetection

    Examples
    --------
    >>> import numpy as np, triaxcal as tc
    >>> rest = np.tile([[0.0, 0.0, 1.0]], (200, 1))
    >>> move = np.linspace([0, 0, 1], [1, 0, 0], 100)
    >>> side = np.tile([[1.0, 0.0, 0.0]], (200, 1))
    >>> det = tc.detect_poses(np.vstack([rest, move, side]), window=25)
    >>> det.points.round(3).tolist()
    [[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]

    A twist about the vertical (18 deg at 90 deg/s, 100 samples/s) leaves the accelerometer
    unchanged; the gyroscope and the magnetometer see it:

    >>> acc = np.tile([0.0, 0.0, 1.0], (500, 1))
    >>> gyro = np.zeros((500, 3)); gyro[240:260, 2] = 90.0
    >>> yaw = np.radians(np.clip((np.arange(500) - 240) * 0.9, 0, 18))
    >>> mag = np.column_stack([25 * np.cos(yaw), -25 * np.sin(yaw), np.full(500, -40.0)])
    >>> len(tc.detect_poses(acc).poses)
    1
    >>> det = tc.detect_poses(np.hstack([acc, gyro, mag]), gyro_columns=(3, 4, 5),
    ...                       mag_columns=(6, 7, 8), gyro_threshold=1.0, mag_threshold=0.5)
    >>> [(p.start, p.end) for p in det.poses]
    [(25, 225), (300, 500)]
    """
    arr = _as_samples(samples)
    opts = _options(window, threshold, units_per_g, min_separation, min_windows, max_std,
                    max_windows, columns, arr.shape[1], gyro_columns=gyro_columns,
                    gyro_threshold=gyro_threshold, mag_columns=mag_columns,
                    mag_threshold=mag_threshold, holdoff_samples=holdoff_samples)
    seg = _Segmenter(**opts)
    nw = arr.shape[0] // opts["window"]
    seg.feed(arr[: nw * opts["window"]])
    seg.finish()
    return _result(seg)


def _result(seg: _Segmenter) -> PoseDetection:
    pts = np.asarray(seg.points, dtype=np.float64).reshape(-1, 3)
    pts.setflags(write=False)
    return PoseDetection(
        points=pts,
        poses=list(seg.poses),
        rejected=list(seg.rejected),
        threshold=seg.threshold,
        window=seg.window,
        thresholds=seg.thresholds,
    )


class PoseDetector:
    """Online version of :func:`detect_poses`: feed samples as they arrive.

    Takes the same options as :func:`detect_poses`. State (the partial window, the previous
    window mean, the learnt thresholds, the open still run, the registered poses) carries
    across calls, and the poses are the same as :func:`detect_poses` finds on the
    concatenated samples, however the stream is cut.

    Examples
    --------
    >>> import numpy as np, triaxcal as tc
    >>> det = tc.PoseDetector(window=25, max_windows=4)
    >>> det.update(np.tile([[0.0, 0.0, 1.0]], (90, 1)))
    []
    >>> [(p.start, p.end) for p in det.update(np.tile([[0.0, 0.0, 1.0]], (20, 1)))]
    [(25, 100)]
    """

    def __init__(
        self,
        *,
        window: int = 25,
        threshold: float | None = None,
        units_per_g: float = 1.0,
        min_separation: float | None = None,
        min_windows: int = 2,
        max_std: float | None = None,
        max_windows: int | None = None,
        columns: Sequence[int] = (0, 1, 2),
        gyro_columns: Sequence[int] | None = None,
        gyro_threshold: float | None = None,
        mag_columns: Sequence[int] | None = None,
        mag_threshold: float | None = None,
        holdoff_samples: int = 0,
    ) -> None:
        self._opts = _options(window, threshold, units_per_g, min_separation, min_windows,
                              max_std, max_windows, columns, gyro_columns=gyro_columns,
                              gyro_threshold=gyro_threshold, mag_columns=mag_columns,
                              mag_threshold=mag_threshold, holdoff_samples=holdoff_samples)
        self._seg = _Segmenter(**self._opts)
        self._buf: np.ndarray | None = None
        self._n_channels: int | None = None
        self.n_samples = 0

    def update(self, samples: Any) -> list[Pose]:
        """Add samples (shape (n, K), n may be 0); return the poses registered by them."""
        arr = _as_samples(samples)
        if self._n_channels is None and arr.shape[0]:
            used = [c for key in ("columns", "gyro_columns", "mag_columns")
                    for c in (self._opts[key] or ())]
            if not all(0 <= c < arr.shape[1] for c in used):
                raise CalibrationError(
                    f"channels {tuple(used)} out of range for {arr.shape[1]} channels"
                )
            self._n_channels = arr.shape[1]
        elif arr.shape[0] and arr.shape[1] != self._n_channels:
            raise CalibrationError(
                f"samples have {arr.shape[1]} channels, earlier ones had {self._n_channels}"
            )
        if arr.shape[0] == 0:
            return []
        self.n_samples += arr.shape[0]
        if self._buf is not None and self._buf.shape[0]:
            arr = np.vstack([self._buf, arr])
        w = self._opts["window"]
        nw = arr.shape[0] // w
        self._buf = arr[nw * w:].copy()
        return self._seg.feed(arr[: nw * w])

    def finish(self) -> list[Pose]:
        """End of stream: decide on the still run in progress (it may register a pose)."""
        return self._seg.finish()

    @property
    def still(self) -> bool:
        """Whether the sensor is still now (a still run is open)."""
        return self._seg.run_len >= 2

    @property
    def poses(self) -> list[Pose]:
        """All poses registered so far (with ``max_windows``, a pose's mean grows to its whole
        run once the board moves)."""
        return list(self._seg.poses)

    @property
    def rejected(self) -> list[Rejection]:
        """All rejected candidates so far."""
        return list(self._seg.rejected)

    @property
    def points(self) -> np.ndarray:
        """Pose means of the accelerometer channels so far, shape (M, 3)."""
        return np.asarray(self._seg.points, dtype=np.float64).reshape(-1, 3)

    @property
    def thresholds(self) -> dict[str, float | None]:
        """Each sensor's threshold so far (``None`` while a learnt one is not known yet)."""
        return self._seg.thresholds

    def result(self) -> PoseDetection:
        """A :class:`PoseDetection` of everything so far (without finishing the open run)."""
        return _result(self._seg)


# --- variance detector (imu_tk / Tedaldi et al. 2014) ----------------------------------------
