"""
Sphere-centre descent: the offset alone
=======================================

When the scale is known (16384 counts per g for a 16-bit +-2 g accelerometer) and only the
offset is wanted, the offset is the centre of the sphere of that radius on which still
readings lie. The variable-step descent searches for the point where
``sum |(x - cx)^2 + (y - cy)^2 + (z - cz)^2 - R^2|`` is least: from the origin, step to the
best of the 26 neighbours, divide the step by ten when none is better. Here on the globe
scheme of a simulated board with exactly 16384 counts per g.
"""

import matplotlib.pyplot as plt
import numpy as np
import triaxcal as tc

imu = tc.sim.SimIMU(1, accel={"scale": [1.0, 1.0, 1.0]})   # 16384 counts per g on every axis
rec = imu.record(tc.sim.globe_script(), rate_hz=100)
points = rec.pose_means("accel")                            # the 84 pose means, counts
truth = imu.truth.accel.offset

d = tc.descend_center(points, 16384.0)
ls = tc.fit_sphere(points, radius=16384.0, scale="fixed")
for name, c in [("descent", d.center), ("least squares", ls.offset),
                ("mean of the readings", points.mean(0)), ("truth", truth)]:
    print(f"{name:22s}", np.round(c, 2), f"off by {np.linalg.norm(c - truth):6.2f} counts")
print(f"descent: {d.iterations} steps, {d.evaluations} error sums")

# %%
# The error sum round the answer, on a slice through the true centre: the descent ends in its
# minimum, the plain mean of the readings (which the method warns against) does not.
xs = np.linspace(truth[0] - 150, truth[0] + 150, 61)
ys = np.linspace(truth[1] - 150, truth[1] + 150, 61)
err = np.array([[tc.sphere_error(points, [x, y, truth[2]], 16384.0) for x in xs] for y in ys])
fig, ax = plt.subplots(figsize=(6, 5), layout="constrained")
cs = ax.contourf(xs, ys, np.log10(err), levels=20)
fig.colorbar(cs, label="log10 error sum (counts^2)")
ax.plot(*d.center[:2], "r*", ms=12, label="descent")
ax.plot(*truth[:2], "wx", ms=10, label="truth")
ax.set_xlabel("centre x (counts)")
ax.set_ylabel("centre y (counts)")
ax.legend()
