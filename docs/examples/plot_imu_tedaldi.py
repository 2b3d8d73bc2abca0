"""
Accelerometer and gyroscope without equipment (Tedaldi et al.)
==============================================================

The recording the method's authors published with imu_tk: an Xsens MTi held still in about
forty orientations, with moves in between (raw 16-bit counts, 100 Hz; imu_tk's
``xsens_acc.mat`` and ``xsens_gyro.mat``). The still intervals are found by a variance detector
for a range of thresholds, the accelerometer is fitted to their means, and the gyroscope's
matrix is fitted so that integrating each move turns the measured gravity direction before it
into the one after it. The maker's own calibration of this unit (printed by the authors'
script) is 415, 413, 415 counts per m/s^2 and 4778, 4758, 4766 counts per rad/s.
"""

import matplotlib.pyplot as plt
import numpy as np
import triaxcal as tc
from gallery_helpers import recording

acc = np.loadtxt(recording("imutk-xsens/xsens_acc.mat"))
gyr = np.loadtxt(recording("imutk-xsens/xsens_gyro.mat"))
t, acc, gyr = acc[:, 0], acc[:, 1:], gyr[:, 1:]

imu = tc.calibrate_imu(acc, gyr, rate_hz=100, gravity=9.81744, t=t)
print(f"{len(imu.intervals)} still intervals (threshold k = {imu.k:g})")
print("accelerometer gains", imu.accel.gains.round(2), "counts per m/s^2 (Xsens: 415 413 415)")
print("gyroscope gains    ", imu.gyro.gains.round(1), "counts per rad/s (Xsens: 4778 4758 4766)")
print(f"gravity direction after each of {imu.n_moves} moves: {imu.gyro_rms_deg:.2f} deg rms "
      f"(nominal scale only: {imu.gyro_rms_deg_before:.2f} deg)")

# %%
# The accelerometer's length through the recording, raw (at the nominal 415 counts per m/s^2)
# and calibrated, with the still intervals the method found shaded.
raw_len = np.linalg.norm(acc - imu.accel.offset, axis=1) / 415.0
cal_len = np.linalg.norm(imu.accel.apply(acc), axis=1)
fig, ax = plt.subplots(figsize=(9, 3.8), layout="constrained")
for a, b in imu.intervals:
    ax.axvspan(t[a] - t[0], t[b - 1] - t[0], color="0.9")
ax.plot(t - t[0], raw_len, lw=0.6, label="raw / nominal gain")
ax.plot(t - t[0], cal_len, lw=0.6, label="calibrated")
ax.set_ylim(9.6, 10.1)
ax.set_xlabel("time (s)")
ax.set_ylabel("|a| (m/s^2)")
ax.legend(loc="lower right")
