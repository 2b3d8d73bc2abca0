"""Overlapping Allan deviation of a sensor at rest, computed in the Rust core and streamed.

Noise model (IEEE Std 952 / 1554): a gyroscope or accelerometer at rest reports its rate
``y_k`` (deg/s, rad/s, m/s^2, g or counts) every ``1 / rate_hz`` seconds. The overlapping Allan
variance at averaging time ``tau = m / rate_hz`` (``m`` samples per cluster) is

    sigma^2(tau) = sum_i (x[i + 2m] - 2 x[i + m] + x[i])^2 / (2 m^2 n),   x[k] = sum_{j<k} y[j],

the mean squared difference of consecutive cluster averages, halved (NIST SP 1065 eq. 11; the
same number as ``allantools.oadev(y, rate, data_type="freq")``). The deviation ``sigma`` is in
the unit of the samples.

Memory does not grow with the log: samples are pushed chunk by chunk (:class:`AllanAccumulator`,
or :func:`allan` with an iterable of chunks) and only a ring of recent phases per stride is
kept (or, when every cluster is a power of two starting at every sample, a ring of recent
window sums per octave: the term is the difference of two window sums ``m`` apart, and a
window of ``2m`` is the sum of two windows of ``m``). Clusters of up to ``exact_up_to``
samples (default 65536) use every start sample, as above; longer ones start every ``d``-th
sample, with ``d`` a power of two that leaves at least 2048 starts per cluster (``m`` rounded
to a multiple of ``d``): unbiased, statistically as good, and equal to
``allantools.calc_adev_phase(phase, rate, m, d)``.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any, Union

import numpy as np

from .._checks import options as opt
from .._core import AllanStream as _CoreAllanStream
from ..errors import CalibrationError
from ..quality.bounds import sample_rate

__all__ = [
    "DEFAULT_EXACT_UP_TO",
    "AllanAccumulator",
    "AllanDeviation",
    "allan",
    "cluster_sizes",
]

#: Clusters up to this many samples use every start sample by default in a stream.
DEFAULT_EXACT_UP_TO = 65536
#: In-memory arrays up to this many samples get every cluster exact by default.
_EXACT_ARRAY_LIMIT = 1 << 21
#: Longest cluster a stream computes by default (2^40 samples: 35 years at 1 kHz).
_STREAM_MAX_M = 1 << 40

Taus = Union[None, str, Iterable[float], np.ndarray]


def cluster_sizes(taus: Taus, rate_hz: float, max_m: int) -> np.ndarray:
    """Cluster sizes (samples, ``m = round(tau * rate_hz)``) for a tau specification.

    ``None`` or ``"octave"``: 1, 2, 4, ... up to ``max_m``; ``"log"``: about 10 per decade;
    otherwise taus in seconds (each rounded to whole samples; those longer than ``max_m``
    samples are dropped).

    >>> cluster_sizes("octave", 100.0, 20).tolist()
    [1, 2, 4, 8, 16]
    >>> cluster_sizes([0.01, 0.05, 0.049, 10.0], 100.0, 20).tolist()
    [1, 5]
    """
    rate = _rate(rate_hz)
    if max_m < 1:
        raise CalibrationError("too few samples for an Allan deviation: need at least 3")
    if taus is None or (isinstance(taus, str) and taus == "octave"):
        return 2 ** np.arange(int(math.floor(math.log2(max_m))) + 1, dtype=np.uint64)
    if isinstance(taus, str):
        if taus != "log":
            raise CalibrationError(
                f"taus must be 'octave', 'log' or taus in seconds, got {taus!r}"
            )
        top = math.log10(max_m)
        m = np.unique(np.round(np.logspace(0, top, max(2, int(10 * top) + 1))))
        return m[(m >= 1) & (m <= max_m)].astype(np.uint64)
    try:
        t = np.asarray(taus, dtype=np.float64).ravel()
    except (TypeError, ValueError, OverflowError):
        raise CalibrationError(
            f"taus must be 'octave', 'log' or numbers in seconds, got {taus!r}"
        ) from None
    if t.size == 0 or not np.isfinite(t).all() or (t <= 0).any():
        raise CalibrationError(f"taus must be finite times in seconds > 0, got {t.tolist()}")
    with np.errstate(over="ignore"):  # a tau past any recording: dropped below
        m = np.round(t * rate)
    if (m < 1).any():
        raise CalibrationError(
            f"taus shorter than one sample (1 / {rate:g} Hz = {1 / rate:g} s): "
            f"{t[m < 1].tolist()}"
        )
    m = np.unique(m[m <= max_m])
    if m.size == 0:
        raise CalibrationError(
            f"every tau is too long for the data: the longest usable is {max_m / rate:g} s"
        )
    return m.astype(np.uint64)


def _rate(rate_hz: Any) -> float:
    return sample_rate(rate_hz)


def _exact(value: Any) -> int | None:
    if value is None:
        return None
    return opt.integer(value, "exact_up_to", ge=1, le=_STREAM_MAX_M,
                       hint="samples, or None")


@dataclass(frozen=True)
class AllanDeviation:
    """Overlapping Allan deviation per axis (see the module docstring for the definition).

    Attributes
    ----------
    taus : ndarray (T,)
        Averaging times in seconds (``m / rate_hz``).
    adev : ndarray (T, K)
        Allan deviation per averaging time and axis, in ``unit``.
    m : ndarray (T,)
        Cluster sizes in samples.
    stride : ndarray (T,)
        Samples between the starts of consecutive terms (1: fully overlapping).
    terms : ndarray (T,)
        Number of terms averaged.
    rate_hz : float
        Sample rate in Hz.
    n : int
        Samples per axis.
    unit : str
        Unit of the samples and of ``adev``: ``"deg/s"``, ``"rad/s"``, ``"m/s^2"``, ``"g"``,
        ``"counts"``...
    axes : tuple of str
        Axis names (``x, y, z`` for three axes).
    """

    taus: np.ndarray
    adev: np.ndarray
    m: np.ndarray
    stride: np.ndarray
    terms: np.ndarray
    rate_hz: float
    n: int
    unit: str = "counts"
    axes: tuple[str, ...] = ("x", "y", "z")

    @property
    def duration_s(self) -> float:
        """Length of the log in seconds (``n / rate_hz``)."""
        return self.n / self.rate_hz

    @property
    def avar(self) -> np.ndarray:
        """Allan variance ``adev**2``, in ``unit**2``."""
        return self.adev**2

    @property
    def edf(self) -> np.ndarray:
        """Approximate equivalent degrees of freedom of each variance (white-rate formula of
        Howe, Allan and Barnes 1981 for the fully overlapping estimator, ``N`` phase points):
        ``(3 (N - 1) / (2 m) - 2 (N - 2) / N) * 4 m^2 / (4 m^2 + 5)``, at least 1."""
        n = float(self.n + 1)
        m = self.m.astype(np.float64)
        e = (3 * (n - 1) / (2 * m) - 2 * (n - 2) / n) * 4 * m**2 / (4 * m**2 + 5)
        return np.maximum(e, 1.0)

    @property
    def rel_error(self) -> np.ndarray:
        """Approximate 1-sigma relative error of each deviation, ``1 / sqrt(2 edf)``."""
        return 1.0 / np.sqrt(2.0 * self.edf)

    def __repr__(self) -> str:
        return (f"AllanDeviation({len(self.taus)} taus {self.taus[0]:.3g}..{self.taus[-1]:.3g} s,"
                f" {len(self.axes)} axes, {self.n} samples at {self.rate_hz:g} Hz, {self.unit})")


class AllanAccumulator:
    """Streaming overlapping Allan deviation: :meth:`add` chunks, then :meth:`result`.

    Memory is fixed when the accumulator is made (:attr:`memory_bytes`, a few MB per axis) and
    does not grow with the number of samples; a 24-hour log at 1 kHz never needs to sit in
    memory.

    Parameters
    ----------
    rate_hz : float
        Sample rate in Hz.
    axes : int
        Channels per row (3 for x, y, z).
    taus : {None, "octave", "log"} or array_like of float
        Averaging times: octave (1, 2, 4... samples, the default), about 10 per decade, or
        times in seconds. ``None`` and the names reach out to ``max_tau_s``.
    max_tau_s : float, optional
        Longest averaging time of ``"octave"`` / ``"log"`` (default: 2^40 samples). Times
        longer than half the log get no terms and are left out of the result.
    exact_up_to : int or None
        Clusters up to this many samples use every start sample (default 65536); longer ones
        are strided (see the module docstring). ``None``: every cluster exact, with memory
        growing with the longest cluster.
    unit : str
        Unit of the samples, recorded in the result.

    Examples
    --------
    >>> import numpy as np, triaxcal as tc
    >>> rng = np.random.default_rng(0)
    >>> acc = tc.AllanAccumulator(100.0, axes=3, unit="deg/s")
    >>> for _ in range(10):                       # 10 chunks of 10 s of white noise
    ...     acc.add(rng.normal(0, 0.1, (1000, 3)))
    >>> r = acc.result()
    >>> float(r.taus[0]), round(float(r.adev[0, 0]), 2)  # 1 sample: the per-sample sigma
    (0.01, 0.1)
    """

    def __init__(
        self,
        rate_hz: float,
        *,
        axes: int = 3,
        taus: Taus = None,
        max_tau_s: float | None = None,
        exact_up_to: int | None = DEFAULT_EXACT_UP_TO,
        unit: str = "counts",
    ) -> None:
        self.rate_hz = _rate(rate_hz)
        if isinstance(axes, bool) or not isinstance(axes, (int, np.integer)) or not 1 <= axes <= 64:
            raise CalibrationError(f"axes must be a whole number from 1 to 64, got {axes!r}")
        self.axes = int(axes)
        max_m = _STREAM_MAX_M
        if max_tau_s is not None:
            mt = opt.number(max_tau_s, "max_tau_s", gt=0, hint="seconds")
            if not mt * self.rate_hz >= 1:
                raise CalibrationError(
                    f"max_tau_s must be at least one sample ({1 / self.rate_hz:g} s), got "
                    f"{max_tau_s!r}"
                )
            max_m = int(min(mt * self.rate_hz, _STREAM_MAX_M))
        if not isinstance(unit, str) or not unit.strip():
            raise CalibrationError("unit must be a unit name such as 'deg/s' or 'counts'")
        self.unit = unit
        ms = cluster_sizes(taus, self.rate_hz, max_m)
        self._core = _CoreAllanStream(
            self.rate_hz, self.axes, [int(v) for v in ms], exact_up_to=_exact(exact_up_to)
        )

    @property
    def n(self) -> int:
        """Samples (rows) added so far."""
        return int(self._core.n)

    @property
    def memory_bytes(self) -> int:
        """Bytes the accumulator holds (fixed when it is made)."""
        return int(self._core.memory_bytes)

    def add(self, chunk: Any) -> None:
        """Add readings: shape (rows, axes), or (rows,) for one axis, any real dtype.

        A chunk with a NaN or inf is refused whole (:class:`~triaxcal.NonFiniteError` naming
        the row in the whole stream) and the accumulator stays as it was.
        """
        try:
            arr = np.asarray(chunk)
        except (TypeError, ValueError) as exc:
            raise CalibrationError(f"chunk must be an array of numbers ({exc})") from None
        if arr.dtype.kind not in "iuf":
            raise CalibrationError(
                f"chunk must hold real numbers (integer or float), got dtype {arr.dtype}"
            )
        if arr.ndim == 1 and self.axes == 1:
            arr = arr[:, None]
        if arr.ndim != 2 or arr.shape[1] != self.axes:
            raise CalibrationError(
                f"chunk must have shape (rows, {self.axes}), one row per reading; got "
                f"{arr.shape}"
            )
        # the core checks every value (NonFiniteError naming the row) before adding any
        self._core.push(np.ascontiguousarray(arr, dtype=np.float64))

    def result(self) -> AllanDeviation:
        """The Allan deviation of everything added (averaging times with at least 2 terms)."""
        d = self._core.result()
        keep = d["terms"] >= 2
        if not keep.any():
            raise CalibrationError(
                f"too few samples ({self.n}) for any of the averaging times: an Allan deviation "
                "at tau needs a log of at least 3 tau"
            )
        if not np.isfinite(d["adev"][keep]).all():
            raise CalibrationError(
                "the Allan deviation overflows a double: readings that differ by more than "
                "about 1e150 are not a sensor's (a wrong column, unit or scale?); rescale them "
                "before computing it"
            )
        axes = ("x", "y", "z") if self.axes == 3 else tuple(f"axis{i}" for i in range(self.axes))
        out = {k: np.array(d[k][keep]) for k in ("taus", "adev", "m", "stride", "terms")}
        for k in ("m", "stride", "terms"):
            out[k] = out[k].astype(np.int64)
        for v in out.values():
            v.setflags(write=False)
        return AllanDeviation(
            taus=out["taus"], adev=out["adev"], m=out["m"], stride=out["stride"],
            terms=out["terms"], rate_hz=self.rate_hz, n=self.n, unit=self.unit, axes=axes,
        )

    def __repr__(self) -> str:
        return (f"AllanAccumulator({self.axes} axes at {self.rate_hz:g} Hz, {self.n} samples, "
                f"{self.memory_bytes / 1e6:.1f} MB)")


def allan(
    samples: Any,
    rate_hz: float,
    *,
    taus: Taus = None,
    exact_up_to: int | None | str = "auto",
    unit: str = "counts",
) -> AllanDeviation:
    """Overlapping Allan deviation per axis of a sensor at rest (Rust core, GIL released).

    Parameters
    ----------
    samples : array_like (N, K) or (N,), or an iterable of such chunks
        Rate readings at rest, one row per sample (any real dtype). An iterable (a generator
        reading a long log, say) is streamed chunk by chunk and never held in memory.
    rate_hz : float
        Sample rate in Hz.
    taus : {None, "octave", "log"} or array_like of float
        ``None`` / ``"octave"``: 1, 2, 4, ... samples (as allantools' default);
        ``"log"``: about 10 per decade; or averaging times in seconds.
    exact_up_to : int, None or "auto"
        Clusters up to this many samples use every start sample, longer ones are strided (see
        the module docstring); ``None``: all exact. ``"auto"`` (default): all exact for an
        array of up to 2^21 samples, 65536 for longer arrays and for streams.
    unit : str
        Unit of the samples (``"deg/s"``, ``"rad/s"``, ``"m/s^2"``, ``"g"``, ``"counts"``),
        which is also the unit of the deviation.

    Returns
    -------
    AllanDeviation

    Raises
    ------
    CalibrationError
        Wrong shape or dtype, NaN or inf (the row is named), a bad rate or tau, too few samples.

    Examples
    --------
    >>> import numpy as np, triaxcal as tc
    >>> rng = np.random.default_rng(1)
    >>> gyro = rng.normal(0.0, 0.05, size=(100_000, 3))   # deg/s, white noise at 100 Hz
    >>> ad = tc.allan(gyro, 100.0, unit="deg/s")
    >>> ad.taus[:3].tolist()
    [0.01, 0.02, 0.04]
    >>> # white noise falls as 1/sqrt(tau): noise density 0.05 / sqrt(100) = 0.005 deg/s/sqrt(Hz)
    >>> bool(abs(ad.adev[ad.taus == 1.28, 0][0] * np.sqrt(1.28) - 0.005) < 0.0005)
    True
    """
    rate = _rate(rate_hz)
    if isinstance(samples, np.ndarray) or (
        not isinstance(samples, Iterable) or isinstance(samples, (list, tuple))
    ):
        try:
            arr = np.asarray(samples) if not isinstance(samples, np.ndarray) else samples
        except (TypeError, ValueError):  # ragged lists
            arr = np.zeros(0, dtype=object)
        if arr.dtype.kind not in "iuf":
            raise CalibrationError(
                f"samples must hold real numbers (integer or float), got dtype {arr.dtype}"
            )
        if arr.ndim == 1:
            arr = arr[:, None]
        if arr.ndim != 2 or arr.shape[1] < 1:
            raise CalibrationError(
                f"samples must have shape (N, K) or (N,), one row per reading; got {arr.shape}"
            )
        n = arr.shape[0]
        if n < 3:
            raise CalibrationError(f"need at least 3 samples for an Allan deviation, got {n}")
        if exact_up_to == "auto":
            exact_up_to = None if n <= _EXACT_ARRAY_LIMIT else DEFAULT_EXACT_UP_TO
        acc = AllanAccumulator(rate, axes=arr.shape[1], taus=taus,
                               max_tau_s=((n - 1) // 2) / rate,
                               exact_up_to=exact_up_to,  # type: ignore[arg-type]
                               unit=unit)
        acc.add(arr)
        return acc.result()
    if exact_up_to == "auto":
        exact_up_to = DEFAULT_EXACT_UP_TO
    it = iter(samples)
    acc2: AllanAccumulator | None = None
    for chunk in it:
        c = np.asarray(chunk)
        if acc2 is None:
            k = 1 if c.ndim == 1 else (c.shape[1] if c.ndim == 2 else 0)
            if k < 1:
                raise CalibrationError(
                    f"each chunk must have shape (rows, K) or (rows,), got {c.shape}"
                )
            acc2 = AllanAccumulator(rate, axes=k, taus=taus,
                                    exact_up_to=exact_up_to,  # type: ignore[arg-type]
                                    unit=unit)
        acc2.add(c)
    if acc2 is None:
        raise CalibrationError("the stream of samples was empty")
    return acc2.result()
