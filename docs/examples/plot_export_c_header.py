"""
Export a C header, float and fixed point
========================================

A calibration becomes a C header for the firmware: ``#define`` constants, arrays and one
``static inline`` apply function per sensor, with units, the fit's quality and a test vector in
its comment. The fixed-point header does the same without floating point (Q7.24 matrix,
``int64_t`` products), for AVR and other FPU-less parts. Here the calibration of a simulated
board, and how far the fixed-point result is from the float one.
"""

import matplotlib.pyplot as plt
import numpy as np
import triaxcal as tc
from triaxcal.export import apply_fixed, fixed_point

imu = tc.sim.SimIMU(seed=3)
rec = imu.record(tc.sim.globe_script(), rate_hz=100)
det = tc.detect_poses(rec.accel, units_per_g=16384)
fit = tc.fit_ellipsoid(det.points, model="full", radius=1.0)
part = tc.SensorCalibration.from_fit(fit, unit="g", points=det.points)
cal = tc.Calibration(accel=part, sensor_id="sim-3")

header = tc.c_header(cal, prefix="imu")
print("\n".join(header.splitlines()[:40]))

# %%
# The fixed-point header's apply function returns the calibrated value times a power of two
# (32768 per g here). Its result, in g, against the float calibration on every sample of the
# recording: within one count of the output scale.
print("\n".join(line for line in tc.c_fixed_header(cal, prefix="imu").splitlines()
                if "Q_OUT_SCALE" in line or "apply_q(" in line))
fp = fixed_point(part)
raw = rec.accel.astype(np.int64)
q = apply_fixed(fp, raw)
float_g = cal.apply(raw, sensor="accel")
scale = fp.out_scale                       # output counts per g
err_counts = q - float_g * scale
print(f"largest difference {np.abs(err_counts).max():.3f} output counts "
      f"({np.abs(err_counts).max() / scale * 1e6:.1f} micro-g)")
fig, ax = plt.subplots(figsize=(7, 3.5), layout="constrained")
ax.hist(err_counts.ravel(), bins=60)
ax.set_xlabel("fixed point minus float (output counts)")
ax.set_ylabel("readings x axes")
