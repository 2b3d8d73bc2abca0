"""
The validity gate refuses logs that cannot calibrate
====================================================

A fit can converge and still not be a calibration. Every command that writes or ships one
passes it through the validity gate, which refuses it (exit status 2, nothing written) and says
in words why and what to record instead. Three cases: a PX4 flight log (``sample.ulg`` of
pyulog's test data), whose flight turned the magnetometer through a small cap of directions
only; a ROS bag (``ardrone_imu.bag`` of the imu_tools test data) whose driver published the
field's direction only; and a gyroscope that never turned (simulated).
"""

import contextlib
import io
import tempfile
import textwrap
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import triaxcal as tc
from gallery_helpers import recording
from triaxcal.cli import main

work = Path(tempfile.mkdtemp())


def fit(*args):
    """Run ``triaxcal fit ...`` through the command line's own entry point; show its verdict."""
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        status = main(["fit", *map(str, args), "-o", str(work / "cal.json")])
    print(f"exit status {status}; cal.json written: {(work / 'cal.json').exists()}")
    print(textwrap.fill(err.getvalue(), 80))


ulog = recording("px4-pyulog-samples/sample.ulg")
fit(ulog, "--sensor", "mag")

# %%
fit(recording("ros1-imu-tools-madgwick/ardrone_imu.bag"), "--sensor", "mag")

# %%
# A board left lying still: a sphere fit of its gyroscope is not a calibration.
imu = tc.sim.SimIMU(seed=2)
still = imu.record(tc.sim.Script.from_moves(np.eye(3), np.zeros((0, 3)), hold_s=60.0),
                   rate_hz=50)
np.savetxt(work / "still.csv", np.column_stack([still.t, still.frames(10)]), delimiter=",",
           header="t,ax,ay,az,gx,gy,gz,mx,my,mz,temp", comments="", fmt="%.6g")
fit(work / "still.csv", "--sensor", "gyro")

# %%
# In Python the same gate is :func:`triaxcal.check_part`; a part forced through it carries
# the reasons (``part.valid``, ``part.invalid_reasons``) and every export refuses it again.
#
# Why the flight log cannot calibrate: the directions of its magnetometer readings (right)
# against a simulated tumble (left). A flight turns about the vertical and tilts a little;
# a calibration needs directions all round the sphere.
flight = tc.read_log(ulog).mag.data
tumble = tc.sim.SimIMU(seed=2).record(tc.sim.globe_script(), rate_hz=50).mag
fig, axes = plt.subplots(1, 2, figsize=(8, 4), layout="constrained",
                         subplot_kw={"projection": "3d"})
for ax, pts, title in [(axes[0], tumble, "simulated tumble: accepted"),
                       (axes[1], flight, "PX4 flight: refused")]:
    d = pts - np.median(pts, axis=0) if pts is tumble else pts
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    ax.scatter(*d[:: max(1, len(d) // 1500)].T, s=3)
    ax.set_title(title)
    ax.set_box_aspect((1, 1, 1))
    for lim in (ax.set_xlim, ax.set_ylim, ax.set_zlim):
        lim(-1, 1)
