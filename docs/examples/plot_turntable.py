"""
Gyroscope on a turntable (real recording)
=========================================

freeIMUCal's recordings of a handheld controller's gyroscope (rad/s) on a record player at
33 1/3 rpm (3.4907 rad/s) and 45 rpm (4.7124 rad/s), turned into several orientations, plus a
recording at rest for the bias. The calibrated rate must have the table's magnitude in every
orientation: the symmetric matrix follows by linear least squares. Fitted on 45 rpm and checked
on 33 1/3 rpm, which the fit never saw.
"""

import matplotlib.pyplot as plt
import numpy as np
import triaxcal as tc
from gallery_helpers import recording

g0, g33, g45 = (np.loadtxt(recording(f"freeimucal-gearvr/{n}RPMgyr.txt")) for n in (0, 33, 45))
RPM33, RPM45 = 2 * np.pi * (100 / 3) / 60, 2 * np.pi * 45 / 60

bias = tc.gyro_bias(g0, rate_hz=100, rest_s=10.0)
fit = tc.fit_turntable([g45], [RPM45], offset=bias.offset)
print("matrix (multiplies):\n", fit.matrix.round(5))
print(f"45 rpm plateaus: {fit.rel_error[0]:+.3%} from the table's rate")

# %%
# The held-out 33 1/3 rpm recording: the rate magnitude sample by sample, before (offset removed
# only) and after the calibration. Uncalibrated, the plateaus sit at different heights with
# the sensor's orientation; calibrated, they all sit at the table's rate.
raw = np.linalg.norm(g33 - bias.offset, axis=1)
cal = np.linalg.norm((g33 - bias.offset) @ fit.matrix.T, axis=1)
fig, ax = plt.subplots(figsize=(9, 3.8), layout="constrained")
ax.plot(raw / RPM33, lw=0.6, label="raw")
ax.plot(cal / RPM33, lw=0.6, label="calibrated")
ax.axhline(1.0, color="k", lw=0.8)
ax.set_ylim(0.97, 1.03)
ax.set_xlabel("sample")
ax.set_ylabel("|rate| / table rate")
ax.legend()
