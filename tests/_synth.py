"""Synthetic distorted spheres with known offset and matrix, shared by the fit tests."""

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
