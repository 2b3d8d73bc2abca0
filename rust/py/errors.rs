//! Core errors to Python exceptions, in one place. Every class subclasses `ValueError`.

use crate::error::CalError;
use pyo3::create_exception;
use pyo3::exceptions::PyValueError;
use pyo3::PyErr;

create_exception!(
    triaxcal,
    CalibrationError,
    PyValueError,
    "The input cannot be calibrated; the message says what is wrong and what to do."
);
create_exception!(
    triaxcal,
    NonFiniteError,
    CalibrationError,
    "A reading is NaN or infinite."
);
create_exception!(
    triaxcal,
    TooFewPointsError,
    CalibrationError,
    "Fewer readings than the model or method needs."
);
create_exception!(
    triaxcal,
    DegenerateDataError,
    CalibrationError,
    "The readings do not determine the model (a plane, a line, too small a cap of the sphere)."
);

/// Wraps a core error so that `?` converts it into the right Python exception.
pub struct CoreError(pub CalError);

impl From<CalError> for CoreError {
    fn from(e: CalError) -> Self {
        CoreError(e)
    }
}

impl From<CoreError> for PyErr {
    fn from(e: CoreError) -> PyErr {
        let msg = e.0.to_string();
        match e.0 {
            CalError::NonFinite { .. } | CalError::NonFiniteSample { .. } => {
                NonFiniteError::new_err(msg)
            }
            CalError::TooFewPoints { .. } => TooFewPointsError::new_err(msg),
            CalError::Degenerate { .. } => DegenerateDataError::new_err(msg),
            CalError::InvalidArgument(_) => CalibrationError::new_err(msg),
        }
    }
}

/// Converts a core result into a Python result.
pub fn py_result<T>(r: crate::error::Result<T>) -> Result<T, PyErr> {
    r.map_err(|e| CoreError(e).into())
}
