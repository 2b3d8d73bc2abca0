"""The AVX2 + FMA kernels and the portable build give the same answers (to round-off).

The portable build runs on CPUs without AVX2 (and on every CPU with ``TRIAXCAL_PORTABLE``
set); the two builds share one generic kernel, but FMA rounds differently, so they agree to
round-off, not bit for bit. Each build runs in its own process (the choice is made once per
process).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np

SCRIPT = r"""
import json, sys
import numpy as np, triaxcal as tc
rng = np.random.default_rng(5)
u = rng.normal(size=(20000, 3)); u /= np.linalg.norm(u, axis=1, keepdims=True)
a = np.array([[1.04, 0.01, -0.01], [0.01, 0.97, 0.015], [-0.01, 0.015, 1.0]])
pts = u @ np.linalg.inv(a).T * 16384 + [412.0, -230.5, 97.25] + rng.normal(scale=160, size=u.shape)
out = {}
for model in ("sphere", "axis", "full"):
    f = tc.fit_ellipsoid(pts, model=model, radius=1.0)
    out[model] = [*f.offset, *f.matrix.ravel(), f.rms, *f.stderr]
sets = [pts[i * 200:(i + 1) * 200] for i in range(40)]
b = tc.fit_batch(sets, model="full", radius=1.0)
out["batch"] = np.concatenate([b.offsets.ravel(), b.matrices.ravel()]).tolist()
d = tc.descend_center(pts[:5000], 16384.0)
out["descent"] = [*d.center, d.error]
rate = rng.normal(scale=0.01, size=(50000, 3))
out["allan"] = np.asarray(tc.allan(rate, rate_hz=100.0).avar).ravel().tolist()
json.dump({k: [float(v) for v in vals] for k, vals in out.items()}, sys.stdout)
"""


def _run(portable: bool) -> dict[str, list[float]]:
    env = {k: v for k, v in os.environ.items() if k != "TRIAXCAL_PORTABLE"}
    if portable:
        env["TRIAXCAL_PORTABLE"] = "1"
    res = subprocess.run([sys.executable, "-c", SCRIPT], env=env, capture_output=True,
                         text=True, timeout=120, check=True)
    return json.loads(res.stdout)


def test_the_two_kernel_builds_agree():
    fast, portable = _run(False), _run(True)
    assert fast.keys() == portable.keys()
    for key in fast:
        a, b = np.array(fast[key]), np.array(portable[key])
        assert a.shape == b.shape and np.all(np.isfinite(a)), key
        scale = np.maximum(np.abs(a), np.abs(a).max() * 1e-6)
        assert np.max(np.abs(a - b) / scale) < 1e-7, (key, np.max(np.abs(a - b) / scale))
