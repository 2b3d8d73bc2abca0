//! The binding layer: the only code that names pyo3 or numpy. Each wrapper extracts borrowed
//! numpy arrays, releases the GIL, calls the core, and returns plain values; the Python facade
//! (`python/triaxcal/`) validates input first and builds the result objects. The exception is
//! `fit_ellipsoid` (`fit.rs`): it checks plain arguments itself, keeps the GIL for small fits
//! and builds the `EllipsoidFit`, for the sake of small calls.

mod allan;
#[cfg(feature = "bench-hooks")]
mod bench;
mod bounds;
mod errors;
mod fit;
mod logs;

use crate::batch;
use crate::ellipsoid::{self, FitOptions, Method, Model};
use crate::error::CalError;
use crate::sphere::{self, Descent, DescentOptions};
use errors::{py_result, CalibrationError, DegenerateDataError, NonFiniteError, TooFewPointsError};
use numpy::{
    Ix1, Ix2, Ix3, PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2,
    PyUntypedArrayMethods,
};
use pyo3::intern;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyInt, PyList};

/// Borrows an (N, 3) aligned, C-contiguous float64 array as points, without copying. (The
/// Python facade converts anything else first: `triaxcal._checks.arrays.as_points`.)
fn points<'a>(arr: &'a PyReadonlyArray2<'_, f64>) -> PyResult<&'a [[f64; 3]]> {
    let shape = arr.shape();
    if shape[1] != 3 {
        return Err(CalibrationError::new_err(format!(
            "points must have shape (N, 3), got (N, {}): pass one row per reading with x, y, z",
            shape[1]
        )));
    }
    let not_c = || {
        CalibrationError::new_err(
            "points must be an aligned, C-contiguous float64 array: call the triaxcal \
             functions, which convert any array, rather than triaxcal._core",
        )
    };
    if !arr.is_c_contiguous() {
        return Err(not_c());
    }
    let flat = arr.as_slice().map_err(|_| not_c())?;
    let (chunks, _) = flat.as_chunks::<3>();
    Ok(chunks)
}

fn descent_dict<'py>(py: Python<'py>, d: Descent) -> PyResult<Bound<'py, PyDict>> {
    let out = PyDict::new(py);
    out.set_item("center", d.center.to_vec())?;
    out.set_item("error", d.error)?;
    out.set_item("iterations", d.iterations)?;
    out.set_item("evaluations", d.evaluations)?;
    out.set_item("step", d.step)?;
    out.set_item("converged", d.converged)?;
    Ok(out)
}

fn options(
    model: &str,
    radius: Option<f64>,
    max_iter: usize,
    tol: f64,
    method: &str,
    debias: bool,
    fixed: Option<[Option<f64>; 9]>,
) -> PyResult<FitOptions> {
    Ok(FitOptions {
        debias,
        diagnostics: true,
        fixed: fixed.unwrap_or([None; 9]),
        model: py_result(Model::parse(model))?,
        radius,
        max_iter,
        tol,
        method: py_result(Method::parse(method))?,
        parallel: true,
    })
}

/// Σ |‖p − center‖² − radius²| over the points.
#[pyfunction]
fn sphere_error(
    py: Python<'_>,
    points: PyReadonlyArray2<'_, f64>,
    center: [f64; 3],
    radius: f64,
) -> PyResult<f64> {
    let pts = self::points(&points)?;
    py_result(py.detach(|| sphere::sphere_error(pts, center, radius)))
}

/// Variable-step 26-neighbour descent for the centre of a sphere of known radius.
#[pyfunction]
#[pyo3(signature = (points, radius, *, start, step, min_step, shrink, max_iter))]
fn descend_center<'py>(
    py: Python<'py>,
    points: PyReadonlyArray2<'py, f64>,
    radius: f64,
    start: [f64; 3],
    step: f64,
    min_step: f64,
    shrink: f64,
    max_iter: usize,
) -> PyResult<Bound<'py, PyDict>> {
    let pts = self::points(&points)?;
    let opts = DescentOptions {
        start,
        step,
        min_step,
        shrink,
        max_iter,
    };
    let d = py_result(py.detach(|| sphere::descend_center(pts, radius, opts)))?;
    descent_dict(py, d)
}

/// Brute-force cube search for the centre of a sphere of known radius.
#[pyfunction]
#[pyo3(signature = (points, radius, *, lo, hi, step))]
fn grid_center<'py>(
    py: Python<'py>,
    points: PyReadonlyArray2<'py, f64>,
    radius: f64,
    lo: [f64; 3],
    hi: [f64; 3],
    step: f64,
) -> PyResult<Bound<'py, PyDict>> {
    let pts = self::points(&points)?;
    let d = py_result(py.detach(|| sphere::grid_center(pts, radius, lo, hi, step)))?;
    descent_dict(py, d)
}

/// Linear least-squares sphere fit: (center, radius, rms).
#[pyfunction]
fn fit_sphere_linear(
    py: Python<'_>,
    points: PyReadonlyArray2<'_, f64>,
) -> PyResult<([f64; 3], f64, f64)> {
    let pts = self::points(&points)?;
    let f = py_result(py.detach(|| sphere::fit_sphere_linear(pts)))?;
    Ok((f.center, f.radius, f.rms))
}

/// Fits many sets: `points` holds them back to back, set i is rows `bounds[i]..bounds[i+1]`;
/// `bounds` may instead be a positive int `n`: sets of `n` rows each (the rows a whole number
/// of them). Returns a dict of read-only arrays: offsets (B, 3), matrices (B, 3, 3), radii,
/// rms, converged, iterations; and the lists errors and error_kinds.
#[pyfunction]
#[pyo3(signature = (points, bounds, model, radius, max_iter, tol, method, debias, fixed=None))]
fn fit_batch<'py>(
    py: Python<'py>,
    points: PyReadonlyArray2<'py, f64>,
    bounds: &Bound<'py, PyAny>,
    model: &str,
    radius: Option<f64>,
    max_iter: usize,
    tol: f64,
    method: &str,
    debias: bool,
    fixed: Option<[Option<f64>; 9]>,
) -> PyResult<Bound<'py, PyDict>> {
    let pts = self::points(&points)?;
    let mut opts = options(model, radius, max_iter, tol, method, debias, fixed)?;
    opts.diagnostics = false; // a batch reports no warnings
    let out_of_range = || CalibrationError::new_err("batch bounds out of range");
    let sets: Vec<&[[f64; 3]]> = if bounds.is_exact_instance_of::<PyInt>() {
        // sets of equal size: no bounds array to make and borrow
        let size: usize = bounds.extract().map_err(|_| out_of_range())?;
        if size == 0 || pts.len() % size != 0 {
            return Err(out_of_range());
        }
        pts.chunks_exact(size).collect()
    } else {
        let bounds = bounds.extract::<PyReadonlyArray1<'py, i64>>()?;
        let b = bounds
            .as_slice()
            .map_err(|_| CalibrationError::new_err("bounds must be contiguous"))?;
        let mut sets = Vec::with_capacity(b.len().saturating_sub(1));
        for w in b.windows(2) {
            let (lo, hi) = (w[0], w[1]);
            if lo < 0 || hi < lo || hi as usize > pts.len() {
                return Err(out_of_range());
            }
            sets.push(&pts[lo as usize..hi as usize]);
        }
        sets
    };
    let results = py.detach(|| batch::fit_batch(&sets, &opts));
    let nb = results.len();
    let mut offsets = vec![f64::NAN; nb * 3];
    let mut matrices = vec![f64::NAN; nb * 9];
    let mut radii = vec![f64::NAN; nb];
    let mut rms = vec![f64::NAN; nb];
    let mut converged = vec![false; nb];
    let mut iterations = vec![0i64; nb];
    let errors = PyList::empty(py);
    let kinds = PyList::empty(py);
    for (i, r) in results.into_iter().enumerate() {
        match r {
            Ok(f) => {
                offsets[3 * i..3 * i + 3].copy_from_slice(&f.offset);
                matrices[9 * i..9 * i + 9].copy_from_slice(f.matrix.as_flattened());
                radii[i] = f.radius;
                rms[i] = f.rms;
                converged[i] = f.converged;
                iterations[i] = f.iterations as i64;
                errors.append(py.None())?;
                kinds.append(py.None())?;
            }
            Err(e) => {
                kinds.append(match e {
                    CalError::NonFinite { .. } | CalError::NonFiniteSample { .. } => {
                        "NonFiniteError"
                    }
                    CalError::TooFewPoints { .. } => "TooFewPointsError",
                    CalError::Degenerate { .. } => "DegenerateDataError",
                    CalError::InvalidArgument(_) => "CalibrationError",
                })?;
                errors.append(e.to_string())?;
            }
        }
    }
    // read-only arrays of their final shapes, made at once (no reshape, no flags to set)
    let out = PyDict::new(py);
    out.set_item(
        intern!(py, "offsets"),
        fit::frozen(py, &offsets, Ix2(nb, 3))?,
    )?;
    out.set_item(
        intern!(py, "matrices"),
        fit::frozen(py, &matrices, Ix3(nb, 3, 3))?,
    )?;
    out.set_item(intern!(py, "radii"), fit::frozen(py, &radii, Ix1(nb))?)?;
    out.set_item(intern!(py, "rms"), fit::frozen(py, &rms, Ix1(nb))?)?;
    out.set_item(
        intern!(py, "converged"),
        fit::frozen(py, &converged, Ix1(nb))?,
    )?;
    out.set_item(
        intern!(py, "iterations"),
        fit::frozen(py, &iterations, Ix1(nb))?,
    )?;
    out.set_item(intern!(py, "errors"), errors)?;
    out.set_item(intern!(py, "error_kinds"), kinds)?;
    Ok(out)
}

/// Applies offset and matrix: (N, 3) -> (N, 3).
#[pyfunction]
fn apply<'py>(
    py: Python<'py>,
    points: PyReadonlyArray2<'py, f64>,
    offset: [f64; 3],
    matrix: [[f64; 3]; 3],
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let pts = self::points(&points)?;
    let out = py.detach(|| {
        let mut out = vec![[0.0; 3]; pts.len()];
        ellipsoid::apply(pts, offset, matrix, &mut out);
        out.into_iter().flatten().collect::<Vec<f64>>()
    });
    PyArray1::from_vec(py, out).reshape([pts.len(), 3])
}

/// The compiled core of triaxcal. Use the `triaxcal` package, not this module.
#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("CalibrationError", py.get_type::<CalibrationError>())?;
    m.add("NonFiniteError", py.get_type::<NonFiniteError>())?;
    m.add("TooFewPointsError", py.get_type::<TooFewPointsError>())?;
    m.add("DegenerateDataError", py.get_type::<DegenerateDataError>())?;
    m.add_function(wrap_pyfunction!(sphere_error, m)?)?;
    m.add_function(wrap_pyfunction!(descend_center, m)?)?;
    m.add_function(wrap_pyfunction!(grid_center, m)?)?;
    m.add_function(wrap_pyfunction!(fit_sphere_linear, m)?)?;
    m.add_function(wrap_pyfunction!(fit::fit_ellipsoid, m)?)?;
    #[cfg(feature = "bench-hooks")]
    {
        m.add_function(wrap_pyfunction!(bench::time_fit, m)?)?;
        m.add_function(wrap_pyfunction!(bench::repeat_call, m)?)?;
    }
    m.add_function(wrap_pyfunction!(fit_batch, m)?)?;
    m.add_function(wrap_pyfunction!(apply, m)?)?;
    m.add_class::<allan::AllanStream>()?;
    m.add_function(wrap_pyfunction!(logs::read_ulog, m)?)?;
    m.add_function(wrap_pyfunction!(logs::read_dataflash, m)?)?;
    bounds::add(m)?;
    Ok(())
}
