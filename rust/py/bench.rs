//! Benchmark hooks, compiled only with the `bench-hooks` cargo feature: the development build
//! (`make install`) enables it for `benches/`; the released wheel (`make wheel`) does not, so
//! the product module carries no benchmark code.

use super::errors::{py_result, CalibrationError};
use super::fit::{points_under_gil, ready_points, HOLD_GIL_UP_TO};
use crate::ellipsoid::{self, FitOptions};
use numpy::PyUntypedArrayMethods;
use pyo3::prelude::*;

/// Benchmark aid (`benches/bench_fit.py`, the call-overhead row): seconds per fit of `points`
/// with the facade's default options and `radius`, the fit run `repeats` times back to back in
/// Rust (no Python in between), so that a Python call's time minus this is what the call adds.
#[pyfunction]
pub(super) fn time_fit(
    py: Python<'_>,
    points: &Bound<'_, PyAny>,
    radius: Option<f64>,
    repeats: usize,
) -> PyResult<f64> {
    let arr = ready_points(points)
        .filter(|a| a.shape()[0] <= HOLD_GIL_UP_TO)
        .ok_or_else(|| {
            CalibrationError::new_err(format!(
                "time_fit times small fits: an aligned, C-contiguous float64 (N, 3) array of \
                 at most {HOLD_GIL_UP_TO} points"
            ))
        })?;
    let opts = FitOptions {
        radius,
        ..FitOptions::default()
    };
    let pts = points_under_gil(py, arr);
    let t0 = std::time::Instant::now();
    for _ in 0..repeats.max(1) {
        py_result(ellipsoid::fit_ellipsoid(std::hint::black_box(pts), &opts))?;
    }
    Ok(t0.elapsed().as_secs_f64() / repeats.max(1) as f64)
}

/// Benchmark aid (`benches/instructions.py`): calls `f()` `times` times. The instruction-count
/// guard counts what runs inside this function (callgrind's `--toggle-collect`), so that
/// starting Python and importing modules, which do not execute the same instructions from one
/// run to the next, stay out of the count.
#[pyfunction]
pub(super) fn repeat_call(f: &Bound<'_, PyAny>, times: usize) -> PyResult<()> {
    for _ in 0..times {
        f.call0()?;
    }
    Ok(())
}
