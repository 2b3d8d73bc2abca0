"""
Allan deviation and noise figures
=================================

An hour of a gyroscope at rest, simulated with known noise: white noise (the angle random
walk), flicker (bias instability) and a rate random walk. The overlapping Allan deviation
shows each as its own slope; the IEEE 952 model fitted to every averaging time at once
recovers the three figures, with their units spelled out, and Kalibr's keys.
"""

import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import triaxcal as tc
from triaxcal.sim import NoiseTruth, simulate_noise

truth = NoiseTruth(white=0.005, bias_instability=0.003, random_walk=3e-4)   # deg/s units
gyro = simulate_noise(truth, 360_000, 100.0, seed=1)     # one hour at 100 Hz, deg/s
ad = tc.allan(gyro, 100.0, unit="deg/s")                   # overlapping Allan deviation
nf = tc.noise_figures(ad, sensor="gyro")
print(nf.text())
print(tc.kalibr_noise(gyro=nf))

# %%
# ``tc.plot_allan`` draws the deviation with the fitted model and its terms (here saved to a
# file and shown).
path = tc.plot_allan(nf, Path(tempfile.mkdtemp()) / "allan.png", dpi=70)
fig, ax = plt.subplots(figsize=(8, 6), layout="constrained")
ax.imshow(plt.imread(path))
ax.set_axis_off()
