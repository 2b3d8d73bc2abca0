"""
Fit a simulated tumble
======================

The whole accelerometer job on a simulated board whose truth is known: the globe scheme
(7 latitudes x 12 turns about the vertical = 84 poses), still-pose detection, the full
ellipsoid fit, and the recovered offsets and gains against the truth.
"""

import matplotlib.pyplot as plt
import numpy as np
import triaxcal as tc

imu = tc.sim.SimIMU(seed=1)                          # known offsets, gains, cross-axis, noise
rec = imu.record(tc.sim.globe_script(), rate_hz=100)  # counts, 100 samples per second
print(f"{len(rec.t)} samples, {rec.t[-1]:.0f} s")

# %%
# Find the still poses, as ``triaxcal fit --poses`` does: windows of 25 samples whose mean
# moved by less than 0.07 g, held for 4 windows.
det = tc.detect_poses(rec.accel, units_per_g=16384)
print(f"{len(det.points)} still poses")

# %%
# Fit offset + symmetric matrix to the pose means, radius 1 g. The matrix multiplies:
# ``g = (raw - offset) @ matrix.T``.
fit = tc.fit_ellipsoid(det.points, model="full", radius=1.0)
truth = imu.truth.accel
print("offset   fitted", fit.offset.round(1), "counts")
print("         true  ", truth.offset.round(1))
print("stderr         ", fit.stderr[:3].round(2))
print("gain x 16384   fitted", (np.diag(fit.matrix) * 16384).round(4))
print("               true  ", (np.diag(truth.matrix) * 16384).round(4))
print(f"residual RMS {fit.rms * 1000:.2f} mg")

# %%
# The lengths of the readings before and after: raw lengths vary by several percent with
# orientation; calibrated ones are 1 g within the noise.
raw_len = np.linalg.norm(det.points, axis=1) / 16384
cal_len = np.linalg.norm(fit.apply(det.points), axis=1)
fig, ax = plt.subplots(figsize=(7, 3.5), layout="constrained")
ax.plot(raw_len, "o", ms=4, label="raw |a| / 16384 counts")
ax.plot(cal_len, "o", ms=4, label="calibrated |a|")
ax.axhline(1.0, color="k", lw=0.8)
ax.set_xlabel("pose")
ax.set_ylabel("length (g)")
ax.legend()
ax.set_title("84 poses of the globe scheme")
