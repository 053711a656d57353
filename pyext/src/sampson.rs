//! Bindings of `affcorr::geom::sampson`: point and affine Sampson distances and their gradients.
//! Docstrings live in `python/affcorr/_native.pyi`.
//!
//! `F` is one `(3, 3)` matrix for every row or a `(N, 3, 3)` stack (one per row); `corrs` is
//! `(N, 4)` or `(N, 8)` for the point distance and `(N, 8)` for the affine one.

use crate::arrays::{Dim, F64Array, to_numpy, value_error};
use affcorr::geom::Mat3;
use affcorr::geom::sampson::{self, AffineSampsonGrad, Fundamentals, PointSampsonGrad};
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
        py.detach(|| sampson::sampson_point_batch(f, rows, &mut out))
    } else {
        let rows = c.rows::<8>();
        py.detach(|| sampson::sampson_point_batch(f, rows, &mut out))
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
    let mut out = vec![[0.0; 2]; rows.len()];
    py.detach(|| sampson::sampson_affine_batch(f, rows, &mut out))
        .map_err(value_error)?;
    to_numpy(py, &[out.len(), 2], out.into_iter().flatten().collect())
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
    let mut out = vec![PointSampsonGrad::default(); n];
    let result = if width == 4 {
        let rows = c.rows::<4>();
        py.detach(|| sampson::sampson_point_grad_batch(f, rows, &mut out))
    } else {
        let rows = c.rows::<8>();
        py.detach(|| sampson::sampson_point_grad_batch(f, rows, &mut out))
    };
    result.map_err(value_error)?;
    let mut d_corrs = vec![0.0; n * width];
    for (row, g) in d_corrs.chunks_exact_mut(width).zip(&out) {
        // The A columns of an (N, 8) input stay zero: SD_P does not depend on them.
        row[..4].copy_from_slice(&g.d_row());
    }
    Ok((
        to_numpy(py, &[n], out.iter().map(|g| g.value).collect())?,
        to_numpy(py, &[n, width], d_corrs)?,
        to_numpy(py, &[n, 3, 3], out.iter().flat_map(|g| g.d_f).collect())?,
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
    let mut out = vec![[AffineSampsonGrad::default(); 2]; n];
    py.detach(|| sampson::sampson_affine_grad_batch(f, rows, &mut out))
        .map_err(value_error)?;
    let grads = || out.iter().flatten();
    Ok((
        to_numpy(py, &[n, 2], grads().map(|g| g.value).collect())?,
        to_numpy(py, &[n, 2, 8], grads().flat_map(|g| g.d_row()).collect())?,
        to_numpy(py, &[n, 2, 3, 3], grads().flat_map(|g| g.d_f).collect())?,
    ))
}
