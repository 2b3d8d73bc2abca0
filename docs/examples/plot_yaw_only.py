"""
Yaw-only: a magnetometer that can only turn about the vertical
===============================================================

A boat, a car or a large drone cannot be tumbled. Turning it round the vertical traces an
ellipse in the horizontal plane, which determines the horizontal hard iron and the 2x2 soft
iron; the vertical offset needs the local field's vertical component (the World Magnetic
Model, with ``--location``), and the vertical gain stays undetermined -- the result says so.

The data: 243 readings of an HMC5883L turned about one axis (nliaudat's
``magnetometer_calibration``, ``mag_out_sample.txt``), which the full ellipsoid fit refuses
(:ref:`sphx_glr_auto_examples_plot_validity_gate.py`).
"""

import matplotlib.pyplot as plt
import numpy as np
import triaxcal as tc
from gallery_helpers import recording

mag = np.loadtxt(recording("hmc5883l-yaw-nliaudat/mag_out_sample.txt"), delimiter=",")
y = tc.fit_yaw(mag, raw_unit="uT")
print(y.text())

# %%
# The horizontal components before and after: an off-centre ellipse becomes a circle round
# the origin, so the heading ``atan2(-y, x)`` is right all the way round.
cal = y.apply(mag)
fig, ax = plt.subplots(figsize=(5.5, 5.5), layout="constrained")
ax.plot(mag[:, 0], mag[:, 1], ".", ms=3, label="raw")
ax.plot(cal[:, 0], cal[:, 1], ".", ms=3, label="calibrated (yaw-only)")
ax.plot(0, 0, "k+")
ax.set_aspect("equal")
ax.set_xlabel("x")
ax.set_ylabel("y")
ax.legend(loc="lower left")
h_raw = np.hypot(*mag[:, :2].T)
h_cal = np.hypot(*cal[:, :2].T)
ax.set_title(f"horizontal field: spread {np.std(h_raw) / np.mean(h_raw):.0%} raw, "
             f"{np.std(h_cal) / np.mean(h_cal):.1%} calibrated")
