"""
The quality report of a real magnetometer
==========================================

Three hundred hand-tumbled readings of an ICM-20948 magnetometer (jremington's
``ICM_20948-AHRS`` project, file ``icm_20948_cal_mag.csv``, raw counts): the robust fit, the
report in words and its figure -- raw readings with the fitted ellipsoid, calibrated readings
with the circle of the radius, the residuals, the coverage map with the largest empty cap, and
the calibrated length of every reading.
"""

import numpy as np
import triaxcal as tc
from gallery_helpers import recording, show
from triaxcal.report.figure import report_figure

raw = np.loadtxt(recording("icm20948-magneto/icm_20948_cal_mag.csv"), delimiter=",")
r = tc.fit_robust(raw, model="auto", radius=48.0)      # the local field, uT
part = tc.SensorCalibration.from_fit(r.fit, unit="uT", points=raw[r.inliers],
                                     rejected=r.rejected)
report = tc.quality_report(raw, part, sensor="mag", model_reason=r.model_reason)
print(report.text())

# %%
# The figure ``triaxcal report --plot`` draws (``tc.plot_report`` saves it; ``report_figure``
# returns it unsaved).
show(report_figure(raw, part, report=report, sensor="mag", dpi=60))
