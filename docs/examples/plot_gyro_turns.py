"""
Gyroscope gains from turns of a known angle
===========================================

Rest, turn by 90 deg about one axis, rest; both ways about x, y and z. The integral of each
turn, in counts times seconds, divided by 90 deg is the gain in counts per deg/s. The board is
simulated with gains 1 % high on x and 1.5 % low on y (nominal 16.4 counts per deg/s, an
MPU-6050 at +-2000 deg/s), so the answer is known.
"""

import matplotlib.pyplot as plt
import numpy as np
import triaxcal as tc

scale = [131 / 16.4 * k for k in (1.01, 0.985, 1.0)]
imu = tc.sim.SimIMU(1, gyro={"scale": scale})
rec = imu.record(tc.sim.rotation_script("xyz", 90.0, peak_dps=180), rate_hz=100)
g = tc.gyro_gains(rec.gyro, angle_deg=90, t=rec.t)
true = np.pi / 180 / np.diag(imu.truth.gyro.matrix)
for axis, ccw, cw, mean, t in zip("xyz", g.gain_ccw_counts_per_dps, g.gain_cw_counts_per_dps,
                                   g.gain_counts_per_dps, true):
    print(f"{axis}: ccw {ccw:.4f}  cw {cw:.4f}  mean {mean:.4f}  true {t:.4f} counts per deg/s")

# %%
# The rates and each turn's angle, integrated with the trapezoid rule after removing the bias
# measured in the rests.
rate = (rec.gyro - g.offset) / g.gain_counts_per_dps
angle = np.concatenate([[np.zeros(3)], np.cumsum((rate[1:] + rate[:-1]) / 2
                                                 * np.diff(rec.t)[:, None], axis=0)])
fig, (a1, a2) = plt.subplots(2, 1, figsize=(8, 5), sharex=True, layout="constrained")
for k, axis in enumerate("xyz"):
    a1.plot(rec.t, rate[:, k], lw=0.8, label=axis)
    a2.plot(rec.t, angle[:, k], lw=1.0, label=axis)
a1.set_ylabel("rate (deg/s)")
a2.set_ylabel("angle turned (deg)")
a2.set_xlabel("time (s)")
a2.set_yticks([-90, 0, 90])
a1.legend(ncol=3)
