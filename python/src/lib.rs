//! `camsim._camsim`: the Python extension of camsim (PyO3 + numpy, abi3).
//!
//! It binds the library crates (`camsim-pipeline` and the stage crates); it never runs the
//! command line. Errors are raised as `camsim.CamsimError` carrying the CLI's one-line message.
//! Arrays are NumPy arrays, row-major, axes (rows, cols[, bands]); wavelengths travel with
//! the data. Long work runs with the GIL released. The Python package `camsim` (python/camsim)
//! wraps this module; its type stubs document units.
#![deny(missing_docs)]

mod capture;
mod lens;
mod metrics;
mod scene;

use camsim_pipeline::error::CliError;
use numpy::{AllowTypeChange, PyArray1, PyArrayLikeDyn, PyArrayMethods};
use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use serde_json::Value;

create_exception!(
    camsim,
    CamsimError,
    PyException,
    "An error of camsim: the same one-line message the command line prints."
);

/// A Python exception from a library error (the CLI's one-line message).
pub(crate) fn err(e: CliError) -> PyErr {
    CamsimError::new_err(e.one_line())
}

/// A Python exception from any message.
pub(crate) fn err_msg(m: impl std::fmt::Display) -> PyErr {
    CamsimError::new_err(m.to_string())
}

/// A JSON value as Python objects (dict, list, float/int, str, bool, None).
pub(crate) fn json_to_py<'py>(py: Python<'py>, v: &Value) -> PyResult<Bound<'py, PyAny>> {
    Ok(match v {
        Value::Null => py.None().into_bound(py),
        Value::Bool(b) => b.into_pyobject(py)?.to_owned().into_any(),
        Value::Number(n) => {
            if let Some(i) = n.as_i64() {
                i.into_pyobject(py)?.into_any()
            } else if let Some(u) = n.as_u64() {
                u.into_pyobject(py)?.into_any()
            } else {
                n.as_f64().unwrap_or(f64::NAN).into_pyobject(py)?.into_any()
            }
        }
        Value::String(s) => s.into_pyobject(py)?.into_any(),
        Value::Array(a) => {
            let items: Vec<Bound<'py, PyAny>> = a
                .iter()
                .map(|x| json_to_py(py, x))
                .collect::<PyResult<_>>()?;
            PyList::new(py, items)?.into_any()
        }
        Value::Object(m) => {
            let d = PyDict::new(py);
            for (k, x) in m {
                d.set_item(k, json_to_py(py, x)?)?;
            }
            d.into_any()
        }
    })
}

/// Parse a JSON text handed over by the Python layer (which `json.dumps` dicts).
pub(crate) fn parse_json(what: &str, text: &str) -> PyResult<Value> {
    serde_json::from_str(text).map_err(|e| err_msg(format!("{what}: invalid JSON: {e}")))
}

/// JSON text of a Python object: a str is taken as JSON text, anything else (dict, list,
/// number) goes through `json.dumps`.
pub(crate) fn json_text(obj: &Bound<'_, PyAny>) -> PyResult<String> {
    if let Ok(s) = obj.extract::<String>() {
        return Ok(s);
    }
    obj.py()
        .import("json")?
        .call_method1("dumps", (obj,))?
        .extract::<String>()
}

/// An array-like as f64 values in row-major order, with its shape.
pub(crate) fn f64_values(a: &PyArrayLikeDyn<'_, f64, AllowTypeChange>) -> (Vec<f64>, Vec<usize>) {
    let v = a.as_array();
    (v.iter().copied().collect(), v.shape().to_vec())
}

/// A 1-D f64 array owning `v` (no copy).
pub(crate) fn vec1<'py, T: numpy::Element>(py: Python<'py>, v: Vec<T>) -> Bound<'py, PyArray1<T>> {
    PyArray1::from_vec(py, v)
}

/// A row-major array of `shape` owning `v` (no copy: a reshaped view of the vector).
pub(crate) fn arr<'py, T: numpy::Element>(
    py: Python<'py>,
    v: Vec<T>,
    shape: &[usize],
) -> PyResult<Bound<'py, PyAny>> {
    Ok(PyArray1::from_vec(py, v)
        .reshape(shape.to_vec())?
        .into_any())
}

/// Call an optional Python progress callback `cb(done, total)` from a thread without the GIL;
/// the first exception it raises is kept and re-raised when the work is done.
pub(crate) struct Progress {
    cb: Option<Py<PyAny>>,
    failed: std::sync::Mutex<Option<PyErr>>,
}

impl Progress {
    pub(crate) fn new(cb: Option<Py<PyAny>>) -> Self {
        Progress {
            cb,
            failed: std::sync::Mutex::new(None),
        }
    }
    pub(crate) fn tick(&self, done: u64, total: u64) {
        if let Some(cb) = &self.cb {
            Python::attach(|py| {
                if let Err(e) = cb.call1(py, (done, total)) {
                    let mut f = self.failed.lock().expect("progress lock");
                    if f.is_none() {
                        *f = Some(e);
                    }
                }
            });
        }
    }
    pub(crate) fn finish(self) -> PyResult<()> {
        match self.failed.into_inner().expect("progress lock") {
            Some(e) => Err(e),
            None => Ok(()),
        }
    }
}

/// Set the number of worker threads of the global pool (like the CLI's `--threads`); must be
/// called before any parallel work, once.
#[pyfunction]
fn set_threads(n: usize) -> PyResult<()> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(n.max(1))
        .build_global()
        .map_err(err_msg)
}

/// The package version.
#[pyfunction]
fn version() -> &'static str {
    env!("CARGO_PKG_VERSION")
}

/// A no-op that crosses the Python/Rust boundary (for overhead benchmarks).
#[pyfunction]
fn noop(x: f64) -> f64 {
    x
}

#[pymodule]
fn _camsim(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("CamsimError", m.py().get_type::<CamsimError>())?;
    m.add_function(wrap_pyfunction!(version, m)?)?;
    m.add_function(wrap_pyfunction!(noop, m)?)?;
    m.add_function(wrap_pyfunction!(set_threads, m)?)?;
    capture::register(m)?;
    scene::register(m)?;
    lens::register(m)?;
    metrics::register(m)?;
    Ok(())
}
