"""Exception classes. All subclass :class:`CalibrationError`, itself a :class:`ValueError`.

Every message says what was wrong and what to do about it.
"""

from ._core import (
    CalibrationError,
    DegenerateDataError,
    NonFiniteError,
    TooFewPointsError,
)

__all__ = ["CalibrationError", "DegenerateDataError", "NonFiniteError", "RefusedError",
           "TooFewPointsError"]


class RefusedError(CalibrationError):
    """The data were read and understood, but what they would give is refused: a fit that is not
    a calibration (:class:`triaxcal.calibration.gate.InvalidCalibrationError`), noise figures
    of readings that moved (:class:`triaxcal.methods.rest.NotAtRestError`). The message says
    why and what to record instead; the command line exits with status 2 (a refusal, not a
    failure to run), and ``--force`` goes on anyway where that makes sense, marking the result."""

    #: How the command line introduces the message.
    verb = "refused"
