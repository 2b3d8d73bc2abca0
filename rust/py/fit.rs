//! `fit_ellipsoid` from Python at the lowest cost a call can have: the binding takes the
//! arguments as the user passed them, and when each is already in the form the facade would
//! turn it into (an exact float64 ndarray of shape (N, 3), aligned and C-contiguous; a model and
//! method by name; a finite positive radius or None; whole-number `max_iter`; a float `tol`;
//! a bool `debias`) it fits and builds the `triaxcal.fit.EllipsoidFit` itself. Anything else
//! returns `None` and the facade validates and converts (one place for the messages: the
//! Python `_check_options` and `as_points`), then calls again.
//!
//! The fast checks accept a subset of what the facade accepts, never more: a value they let
//! through is valid (`tests/test_fit_call.py` checks that against the facade's validation).

use super::errors::{py_result, CalibrationError};
use crate::ellipsoid::{self, EllipsoidFit, FitOptions, Method, Model};
use numpy::npyffi::{objects::_PyArray_GET_ITEM_DATA, NPY_ARRAY_WRITEABLE};
use numpy::{PyArray, PyArray2, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::intern;
use pyo3::prelude::*;
use pyo3::sync::PyOnceLock;
use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PyString, PyTuple, PyType};

/// Up to this many points a fit takes under about 0.3 ms (211 instructions a point): it keeps
/// the GIL rather than releasing and re-taking it around the fit, and reads the points in place
/// under it. Larger fits borrow them through numpy's borrow checker and release the GIL.
pub(super) const HOLD_GIL_UP_TO: usize = 1024;

/// What the binding takes from the facade's module (`triaxcal.fit`, the module of the class it
/// is given), once: `MAX_ITER`, `PARAM_NAMES` per model (sphere, axis, full) and
/// `object.__new__`. One source for each: the facade's.
struct Facade {
    max_iter: usize,
    param_names: [Py<PyTuple>; 3],
    object_new: Py<PyAny>,
}

fn facade<'a>(py: Python<'_>, cls: &Bound<'_, PyType>) -> PyResult<&'a Facade> {
    static FACADE: PyOnceLock<Facade> = PyOnceLock::new();
    FACADE.get_or_try_init(py, || {
        let module = PyModule::import(
            py,
            cls.getattr(intern!(py, "__module__"))?.cast::<PyString>()?,
        )?;
        let names = module.getattr("PARAM_NAMES")?;
        let t = |m: &str| -> PyResult<Py<PyTuple>> {
            Ok(names.get_item(m)?.cast_into::<PyTuple>()?.unbind())
        };
        Ok(Facade {
            max_iter: module.getattr("MAX_ITER")?.extract()?,
            param_names: [t("sphere")?, t("axis")?, t("full")?],
            object_new: PyModule::import(py, "builtins")?
                .getattr("object")?
                .getattr("__new__")?
                .unbind(),
        })
    })
}

fn model_index(m: Model) -> usize {
    match m {
        Model::Sphere => 0,
        Model::Axis => 1,
        Model::Full => 2,
    }
}

/// A float or an int (not a bool) as f64, if `v` is exactly one of those types.
fn exact_real(v: &Bound<'_, PyAny>) -> Option<f64> {
    if let Ok(f) = v.cast_exact::<PyFloat>() {
        return Some(f.value());
    }
    if v.is_exact_instance_of::<PyInt>() {
        return v.extract::<f64>().ok(); // None if too large for a float
    }
    None
}

/// The value paired with the name `v` is (`v` an exact str), if any. Names in Python source
/// are interned, so the identity test settles the usual case without comparing characters.
fn one_of<T: Copy, const K: usize>(
    v: &Bound<'_, PyAny>,
    names: [(&Bound<'_, PyString>, T); K],
) -> Option<T> {
    if !v.is_exact_instance_of::<PyString>() {
        return None;
    }
    let hit = |(name, value): &(&Bound<'_, PyString>, T)| v.is(*name).then_some(*value);
    names.iter().find_map(hit).or_else(|| {
        names
            .iter()
            .find_map(|(name, value)| v.eq(*name).ok()?.then_some(*value))
    })
}

/// The options, if every one is already valid and of its plain Python type; `None` otherwise.
#[allow(clippy::too_many_arguments)]
fn exact_options(
    model: &Bound<'_, PyAny>,
    radius: &Bound<'_, PyAny>,
    max_iter: &Bound<'_, PyAny>,
    tol: &Bound<'_, PyAny>,
    method: &Bound<'_, PyAny>,
    debias: &Bound<'_, PyAny>,
    fixed: Option<[Option<f64>; 9]>,
    most_iter: usize,
) -> Option<FitOptions> {
    let py = model.py();
    let model = one_of(
        model,
        [
            (intern!(py, "sphere"), Model::Sphere),
            (intern!(py, "axis"), Model::Axis),
            (intern!(py, "full"), Model::Full),
        ],
    )?;
    let method = one_of(
        method,
        [
            (intern!(py, "lm"), Method::LevenbergMarquardt),
            (intern!(py, "gn"), Method::GaussNewton),
            (intern!(py, "algebraic"), Method::Algebraic),
        ],
    )?;
    let radius = if radius.is_none() {
        None
    } else {
        Some(exact_real(radius).filter(|r| r.is_finite() && *r > 0.0)?)
    };
    if !max_iter.is_exact_instance_of::<PyInt>() {
        return None;
    }
    let max_iter = max_iter
        .extract::<usize>()
        .ok()
        .filter(|&m| m <= most_iter)?;
    let tol = exact_real(tol).filter(|t| (0.0..1.0).contains(t))?;
    let debias = debias.cast_exact::<PyBool>().ok()?.is_true();
    Some(FitOptions {
        debias,
        diagnostics: true,
        fixed: fixed.unwrap_or([None; 9]),
        model,
        radius,
        max_iter,
        tol,
        method,
        parallel: true,
    })
}

/// `points` as an exact, aligned, C-contiguous float64 (N, 3) ndarray, or `None`.
pub(super) fn ready_points<'a, 'py>(
    points: &'a Bound<'py, PyAny>,
) -> Option<&'a Bound<'py, PyArray2<f64>>> {
    let arr = points.cast_exact::<PyArray2<f64>>().ok()?;
    (arr.shape()[1] == 3 && arr.is_c_contiguous() && arr.is_aligned()).then_some(arr)
}

/// A new read-only array of `shape` holding `values` (row-major).
pub(super) fn frozen<'py, T: numpy::Element + Clone, D: numpy::ndarray::Dimension>(
    py: Python<'py>,
    values: &[T],
    shape: D,
) -> PyResult<Bound<'py, PyArray<T, D>>> {
    let view = numpy::ndarray::ArrayView::from_shape(shape, values)
        .map_err(|e| CalibrationError::new_err(format!("internal: result shape: {e}")))?;
    let arr = PyArray::from_array(py, &view);
    clear_writeable(&arr);
    Ok(arr)
}

/// Clears numpy's WRITEABLE flag of an array made here and not yet shared, directly, as
/// rust-numpy's own `make_nonwriteable` does, without going through its borrow checker (which
/// allocates a hash table per borrow: about 1,000 instructions, a tenth of a fit of 10 points).
#[allow(unsafe_code)]
fn clear_writeable<T, D>(arr: &Bound<'_, PyArray<T, D>>) {
    // SAFETY: the GIL is held and the array is new: no view of it, Rust or Python, exists yet.
    unsafe { (*_PyArray_GET_ITEM_DATA(arr.as_array_ptr())).flags &= !NPY_ARRAY_WRITEABLE }
}

/// The points of a ready array, read in place while the GIL is held (`py` proves it, and the
/// slice cannot outlive the array's borrow), without numpy's borrow checker (about 3,500
/// instructions a call, a third of the binding's own cost). While the GIL is held no Python
/// code can write to the array, and triaxcal never takes a mutable view of a caller's array.
/// (Native code writing to it from another thread without the GIL would race with this read
/// as it would with any numpy function reading it; rust-numpy's checker does not see such
/// writers either.)
#[allow(unsafe_code)]
pub(super) fn points_under_gil<'a>(
    _py: Python<'_>,
    arr: &'a Bound<'_, PyArray2<f64>>,
) -> &'a [[f64; 3]] {
    // SAFETY: as above; `ready_points` checked that the array is C-contiguous and aligned, of
    // float64 and shape (N, 3).
    let flat = unsafe { arr.as_slice() }.expect("checked contiguous and aligned");
    flat.as_chunks::<3>().0
}

/// The `EllipsoidFit` dataclass filled in directly: `object.__new__(cls)` and the same fields
/// its generated `__init__` would set (a test checks that they are exactly the dataclass's).
fn fit_object<'py>(
    py: Python<'py>,
    cls: &Bound<'py, PyType>,
    facade: &Facade,
    f: EllipsoidFit,
    fixed_names: &Bound<'py, PyTuple>,
) -> PyResult<Bound<'py, PyAny>> {
    let obj = facade.object_new.bind(py).call1((cls,))?;
    let d = obj.getattr(intern!(py, "__dict__"))?;
    let d = d.cast::<PyDict>()?;

    let offset = frozen(py, &f.offset, numpy::Ix1(3))?;
    let matrix = frozen(py, f.matrix.as_flattened(), numpy::Ix2(3, 3))?;
    let stderr = frozen(py, &f.stderr, numpy::Ix1(f.stderr.len()))?;
    let m = model_index(f.model);
    let model = match f.model {
        Model::Sphere => intern!(py, "sphere"),
        Model::Axis => intern!(py, "axis"),
        Model::Full => intern!(py, "full"),
    };
    d.set_item(intern!(py, "model"), model)?;
    d.set_item(intern!(py, "offset"), offset)?;
    d.set_item(intern!(py, "matrix"), matrix)?;
    d.set_item(intern!(py, "radius"), f.radius)?;
    d.set_item(intern!(py, "rms"), f.rms)?;
    d.set_item(intern!(py, "stderr"), stderr)?;
    d.set_item(intern!(py, "param_names"), facade.param_names[m].bind(py))?;
    d.set_item(intern!(py, "iterations"), f.iterations)?;
    d.set_item(intern!(py, "converged"), f.converged)?;
    d.set_item(intern!(py, "condition"), f.condition)?;
    d.set_item(intern!(py, "n"), f.n)?;
    d.set_item(intern!(py, "warnings"), PyTuple::new(py, f.warnings)?)?;
    d.set_item(intern!(py, "model_reason"), py.None())?;
    d.set_item(intern!(py, "fixed"), fixed_names)?;
    Ok(obj)
}

/// Geometric ellipsoid fit, returned as `cls` (`triaxcal.fit.EllipsoidFit`); `None` when an
/// argument is not yet in its plain form (the facade then validates, converts and calls again).
/// `fixed` is the facade's 9-vector of held parameters, `fixed_names` their names.
#[pyfunction]
#[pyo3(signature = (points, cls, model, radius, max_iter, tol, method, debias, fixed, fixed_names))]
#[allow(clippy::too_many_arguments)]
pub(super) fn fit_ellipsoid<'py>(
    py: Python<'py>,
    points: &Bound<'py, PyAny>,
    cls: &Bound<'py, PyType>,
    model: &Bound<'py, PyAny>,
    radius: &Bound<'py, PyAny>,
    max_iter: &Bound<'py, PyAny>,
    tol: &Bound<'py, PyAny>,
    method: &Bound<'py, PyAny>,
    debias: &Bound<'py, PyAny>,
    fixed: Option<[Option<f64>; 9]>,
    fixed_names: &Bound<'py, PyTuple>,
) -> PyResult<Option<Bound<'py, PyAny>>> {
    let facade = facade(py, cls)?;
    let (Some(arr), Some(opts)) = (
        ready_points(points),
        exact_options(
            model,
            radius,
            max_iter,
            tol,
            method,
            debias,
            fixed,
            facade.max_iter,
        ),
    ) else {
        return Ok(None);
    };
    let f = if arr.shape()[0] <= HOLD_GIL_UP_TO {
        py_result(ellipsoid::fit_ellipsoid(points_under_gil(py, arr), &opts))?
    } else {
        let ro = arr.try_readonly().map_err(|e| {
            CalibrationError::new_err(format!(
                "the points array is being written to elsewhere ({e}); pass a copy"
            ))
        })?;
        let pts = ro.as_slice()?.as_chunks::<3>().0;
        py_result(py.detach(|| ellipsoid::fit_ellipsoid(pts, &opts)))?
    };
    fit_object(py, cls, facade, f, fixed_names).map(Some)
}
