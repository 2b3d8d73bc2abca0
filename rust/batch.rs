//! Many data sets at once (a production line: thousands of boards), in parallel with rayon.
//!
//! Each set is fitted on its own with the options given (see `ellipsoid`); the sets run in
//! parallel and each fit runs single-threaded, without the coverage diagnostics (a batch
//! reports no warnings). A bad set yields its own error and does not spoil the others.

use crate::ellipsoid::{fit_ellipsoid, EllipsoidFit, FitOptions};
use crate::error::{CalError, Result};
use rayon::prelude::*;

/// Fits every set in `sets`; the result has one entry per set, in order.
///
/// ```
/// use triaxcal::batch::fit_batch;
/// use triaxcal::ellipsoid::{FitOptions, Model};
/// let good = [[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, -1.0]];
/// let bad = [[f64::NAN, 0.0, 0.0]; 6];
/// let out = fit_batch(&[&good[..], &bad[..]], &FitOptions { model: Model::Sphere, ..Default::default() });
/// assert!(out[0].is_ok() && out[1].is_err());
/// ```
pub fn fit_batch(sets: &[&[[f64; 3]]], opts: &FitOptions) -> Vec<Result<EllipsoidFit>> {
    let inner = FitOptions {
        parallel: false,
        diagnostics: false,
        ..*opts
    };
    sets.par_iter()
        .map(|s| {
            std::panic::catch_unwind(|| fit_ellipsoid(s, &inner)).unwrap_or_else(|_| {
                Err(CalError::InvalidArgument(
                    "internal error while fitting this set (please report it with the data)".into(),
                ))
            })
        })
        .collect()
}
