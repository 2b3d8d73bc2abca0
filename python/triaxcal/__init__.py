"""triaxcal: calibrate three-axis accelerometers, gyroscopes and magnetometers.

Fits run in Rust (``triaxcal._core``); capture, methods, export and the command line are
Python. Calibrated readings are ``(raw - offset) @ matrix.T``: the matrix *multiplies*.

The public names come from the packages of the pipeline, in its order, each listing its own in
its ``__all__``: reading (:mod:`triaxcal.io`), still poses (:mod:`triaxcal.detect`), fits
(:mod:`triaxcal.fit`), calibration methods (:mod:`triaxcal.methods`), calibrations and the
validity gate (:mod:`triaxcal.calibration`), the quality report (:mod:`triaxcal.report`) and
exports (:mod:`triaxcal.export`); with the errors, the mounting rotations and the simulator.
"""

from . import calibration, detect, errors, export, fit, io, methods, report, sim
from ._core import __version__
from .calibration import *  # noqa: F403
from .conventions import rotations
from .detect import *  # noqa: F403
from .errors import *  # noqa: F403
from .export import *  # noqa: F403
from .fit import *  # noqa: F403
from .io import *  # noqa: F403
from .methods import *  # noqa: F403
from .report import *  # noqa: F403

__all__ = ["__version__", "rotations", "sim"]
__all__ += errors.__all__
__all__ += io.__all__
__all__ += detect.__all__
__all__ += fit.__all__
__all__ += methods.__all__
__all__ += calibration.__all__
__all__ += report.__all__
__all__ += export.__all__
