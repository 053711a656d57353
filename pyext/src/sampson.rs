//! Bindings of `affcorr::geom::sampson`: point and affine Sampson distances and their gradients.
//! Docstrings live in `python/affcorr/_native.pyi`.
//!
//! `F` is one `(3, 3)` matrix for every row or a `(N, 3, 3)` stack (one per row); `corrs` is
//! `(N, 4)` or `(N, 8)` for the point distance and `(N, 8)` for the affine one.

use crate::arrays::{Dim, F64Array, to_numpy, value_error};
use affcorr::geom::Mat3;
use affcorr::geom::sampson::{self, Fundamentals};
use numpy::PyArrayDyn;
use pyo3::prelude::*;

const N: Dim = Dim::Any("N");

type Array<'py> = Bound<'py, PyArrayDyn<f64>>;

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(sampson_point, m)?)?;
    m.add_function(wrap_pyfunction!(sampson_affine, m)?)?;
    m.add_function(wrap_pyfunction!(sampson_point_grad, m)?)?;
    m.add_function(wrap_pyfunction!(sampson_affine_grad, m)?)?;
    Ok(())
}

/// The `F` argument: one matrix (checked here, so the message reads "F", not "F[0]") or one
/// per row (checked per row by the core crate).
enum FArg<'py> {
    Shared(Mat3),
    PerRow(F64Array<'py>),
}

impl<'py> FArg<'py> {
    fn extract(obj: &Bound<'py, PyAny>) -> PyResult<Self> {
        let m3 = [Dim::Is(3), Dim::Is(3)];
        let a = F64Array::extract(obj, "F")?.expect_one_of(&[&m3, &[N, m3[0], m3[1]]])?;
        if a.shape().len() == 3 {
            return Ok(Self::PerRow(a));
        }
        let f = a.mat3();
        if f.iter().any(|v| !v.is_finite()) {
            return Err(value_error("F contains NaN or infinity"));
        }
        Ok(Self::Shared(f))
    }

    fn get(&self) -> Fundamentals<'_> {
        match self {
            Self::Shared(f) => Fundamentals::Shared(f),
            Self::PerRow(a) => Fundamentals::PerRow(a.rows::<9>()),
        }
    }
}

fn point_corrs<'py>(obj: &Bound<'py, PyAny>) -> PyResult<F64Array<'py>> {
    F64Array::extract(obj, "corrs")?.expect_one_of(&[&[N, Dim::Is(4)], &[N, Dim::Is(8)]])
}

fn affine_corrs<'py>(obj: &Bound<'py, PyAny>) -> PyResult<F64Array<'py>> {
    F64Array::extract(obj, "corrs")?.expect(&[N, Dim::Is(8)])
}

#[pyfunction]
#[pyo3(signature = (F, corrs))]
#[allow(non_snake_case)]
fn sampson_point<'py>(
    py: Python<'py>,
    F: &Bound<'py, PyAny>,
    corrs: &Bound<'py, PyAny>,
) -> PyResult<Array<'py>> {
    let f = FArg::extract(F)?;
    let c = point_corrs(corrs)?;
    let f = f.get();
    let n = c.shape()[0];
    let mut out = vec![0.0; n];
    let result = if c.shape()[1] == 4 {
        let rows = c.rows::<4>();
        crate::interrupt::parallel(py, n, || sampson::sampson_point_batch(f, rows, &mut out))
    } else {
        let rows = c.rows::<8>();
        crate::interrupt::parallel(py, n, || sampson::sampson_point_batch(f, rows, &mut out))
    };
    result.map_err(value_error)?;
    to_numpy(py, &[n], out)
}

#[pyfunction]
#[pyo3(signature = (F, corrs))]
#[allow(non_snake_case)]
fn sampson_affine<'py>(
    py: Python<'py>,
    F: &Bound<'py, PyAny>,
    corrs: &Bound<'py, PyAny>,
) -> PyResult<Array<'py>> {
    let f = FArg::extract(F)?;
    let c = affine_corrs(corrs)?;
    let (f, rows) = (f.get(), c.rows::<8>());
    let mut out = vec![0.0; 2 * rows.len()];
    let out_rows = out.as_chunks_mut::<2>().0;
    crate::interrupt::parallel(py, rows.len(), || {
        sampson::sampson_affine_batch(f, rows, out_rows)
    })
    .map_err(value_error)?;
    to_numpy(py, &[rows.len(), 2], out)
}

#[pyfunction]
#[pyo3(signature = (F, corrs))]
#[allow(non_snake_case)]
fn sampson_point_grad<'py>(
    py: Python<'py>,
    F: &Bound<'py, PyAny>,
    corrs: &Bound<'py, PyAny>,
) -> PyResult<(Array<'py>, Array<'py>, Array<'py>)> {
    let f = FArg::extract(F)?;
    let c = point_corrs(corrs)?;
    let f = f.get();
    let (n, width) = (c.shape()[0], c.shape()[1]);
    // Written in place into the final arrays (no intermediate rows: at these sizes fresh memory,
    // not arithmetic, is the cost).
    let (mut value, mut d_corrs, mut d_f) = (vec![0.0; n], vec![0.0; n * width], vec![0.0; n * 9]);
    let d_f_rows = d_f.as_chunks_mut::<9>().0;
    let result = if width == 4 {
        let (rows, d_rows) = (c.rows::<4>(), d_corrs.as_chunks_mut::<4>().0);
        crate::interrupt::parallel(py, n, || {
            sampson::sampson_point_grad_columns(f, rows, &mut value, d_rows, d_f_rows)
        })
    } else {
        // The A columns of the gradient stay zero: SD_P does not depend on them.
        let (rows, d_rows) = (c.rows::<8>(), d_corrs.as_chunks_mut::<8>().0);
        crate::interrupt::parallel(py, n, || {
            sampson::sampson_point_grad_columns(f, rows, &mut value, d_rows, d_f_rows)
        })
    };
    result.map_err(value_error)?;
    Ok((
        to_numpy(py, &[n], value)?,
        to_numpy(py, &[n, width], d_corrs)?,
        to_numpy(py, &[n, 3, 3], d_f)?,
    ))
}

#[pyfunction]
#[pyo3(signature = (F, corrs))]
#[allow(non_snake_case)]
fn sampson_affine_grad<'py>(
    py: Python<'py>,
    F: &Bound<'py, PyAny>,
    corrs: &Bound<'py, PyAny>,
) -> PyResult<(Array<'py>, Array<'py>, Array<'py>)> {
    let f = FArg::extract(F)?;
    let c = affine_corrs(corrs)?;
    let (f, rows) = (f.get(), c.rows::<8>());
    let n = rows.len();
    let (mut value, mut d_corrs, mut d_f) =
        (vec![0.0; 2 * n], vec![0.0; 16 * n], vec![0.0; 18 * n]);
    let value_rows = value.as_chunks_mut::<2>().0;
    let d_rows = d_corrs.as_chunks_mut::<8>().0.as_chunks_mut::<2>().0;
    let d_f_rows = d_f.as_chunks_mut::<9>().0.as_chunks_mut::<2>().0;
    crate::interrupt::parallel(py, n, || {
        sampson::sampson_affine_grad_columns(f, rows, value_rows, d_rows, d_f_rows)
    })
    .map_err(value_error)?;
    Ok((
        to_numpy(py, &[n, 2], value)?,
        to_numpy(py, &[n, 2, 8], d_corrs)?,
        to_numpy(py, &[n, 2, 3, 3], d_f)?,
    ))
}
