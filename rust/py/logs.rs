//! The log readers (`rust/logs/`): read with the GIL released, returned as dicts of numpy
//! arrays and plain values for `triaxcal.io.logs`.

use super::errors::py_result;
use crate::logs::{dataflash, ulog, Column, Value};
use numpy::PyArray1;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyList, PyTuple};
use std::path::PathBuf;

fn value<'py>(py: Python<'py>, v: Value) -> PyResult<Bound<'py, PyAny>> {
    Ok(match v {
        Value::Int(x) => x.into_pyobject(py)?.into_any(),
        Value::UInt(x) => x.into_pyobject(py)?.into_any(),
        Value::Float(x) => x.into_pyobject(py)?.into_any(),
        Value::Bool(x) => x.into_pyobject(py)?.to_owned().into_any(),
        Value::Str(x) => x.into_pyobject(py)?.into_any(),
        Value::Bytes(x) => PyBytes::new(py, &x).into_any(),
    })
}

fn column<'py>(py: Python<'py>, c: Column) -> PyResult<Bound<'py, PyAny>> {
    Ok(match c {
        Column::I8(v) => PyArray1::from_vec(py, v).into_any(),
        Column::U8(v) => PyArray1::from_vec(py, v).into_any(),
        Column::I16(v) => PyArray1::from_vec(py, v).into_any(),
        Column::U16(v) => PyArray1::from_vec(py, v).into_any(),
        Column::I32(v) => PyArray1::from_vec(py, v).into_any(),
        Column::U32(v) => PyArray1::from_vec(py, v).into_any(),
        Column::I64(v) => PyArray1::from_vec(py, v).into_any(),
        Column::U64(v) => PyArray1::from_vec(py, v).into_any(),
        Column::F32(v) => PyArray1::from_vec(py, v).into_any(),
        Column::F64(v) => PyArray1::from_vec(py, v).into_any(),
        Column::Str(v) => PyList::new(py, v)?.into_any(),
    })
}

fn columns<'py>(py: Python<'py>, cols: Vec<(String, Column)>) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    for (name, c) in cols {
        d.set_item(name, column(py, c)?)?;
    }
    Ok(d)
}

fn values<'py>(py: Python<'py>, items: Vec<(String, Value)>) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    for (k, v) in items {
        d.set_item(k, value(py, v)?)?;
    }
    Ok(d)
}

/// A PX4 ULog: dict of start_timestamp, info, initial_parameters (dicts), changed_parameters
/// (list of (time, name, value)), datasets (list of (name, multi_id, {field: array})),
/// corrupt, appended. `topics`: the topics to decode (all when None).
#[pyfunction]
#[pyo3(signature = (path, topics=None))]
pub(super) fn read_ulog<'py>(
    py: Python<'py>,
    path: PathBuf,
    topics: Option<Vec<String>>,
) -> PyResult<Bound<'py, PyDict>> {
    let log = py_result(py.detach(|| {
        let names: Option<Vec<&str>> = topics
            .as_ref()
            .map(|t| t.iter().map(String::as_str).collect());
        ulog::read(&path, names.as_deref())
    }))?;
    let out = PyDict::new(py);
    out.set_item("start_timestamp", log.start_timestamp)?;
    out.set_item("info", values(py, log.info)?)?;
    out.set_item("initial_parameters", values(py, log.initial_parameters)?)?;
    let changed = PyList::empty(py);
    for (t, k, v) in log.changed_parameters {
        changed.append(PyTuple::new(
            py,
            [
                t.into_pyobject(py)?.into_any(),
                k.into_pyobject(py)?.into_any(),
                value(py, v)?,
            ],
        )?)?;
    }
    out.set_item("changed_parameters", changed)?;
    let sets = PyList::empty(py);
    for d in log.datasets {
        sets.append((d.name, d.multi_id, columns(py, d.fields)?))?;
    }
    out.set_item("datasets", sets)?;
    out.set_item("corrupt", log.corrupt)?;
    out.set_item("appended", log.appended)?;
    Ok(out)
}

/// An ArduPilot DataFlash log: dict of messages ({name: {"columns": {field: array or list of
/// str}, "seq": array}}), bad_headers, and fallback (None, or why pymavlink must read it).
#[pyfunction]
pub(super) fn read_dataflash<'py>(
    py: Python<'py>,
    path: PathBuf,
    types: Vec<String>,
) -> PyResult<Bound<'py, PyDict>> {
    let outcome = py_result(py.detach(|| {
        let names: Vec<&str> = types.iter().map(String::as_str).collect();
        dataflash::read(&path, &names)
    }))?;
    let out = PyDict::new(py);
    let messages = PyDict::new(py);
    match outcome {
        dataflash::Outcome::Fallback(why) => {
            out.set_item("fallback", why)?;
            out.set_item("bad_headers", 0)?;
        }
        dataflash::Outcome::Read {
            messages: ms,
            bad_headers,
        } => {
            out.set_item("fallback", py.None())?;
            out.set_item("bad_headers", bad_headers)?;
            for m in ms {
                let d = PyDict::new(py);
                d.set_item("columns", columns(py, m.columns)?)?;
                d.set_item("seq", PyArray1::from_vec(py, m.seq))?;
                messages.set_item(m.name, d)?;
            }
        }
    }
    out.set_item("messages", messages)?;
    Ok(out)
}
