"""
Gyroscope bias against temperature
==================================

A board cooled to 10 deg C warms up to 30 deg C lying still. Its gyroscope bias drifts with the
temperature (here 3, -2 and 1.5 counts per deg C); a straight line in the temperature change
since the start, fitted per axis, removes it: ``offset(T) = offset + c1 (T - T_ref)``.
"""

import matplotlib.pyplot as plt
import numpy as np
import triaxcal as tc

imu = tc.sim.SimIMU(1, gyro={"tempco": [3.0, -2.0, 1.5]})          # counts per deg C
still = tc.sim.Script.from_moves(np.eye(3), np.zeros((0, 3)), hold_s=600.0)   # 10 minutes
rec = imu.record(still, rate_hz=50, temp_c=(10.0, 30.0))

m = tc.fit_temperature(rec.gyro, rec.temp_c, degree=1)
print("slope per deg C", np.round(m.offset_coef[1], 3), "counts (true 3, -2, 1.5)")
print(f"fitted over {m.t_min_degC:.1f} .. {m.t_max_degC:.1f} deg C, residual RMS",
      np.round(m.rms, 2), "counts")

# %%
# The bias against temperature, with the fitted lines, and what is left after applying them.
step = 50
fig, (a1, a2) = plt.subplots(1, 2, figsize=(9, 3.8), layout="constrained")
temps = np.linspace(m.t_min_degC, m.t_max_degC, 50)
line_of = m.offset(temps)                  # offset(T), counts
left = rec.gyro - m.offset(rec.temp_c)     # what the temperature terms leave
for k, axis in enumerate("xyz"):
    (dots,) = a1.plot(rec.temp_c[::step], rec.gyro[::step, k], ".", ms=2, label=axis)
    a1.plot(temps, line_of[:, k], color=dots.get_color(), lw=1)
    a2.plot(rec.temp_c[::step], left[::step, k], ".", ms=2, color=dots.get_color())
a1.set_xlabel("temperature (deg C)")
a1.set_ylabel("gyro at rest (counts)")
a1.legend()
a2.set_xlabel("temperature (deg C)")
a2.set_ylabel("minus offset(T) (counts)")
