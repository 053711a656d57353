//! numpy conversion shared by every binding.
//!
//! Inputs of any dtype and memory order are accepted: [`F64Array::extract`] makes a C-contiguous
//! float64 copy when (and only when) the input is not one already, then the caller checks the
//! shape with [`F64Array::expect`]. Errors name the argument.

use numpy::ndarray::{ArrayD, IxDyn};
use numpy::{IntoPyArray, PyArrayDyn, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// A dimension in an expected shape.
#[derive(Clone, Copy, Debug)]
pub enum Dim {
    /// Any length, shown as `name` in messages.
    Any(&'static str),
    /// Exactly this length.
    Is(usize),
}

/// A read-only C-contiguous float64 view of a Python argument.
pub struct F64Array<'py> {
    array: PyReadonlyArrayDyn<'py, f64>,
    name: &'static str,
}

impl<'py> F64Array<'py> {
    /// Converts `obj` (any array-like) to C-contiguous float64, copying only when needed.
    pub fn extract(obj: &Bound<'py, PyAny>, name: &'static str) -> PyResult<Self> {
        if let Ok(a) = obj.cast::<PyArrayDyn<f64>>()
            && a.is_c_contiguous()
        {
            return Ok(Self {
                array: a.readonly(),
                name,
            });
        }
        let py = obj.py();
        let kwargs = PyDict::new(py);
        kwargs.set_item("dtype", "float64")?;
        let converted = py
            .import("numpy")?
            .call_method("ascontiguousarray", (obj,), Some(&kwargs))
            .map_err(|e| {
                // A KeyboardInterrupt in the argument's __array__ stays one.
                crate::errors::rewrap(e, |e| {
                    PyValueError::new_err(format!("{name} must be a numeric array: {e}"))
                })
            })?;
        let array = converted
            .cast_into::<PyArrayDyn<f64>>()
            .map_err(|_| PyValueError::new_err(format!("{name} must be a numeric array")))?;
        Ok(Self {
            array: array.readonly(),
            name,
        })
    }

    /// The shape.
    pub fn shape(&self) -> &[usize] {
        self.array.shape()
    }

    /// Checks the shape against `dims`; the message shows the expected and actual shapes.
    pub fn expect(self, dims: &[Dim]) -> PyResult<Self> {
        let shape = self.shape();
        let ok = shape.len() == dims.len()
            && shape.iter().zip(dims).all(|(&s, d)| match d {
                Dim::Any(_) => true,
                Dim::Is(n) => s == *n,
            });
        if ok {
            Ok(self)
        } else {
            Err(shape_error(self.name, &[dims], shape))
        }
    }

    /// Like [`Self::expect`], accepting any one of several shapes.
    pub fn expect_one_of(self, options: &[&[Dim]]) -> PyResult<Self> {
        for dims in options {
            let shape = self.shape();
            let ok = shape.len() == dims.len()
                && shape.iter().zip(dims.iter()).all(|(&s, d)| match d {
                    Dim::Any(_) => true,
                    Dim::Is(n) => s == *n,
                });
            if ok {
                return Ok(self);
            }
        }
        Err(shape_error(self.name, options, self.shape()))
    }

    /// The data, row-major.
    pub fn as_slice(&self) -> &[f64] {
        self.array.as_slice().expect("C-contiguous by construction")
    }

    /// Rows of width `W` (the last dimension must be `W`).
    pub fn rows<const W: usize>(&self) -> &[[f64; W]] {
        let (rows, rest) = self.as_slice().as_chunks::<W>();
        debug_assert!(rest.is_empty());
        rows
    }

    /// A 3×3 matrix (shape already checked).
    pub fn mat3(&self) -> affcorr::geom::Mat3 {
        affcorr::geom::Mat3::from_row_slice(self.as_slice())
    }
}

fn fmt_dims(dims: &[Dim]) -> String {
    let parts: Vec<String> = dims
        .iter()
        .map(|d| match d {
            Dim::Any(n) => n.to_string(),
            Dim::Is(n) => n.to_string(),
        })
        .collect();
    format!(
        "({}{})",
        parts.join(", "),
        if dims.len() == 1 { "," } else { "" }
    )
}

fn shape_error(name: &str, options: &[&[Dim]], got: &[usize]) -> PyErr {
    let expected: Vec<String> = options.iter().map(|d| fmt_dims(d)).collect();
    let got: Vec<String> = got.iter().map(|n| n.to_string()).collect();
    PyValueError::new_err(format!(
        "{name} must have shape {}, got ({})",
        expected.join(" or "),
        got.join(", ")
    ))
}

/// A new numpy array of `shape` from row-major `data`.
pub fn to_numpy<'py>(
    py: Python<'py>,
    shape: &[usize],
    data: Vec<f64>,
) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
    let array = ArrayD::from_shape_vec(IxDyn(shape), data).map_err(|e| {
        pyo3::exceptions::PyRuntimeError::new_err(format!("internal shape error: {e}"))
    })?;
    Ok(array.into_pyarray(py))
}

/// A 3×3 matrix as a new (3, 3) array.
pub fn mat3_to_numpy<'py>(
    py: Python<'py>,
    m: &affcorr::geom::Mat3,
) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
    to_numpy(py, &[3, 3], affcorr::geom::types::mat3_to_row(m).to_vec())
}

/// Flattens rows of width `W` into one vector (no copy of the allocation's elements twice).
pub fn flatten<const W: usize>(rows: Vec<[f64; W]>) -> Vec<f64> {
    rows.into_iter().flatten().collect()
}

/// Rust input errors become `ValueError` with the core crate's message.
pub fn value_error<E: std::fmt::Display>(e: E) -> PyErr {
    PyValueError::new_err(e.to_string())
}

/// An integer option: a Python int or any object with `__index__` (numpy integers included),
/// never a bool or a float, in `min..=max`. Every error names the option: `what` describes
/// the accepted values ("a positive int", "a non-negative integer"); a value past `max`
/// (however many bits) says `"{name} = {value} is over the limit of {max}"`.
pub fn int_option(
    v: &Bound<'_, PyAny>,
    name: &str,
    what: &str,
    min: u64,
    max: u64,
) -> PyResult<u64> {
    let py = v.py();
    let bad = || {
        let r = v
            .repr()
            .map(|r| r.to_string())
            .unwrap_or_else(|_| "?".into());
        PyValueError::new_err(format!("{name} must be {what}, got {r}"))
    };
    if v.is_instance_of::<pyo3::types::PyBool>() {
        return Err(bad());
    }
    let index = py
        .import("operator")?
        .call_method1("index", (v,))
        .map_err(|e| crate::errors::rewrap(e, |_| bad()))?;
    let value: i128 = match index.extract() {
        Ok(x) => x,
        // Beyond 128 bits: below min or over max, by its sign.
        Err(_) if index.lt(0)? => return Err(bad()),
        Err(_) => i128::MAX,
    };
    if value < i128::from(min) {
        return Err(bad());
    }
    if value > i128::from(max) {
        return Err(PyValueError::new_err(format!(
            "{name} = {} is over the limit of {max}",
            index.str()?
        )));
    }
    Ok(value as u64)
}

/// [`int_option`] for an optional option: `None` stays `None`.
pub fn opt_int_option(
    v: Option<&Bound<'_, PyAny>>,
    name: &str,
    what: &str,
    min: u64,
    max: u64,
) -> PyResult<Option<u64>> {
    match v {
        Some(v) if !v.is_none() => int_option(v, name, what, min, max).map(Some),
        _ => Ok(None),
    }
}

/// A `u64` option as `usize` (lossless on the 64-bit targets this builds for).
pub fn to_usize(v: u64) -> usize {
    usize::try_from(v).unwrap_or(usize::MAX)
}
