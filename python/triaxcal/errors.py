"""Exception classes. All subclass :class:`CalibrationError`, itself a :class:`ValueError`.

Every message says what was wrong and what to do about it.
"""

from ._core import (
    CalibrationError,
    DegenerateDataError,
    NonFiniteError,
    TooFewPointsError,
)

__all__ = ["CalibrationError", "DegenerateDataError", "NonFiniteError", "TooFewPointsError"]
