"""Synthetic data shared by the tests: distorted spheres with known offset and matrix (the fit
tests), and a board twisted from its first sample (the pose detectors' tests)."""

from __future__ import annotations

import numpy as np


def random_sym(rng: np.random.Generator, diag=(0.9, 1.1), off=0.05) -> np.ndarray:
    """A symmetric positive-definite matrix near the identity."""
    d = rng.uniform(*diag, size=3)
    e = rng.uniform(-off, off, size=3)
    return np.array([[d[0], e[0], e[1]], [e[0], d[1], e[2]], [e[1], e[2], d[2]]])


def distorted_sphere(n, *, offset, matrix, radius=1.0, noise=0.0, seed=0):
    """Raw readings whose calibration is ``(raw - offset) @ matrix.T`` with magnitude ``radius``.

    ``noise`` is Gaussian noise on the raw readings, as a fraction of the radius expressed in raw
    units. Returns (raw, true_field).
    """
    rng = np.random.default_rng(seed)
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    field = u * radius
    raw = field @ np.linalg.inv(matrix).T + offset
    if noise:
        raw_scale = radius / np.mean(np.diag(matrix))
        raw = raw + rng.normal(scale=noise * raw_scale, size=raw.shape)
    return raw, field


def twist_first(rng: np.random.Generator, n_poses: int = 12):
    """Flat on a table, twisted about the vertical from the first sample (10 deg/s for 3 s),
    then ``n_poses`` poses of 1 s (4 windows of 25) joined by twists of 0.5 s, each at its own
    speed: accelerometer, gyroscope (bias 60, -40, 25 counts; 131 counts per deg/s). Returns the
    (n, 6) readings and which samples are at rest."""
    bias = np.array([60.0, -40.0, 25.0])
    rates = [1310.0 * np.ones(300)]
    for _ in range(n_poses):
        rates.append(np.zeros(100))
        rates.append(float(rng.uniform(20, 60)) * 131 * np.sin(np.linspace(0, np.pi, 50)))
    z = np.concatenate(rates)
    n = len(z)
    acc = np.tile([0.0, 0.0, 16384.0], (n, 1)) + rng.normal(0, 30, (n, 3))
    gyro = bias + rng.normal(0, 4, (n, 3))
    gyro[:, 2] += z
    return np.hstack([acc, gyro]), (z == 0)
