"""The pose detection of a session, the same in ``capture``, ``fit --poses``, ``report`` and
``demo``.

A session (a table whose columns are named ``ax ay az gx gy gz mx my mz ...``, as ``triaxcal
capture`` writes them) is reduced to still poses by :class:`~triaxcal.detect.PoseDetector` with
every sensor the session has: the accelerometer's window-mean change (the original method's 0.07
g), the
gyroscope's rate and the magnetometer's change (thresholds learnt from their noise unless
given). :class:`PoseSettings` holds what a user can choose on the command line;
:meth:`PoseSettings.resolve` turns it into the detector's options for a given session, filling
in what the data decide (accelerometer counts per g, sample rate for the hold-off) from the
session's first rows only, so that a live capture, which sees those rows first, and a later
``fit`` of the saved file resolve them identically and find the same poses.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, replace
from typing import Any

import numpy as np

from .._checks import options
from .._checks.arrays import as_samples
from .._checks.spelling import opt
from ..errors import CalibrationError
from ..quality.bounds import sample_rate
from ._segmenter import PoseDetection
from .poses import PoseDetector, _columns, detect_poses

#: Last column of a session whose rows are the board's pose means (``capture --board-poses``):
#: the samples each mean averages.
POSE_N_COLUMN = "pose_n"

__all__ = [
    "HEAD_ROWS",
    "POSE_N_COLUMN",
    "pose_points",
    "PoseSettings",
    "ResolvedPoses",
    "session_poses",
    "sensor_columns",
    "stored_settings",
]

#: Rows at the start of a session from which the counts per g and the sample rate are taken.
HEAD_ROWS = 100

#: Channel names of each sensor in a session (the device order of ``triaxcal capture``).
SENSOR_NAMES = {"accel": ("ax", "ay", "az"), "gyro": ("gx", "gy", "gz"),
                "mag": ("mx", "my", "mz")}


def sensor_columns(names: Sequence[str] | None) -> dict[str, tuple[int, int, int]]:
    """Column indices of each sensor whose three channels are all named in ``names``.

    >>> sensor_columns(("t", "ax", "ay", "az", "gx", "gy", "gz", "temp"))
    {'accel': (1, 2, 3), 'gyro': (4, 5, 6)}
    """
    out: dict[str, tuple[int, int, int]] = {}
    if not names:
        return out
    for sensor, want in SENSOR_NAMES.items():
        if all(w in names for w in want):
            out[sensor] = tuple(list(names).index(w) for w in want)  # type: ignore[assignment]
    return out


@dataclass(frozen=True)
class ResolvedPoses:
    """Detector options for one session, with the values the data decided.

    ``kwargs`` go to :func:`~triaxcal.detect_poses` / :class:`~triaxcal.PoseDetector`;
    ``counts_per_g`` and ``rate_hz`` are the resolved values (``rate_hz`` is None when no
    hold-off needed it); ``sensors`` names the sensors that take part.
    """

    kwargs: dict[str, Any]
    counts_per_g: float
    rate_hz: float | None
    sensors: tuple[str, ...]

    def detector(self, **extra: Any) -> PoseDetector:
        """A fresh :class:`~triaxcal.PoseDetector` with these options (and ``extra``)."""
        return PoseDetector(**{**self.kwargs, **extra})


def _positive(value: Any, what: str, allow_none: bool = True) -> float | None:
    if value is None and allow_none:
        return None
    return options.magnitude(value, what)


@dataclass(frozen=True)
class PoseSettings:
    """What a user chooses about pose detection (the ``--window``, ``--accel-threshold``,
    ``--gyro-threshold``, ``--mag-threshold``, ``--holdoff``, ``--rate-hz`` and
    ``--counts-per-g`` options).

    Attributes
    ----------
    window : int
        Samples per averaging window.
    accel_threshold_g : float
        Largest change of the accelerometer's window mean between two windows, in g (the
        original method's 0.07).
    counts_per_g : float, optional
        Accelerometer units per g. ``None``: the median length of the accelerometer readings
        in the first :data:`HEAD_ROWS` rows (the board lies still at the start, so that is 1 g
        in its units: 16384 counts at +-2 g, 1 for a board that prints g).
    use_gyro, use_mag : bool
        Let the gyroscope's rate and the magnetometer's change end a pose (when the session has
        them).
    gyro_threshold, mag_threshold : float, optional
        In the sensor's raw units (counts). ``None``: learnt from the sensor's noise.
    hold_windows : int, optional
        A run is registered (or rejected) once it has this many windows -- the capture's bell,
        the sphere-centre note's beep -- and then goes on averaging until the board moves.
        ``None``: decided
        when the board moves. The same in capture and fit, so both make the same decisions.
    holdoff_s : float
        Seconds ignored after each registered pose (the original method's 2 s after its beep); 0:
        none.
    rate_hz : float, optional
        Samples per second, to turn ``holdoff_s`` into samples. ``None``: from the session's
        ``t`` column (host arrival times) over the first :data:`HEAD_ROWS` rows.
    """

    window: int = 25
    accel_threshold_g: float = 0.07
    counts_per_g: float | None = None
    use_gyro: bool = True
    use_mag: bool = True
    gyro_threshold: float | None = None
    mag_threshold: float | None = None
    hold_windows: int | None = 4
    holdoff_s: float = 0.0
    rate_hz: float | None = None

    def __post_init__(self) -> None:
        if isinstance(self.window, bool) or not isinstance(self.window, (int, np.integer)) or \
                self.window < 1:
            raise CalibrationError(f"{opt('window')} must be a whole number of samples >= 1, "
                                   f"got {self.window!r}")
        _positive(self.accel_threshold_g, "accel_threshold_g", allow_none=False)
        _positive(self.counts_per_g, "counts_per_g")
        _positive(self.gyro_threshold, "gyro_threshold")
        _positive(self.mag_threshold, "mag_threshold")
        if self.rate_hz is not None:
            sample_rate(self.rate_hz)
        hw = self.hold_windows
        if hw is not None and (isinstance(hw, bool) or not isinstance(hw, (int, np.integer))
                               or hw < 2):
            raise CalibrationError(f"{opt('hold_windows')} must be a whole number >= 2 (or "
                                   f"None), got {hw!r}")
        options.number(self.holdoff_s, "holdoff_s", ge=0, hint="seconds")
        for name in ("use_gyro", "use_mag"):
            options.flag(getattr(self, name), name)

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON values (stored with a calibration made from poses)."""
        return asdict(self)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> PoseSettings:
        """Inverse of :meth:`to_dict`; unknown keys are an error."""
        if not isinstance(d, Mapping):
            raise CalibrationError("pose settings must be a JSON object")
        known = set(cls.__dataclass_fields__)
        unknown = set(d) - known
        if unknown:
            raise CalibrationError(f"unknown pose setting(s) {sorted(unknown)}")
        return cls(**dict(d))

    def resolve(
        self,
        names: Sequence[str] | None,
        head: Any,
        *,
        accel: Sequence[int] | None = None,
        t: Any = None,
    ) -> ResolvedPoses:
        """Detector options for a session with columns ``names`` whose first rows are ``head``.

        Parameters
        ----------
        names : sequence of str, optional
            Column names of the session (``t`` first for a capture session). Sensors are
            found by name (``ax ay az``, ``gx gy gz``, ``mx my mz``).
        head : array_like, shape (n, K)
            The session's first rows (at least :data:`HEAD_ROWS`, or all of a shorter one).
        accel : 3 ints, optional
            The accelerometer's columns when ``names`` do not name them (a headerless table).
        t : array_like, shape (n,), optional
            Arrival times (s) of the ``head`` rows, when they are not a ``t`` column of it.
        """
        rows = np.asarray(head, dtype=np.float64)
        if rows.ndim != 2:
            raise CalibrationError("head must be rows of the session, shape (n, K)")
        rows = rows[:HEAD_ROWS]
        cols = sensor_columns(names)
        if accel is not None:
            cols["accel"] = _columns(accel, "accel", None)
        if "accel" not in cols:
            raise CalibrationError(
                "pose detection needs the accelerometer: name its columns ax, ay, az (as "
                f"triaxcal capture does) or pick them ({opt('columns')})"
            )
        if not self.use_gyro:
            cols.pop("gyro", None)
        if not self.use_mag:
            cols.pop("mag", None)
        cpg = self.counts_per_g
        if cpg is None:
            if not len(rows):
                raise CalibrationError("the session has no rows to detect poses in")
            norms = np.linalg.norm(rows[:, list(cols["accel"])], axis=1)
            cpg = float(np.median(norms))
            if not (math.isfinite(cpg) and cpg > 0):
                raise CalibrationError(
                    "cannot tell the accelerometer's units from the first rows (they read "
                    f"zero): give them ({opt('counts_per_g')})"
                )
        rate = self.rate_hz
        holdoff = 0
        if self.holdoff_s > 0:
            if rate is None:
                if t is not None:
                    times = np.asarray(t, dtype=np.float64).reshape(-1)[:HEAD_ROWS]
                elif names and "t" in names:
                    times = rows[:, list(names).index("t")]
                else:
                    times = np.zeros(0)
                if len(times) < 2 or not times[-1] > times[0]:
                    raise CalibrationError(
                        f"{opt('holdoff_s')} needs the sample rate: give it ({opt('rate_hz')}; "
                        "the session has no usable t column)"
                    )
                rate = (len(times) - 1) / float(times[-1] - times[0])
            holdoff = options.samples(self.holdoff_s, rate, "holdoff_s")
        kwargs: dict[str, Any] = {
            "window": int(self.window),
            "threshold": self.accel_threshold_g * cpg,
            "units_per_g": cpg,
            "columns": cols["accel"],
            "holdoff_samples": holdoff,
            "max_windows": None if self.hold_windows is None else int(self.hold_windows),
        }
        if "gyro" in cols:
            kwargs["gyro_columns"] = cols["gyro"]
            kwargs["gyro_threshold"] = self.gyro_threshold
        if "mag" in cols:
            kwargs["mag_columns"] = cols["mag"]
            kwargs["mag_threshold"] = self.mag_threshold
        return ResolvedPoses(kwargs=kwargs, counts_per_g=cpg,
                             rate_hz=rate if self.holdoff_s > 0 else None,
                             sensors=tuple(s for s in SENSOR_NAMES if s in cols))

    def with_resolved(self, resolved: ResolvedPoses) -> PoseSettings:
        """These settings with the data-decided values fixed (to store and replay exactly)."""
        return replace(self, counts_per_g=resolved.counts_per_g,
                       rate_hz=resolved.rate_hz if resolved.rate_hz is not None else self.rate_hz)


def session_poses(
    names: Sequence[str] | None,
    data: Any,
    settings: PoseSettings | None = None,
    *,
    accel: Sequence[int] | None = None,
) -> tuple[PoseDetection, ResolvedPoses]:
    """The still poses of a whole session, as ``triaxcal fit --poses`` and ``report`` find them.

    Parameters
    ----------
    names : sequence of str, optional
        Column names of ``data`` (sensors are found by name).
    data : array_like, shape (N, K)
        The session's rows (all columns; a ``t`` column is averaged like the others).
    settings : PoseSettings, optional
        Default: ``PoseSettings()``.
    accel : 3 ints, optional
        The accelerometer's columns when ``names`` do not name them.

    Returns
    -------
    (PoseDetection, ResolvedPoses)

    Examples
    --------
    >>> import numpy as np
    >>> from triaxcal import sim
    >>> rec = sim.SimIMU(1).record(sim.globe_script(hold_s=1.0), rate_hz=100)
    >>> names = ("ax", "ay", "az", "gx", "gy", "gz", "mx", "my", "mz", "temp")
    >>> det, how = session_poses(names, rec.frames(10))
    >>> len(det.poses), how.sensors
    (84, ('accel', 'gyro', 'mag'))
    """
    s = options.instance(settings if settings is not None else PoseSettings(), PoseSettings,
                         "settings", "a PoseSettings (or None)")
    if names is not None and (isinstance(names, (str, bytes)) or not isinstance(names, Sequence)
                              or not all(isinstance(n, str) for n in names)):
        raise CalibrationError(f"names must be the column names (a sequence of str) or None, "
                               f"got {names!r:.60}")
    arr = as_samples(data, "data", channels="xyz+")
    how = s.resolve(names, arr[:HEAD_ROWS], accel=accel)
    return detect_poses(arr, **how.kwargs), how


def pose_points(
    table: Any, cols: list[int], settings: PoseSettings
) -> tuple[np.ndarray, dict[str, Any]]:
    """Still-pose means of columns ``cols`` of a :class:`~triaxcal.io.tables.Table`, and the
    statistics that say how they were found (``poses``, ``n_poses``, ``pose_detection``: the
    settings with the values the data decided, so that ``report`` finds the same poses again).

    A session whose rows are the board's pose means (a ``pose_n`` column: ``triaxcal capture
    --board-poses``) is taken as it is: each row is one pose, ``pose_source`` says so."""
    if table.names is not None and POSE_N_COLUMN in table.names:
        if not len(table.data):
            raise CalibrationError(f"{table.path} has no poses: the board sent none")
        n = table.data[:, table.names.index(POSE_N_COLUMN)]
        return table.data[:, cols], {"poses": True, "n_poses": len(table.data),
                                     "pose_source": "board",
                                     "pose_samples_min": int(n.min()) if len(n) else 0}
    accel = None if "accel" in sensor_columns(table.names) else cols
    det, how = session_poses(table.names, table.data, settings, accel=accel)
    if len(det.poses) == 0:
        raise CalibrationError(
            f"no still poses found in {table.path} (window {settings.window} samples): hold the "
            "board still for a second in each pose, or drop --poses for point-per-row data"
        )
    pts = np.array([np.asarray(p.mean)[cols] for p in det.poses], dtype=np.float64)
    stats = {"poses": True, "n_poses": len(det.poses),
             "pose_detection": settings.with_resolved(how).to_dict(),
             "pose_sensors": list(how.sensors)}
    return pts, stats


def stored_settings(stats: Any) -> PoseSettings:
    """The pose settings a calibration part was fitted with (``stats["pose_detection"]``).

    Parts written before the detector used every sensor stored only ``pose_window`` and
    ``units_per_g``: they replay with the accelerometer alone, as they were made.
    """
    d = stats.get("pose_detection") if hasattr(stats, "get") else None
    if d is not None:
        return PoseSettings.from_dict(d)
    return PoseSettings(window=int(stats.get("pose_window", 25)),
                        counts_per_g=float(stats.get("units_per_g", 16384.0)),
                        use_gyro=False, use_mag=False, hold_windows=None)
