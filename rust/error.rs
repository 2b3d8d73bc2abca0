//! One error type for the whole numerical core.
//!
//! Every variant says what was wrong with the input and what the user can do about it; the
//! binding layer (`rust/py/errors.rs`) maps each variant to a Python exception class that
//! subclasses `ValueError`.

use std::fmt;

/// Everything that can go wrong in the core. No function of the core panics on bad input.
#[derive(Debug, Clone, PartialEq)]
pub enum CalError {
    /// A coordinate is NaN or infinite.
    NonFinite {
        /// Zero-based index of the first offending point.
        index: usize,
    },
    /// Fewer points than the model can be determined from.
    TooFewPoints {
        /// How many points were given.
        got: usize,
        /// How many the model needs at least.
        need: usize,
        /// The model or method that was asked for.
        what: &'static str,
    },
    /// The points do not determine the model: they lie on a plane or a line, or cover too
    /// small a part of the sphere.
    Degenerate {
        /// What is degenerate, in words.
        why: String,
        /// What to do about it, in words.
        fix: String,
    },
    /// A reading of a stream (the Allan deviation's) is NaN or infinite.
    NonFiniteSample {
        /// Zero-based row in the whole stream.
        row: u64,
        /// Zero-based axis (column).
        axis: usize,
    },
    /// An option is out of range (a non-positive radius or step, an unknown model name...).
    InvalidArgument(String),
}

impl fmt::Display for CalError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            CalError::NonFinite { index } => write!(
                f,
                "point {index} has a NaN or infinite coordinate: drop or repair non-finite \
                 readings (e.g. points[np.isfinite(points).all(axis=1)]) before fitting"
            ),
            CalError::TooFewPoints { got, need, what } => write!(
                f,
                "{what} needs at least {need} points, got {got}: collect more orientations"
            ),
            CalError::Degenerate { why, fix } => write!(f, "{why}: {fix}"),
            CalError::NonFiniteSample { row, axis } => write!(
                f,
                "row {row} of the stream is NaN or inf (axis {axis}): drop or repair \
                 non-finite readings before computing the Allan deviation"
            ),
            CalError::InvalidArgument(msg) => f.write_str(msg),
        }
    }
}

impl std::error::Error for CalError {}

/// Result alias used throughout the core.
pub type Result<T> = std::result::Result<T, CalError>;

/// Fails with [`CalError::NonFinite`] at the first point with a NaN or infinite coordinate.
pub fn check_finite(points: &[[f64; 3]]) -> Result<()> {
    match points
        .iter()
        .position(|p| !(p[0].is_finite() && p[1].is_finite() && p[2].is_finite()))
    {
        Some(index) => Err(CalError::NonFinite { index }),
        None => Ok(()),
    }
}

/// Fails with [`CalError::InvalidArgument`] unless `value` is finite and strictly positive.
pub fn check_positive(name: &str, value: f64) -> Result<()> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(CalError::InvalidArgument(format!(
            "{name} must be a finite number greater than zero, got {value}"
        )))
    }
}
