//! The streaming Allan deviation accumulator (`rust/allan.rs`) as a Python class.

use super::errors::{py_result, CalibrationError};
use crate::allan::Allan;
use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// Allan deviation accumulator (overlapping, or not); feed (rows, axes) float64 chunks with
/// `push`.
#[pyclass(name = "AllanStream", module = "triaxcal._core")]
pub struct AllanStream {
    inner: Allan,
}

#[pymethods]
impl AllanStream {
    /// `overlapping=False`: the non-overlapping deviation (terms start every `m` samples;
    /// allantools' `adev`), `exact_up_to` then unused.
    #[new]
    #[pyo3(signature = (rate_hz, axes, ms, *, exact_up_to, overlapping=true))]
    fn new(
        rate_hz: f64,
        axes: usize,
        ms: Vec<u64>,
        exact_up_to: Option<u64>,
        overlapping: bool,
    ) -> PyResult<Self> {
        let inner = py_result(if overlapping {
            Allan::new(rate_hz, axes, &ms, exact_up_to)
        } else {
            Allan::non_overlapping(rate_hz, axes, &ms)
        })?;
        Ok(AllanStream { inner })
    }

    /// Adds a C-contiguous (rows, axes) float64 chunk, with the GIL released.
    fn push(&mut self, py: Python<'_>, chunk: PyReadonlyArray2<'_, f64>) -> PyResult<()> {
        let shape = chunk.shape();
        if shape[1] != self.inner.result_axes() {
            return Err(CalibrationError::new_err(format!(
                "chunk must have shape (rows, {}), got (rows, {})",
                self.inner.result_axes(),
                shape[1]
            )));
        }
        let flat = chunk.as_slice().map_err(|_| {
            CalibrationError::new_err("chunk must be C-contiguous (np.ascontiguousarray)")
        })?;
        let inner = &mut self.inner;
        py_result(py.detach(|| inner.push(flat)))
    }

    /// Samples pushed so far.
    #[getter]
    fn n(&self) -> u64 {
        self.inner.len()
    }

    /// Bytes held by the accumulator (fixed when it is made).
    #[getter]
    fn memory_bytes(&self) -> usize {
        self.inner.memory_bytes()
    }

    /// Dict of arrays: m, stride, taus, terms (C,), adev (C, axes), n.
    fn result<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let r = self.inner.result();
        let nc = r.clusters.len();
        let nax = self.inner.result_axes();
        let out = PyDict::new(py);
        out.set_item(
            "m",
            PyArray1::from_vec(py, r.clusters.iter().map(|c| c.m).collect()),
        )?;
        out.set_item(
            "stride",
            PyArray1::from_vec(py, r.clusters.iter().map(|c| c.stride).collect()),
        )?;
        out.set_item("taus", PyArray1::from_vec(py, r.taus))?;
        out.set_item("terms", PyArray1::from_vec(py, r.terms))?;
        let flat: Vec<f64> = r.adev.into_iter().flatten().collect();
        out.set_item("adev", PyArray1::from_vec(py, flat).reshape([nc, nax])?)?;
        out.set_item("n", r.n)?;
        Ok(out)
    }
}
