"""Simulated rate noise of an inertial sensor at rest, of known size (IEEE Std 952 terms).

For a gyroscope (or an accelerometer, with velocity in place of angle) held still, the reading
on each axis is ``bias + white + flicker + walk`` in ``unit`` (deg/s, rad/s, m/s^2, g...):

* ``white``: white rate noise of density ``white`` (unit/sqrt(Hz), the angle / velocity random
  walk N); per sample it has standard deviation ``white * sqrt(rate_hz)``. Its Allan deviation
  is ``N / sqrt(tau)``.
* ``flicker``: bias instability ``B`` (unit), a 1/f process with one-sided power spectral
  density ``B^2 / (pi f)`` (the two-sided ``B^2 / (2 pi f)`` of IEEE 952). Its Allan deviation
  is the flat floor ``sqrt(2 ln 2 / pi) B = 0.664 B``. Made by shaping white noise in the
  frequency domain over the whole log, so it needs the log in memory.
* ``walk``: rate random walk ``K`` (unit/sqrt(s), i.e. unit/s/sqrt(Hz)): the bias steps by a
  normal increment of standard deviation ``K / sqrt(rate_hz)`` every sample. Its Allan
  deviation is ``K sqrt(tau / 3)``.

The three are independent on each axis and between axes.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from .._checks.options import seed as seed_of
from ..errors import CalibrationError

__all__ = ["NoiseTruth", "noise_chunks", "simulate_noise"]

#: Allan deviation floor of flicker noise per unit of bias instability, sqrt(2 ln 2 / pi).
FLICKER_FLOOR = math.sqrt(2.0 * math.log(2.0) / math.pi)


@dataclass(frozen=True)
class NoiseTruth:
    """Known noise of a simulated sensor at rest (see the module docstring for the terms).

    Attributes
    ----------
    white : float
        White rate noise density N in unit/sqrt(Hz) (angle / velocity random walk).
    bias_instability : float
        Flicker bias instability B in unit (Allan deviation floor 0.664 B).
    random_walk : float
        Rate / acceleration random walk K in unit/sqrt(s) (= unit/s/sqrt(Hz)).
    bias : float or tuple of float
        Constant bias in unit, one value or one per axis.
    unit : str
        Unit of the readings.
    """

    white: float = 0.0
    bias_instability: float = 0.0
    random_walk: float = 0.0
    bias: float | tuple[float, ...] = 0.0
    unit: str = "deg/s"

    def __post_init__(self) -> None:
        for name in ("white", "bias_instability", "random_walk"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise CalibrationError(f"{name} must be a finite number >= 0, got {v!r}")

    def adev(self, tau: np.ndarray) -> np.ndarray:
        """The Allan deviation these terms add up to at ``tau`` seconds, in unit."""
        t = np.asarray(tau, dtype=np.float64)
        return np.sqrt(self.white**2 / t + (FLICKER_FLOOR * self.bias_instability) ** 2
                       + self.random_walk**2 * t / 3.0)


def _check(n: int, rate_hz: float, axes: int) -> None:
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise CalibrationError(f"n must be a whole number of samples >= 1, got {n!r}")
    if not (math.isfinite(rate_hz) and rate_hz > 0):
        raise CalibrationError(f"rate_hz must be > 0, got {rate_hz!r}")
    if isinstance(axes, bool) or not isinstance(axes, (int, np.integer)) or axes < 1:
        raise CalibrationError(f"axes must be a whole number >= 1, got {axes!r}")


def _bias(truth: NoiseTruth, axes: int) -> np.ndarray:
    b = np.broadcast_to(np.asarray(truth.bias, dtype=np.float64), (axes,))
    return np.array(b)


def simulate_noise(
    truth: NoiseTruth, n: int, rate_hz: float, *, axes: int = 3, seed: int = 0
) -> np.ndarray:
    """Readings (n, axes) in ``truth.unit`` of a sensor at rest with the noise ``truth``.

    Examples
    --------
    >>> import numpy as np
    >>> from triaxcal.sim import NoiseTruth, simulate_noise
    >>> y = simulate_noise(NoiseTruth(white=0.01), 100_000, 100.0, seed=1)   # deg/s
    >>> y.shape, round(float(y.std()), 3)                # 0.01 deg/s/sqrt(Hz) * sqrt(100 Hz)
    ((100000, 3), 0.1)
    """
    _check(n, rate_hz, axes)
    rng = np.random.default_rng([seed_of(seed), 0x0A11A])
    dt = 1.0 / rate_hz
    out = rng.normal(0.0, truth.white * math.sqrt(rate_hz), (n, axes))
    out += _bias(truth, axes)
    if truth.random_walk > 0:
        out += np.cumsum(rng.normal(0.0, truth.random_walk * math.sqrt(dt), (n, axes)), axis=0)
    if truth.bias_instability > 0 and n > 2:
        # one-sided PSD S(f) = h / f with h = B^2 / pi, on the FFT grid f_k = k / (n dt);
        # with x = irfft(X), E|X_k|^2 = n S(f_k) / (2 dt) gives Var x = sum_k S(f_k) df
        k = np.arange(1, n // 2 + 1)
        f = k / (n * dt)
        var = n * (truth.bias_instability**2 / math.pi) / f / (2.0 * dt)
        for a in range(axes):
            spec = np.zeros(n // 2 + 1, dtype=np.complex128)
            spec[1:] = (rng.normal(size=k.size) + 1j * rng.normal(size=k.size)) * np.sqrt(
                var / 2.0
            )
            if n % 2 == 0:  # the Nyquist bin of an even length is real
                spec[-1] = spec[-1].real * math.sqrt(2.0)
            out[:, a] += np.fft.irfft(spec, n=n)
    return out


def noise_chunks(
    truth: NoiseTruth,
    n: int,
    rate_hz: float,
    *,
    axes: int = 3,
    seed: int = 0,
    chunk: int = 1 << 20,
) -> Iterator[np.ndarray]:
    """The readings of :func:`simulate_noise` as chunks of ``chunk`` rows, generated one at a
    time so that a log of any length never sits in memory. White noise, random walk and bias
    only: flicker needs the whole log (use :func:`simulate_noise`)."""
    _check(n, rate_hz, axes)
    if truth.bias_instability > 0:
        raise CalibrationError(
            "noise_chunks makes white noise and random walk only; flicker (bias instability) "
            "needs the whole log: use simulate_noise"
        )
    if isinstance(chunk, bool) or not isinstance(chunk, (int, np.integer)) or chunk < 1:
        raise CalibrationError(f"chunk must be a whole number of rows >= 1, got {chunk!r}")
    rng = np.random.default_rng([seed_of(seed), 0x0A11A])
    sd_white = truth.white * math.sqrt(rate_hz)
    sd_walk = truth.random_walk / math.sqrt(rate_hz)
    bias = _bias(truth, axes)
    level = np.zeros(axes)
    done = 0
    while done < n:
        rows = min(int(chunk), n - done)
        out = rng.normal(0.0, sd_white, (rows, axes)) + bias
        if sd_walk > 0:
            walk = np.cumsum(rng.normal(0.0, sd_walk, (rows, axes)), axis=0) + level
            level = walk[-1].copy()
            out += walk
        done += rows
        yield out
