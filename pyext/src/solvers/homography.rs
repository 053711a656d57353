//! Bindings of the homography solvers (`affcorr_solvers::homography`), and the input helpers the
//! fundamental bindings share. Each solver returns a list of (3, 3) arrays with ‖H‖_F = 1; a
//! degenerate sample (collinear or coincident points, det A ≤ 0, rank-deficient system) gives an
//! empty list. Bad shapes and NaN/infinity raise `ValueError` naming the argument.

use crate::arrays::{Dim, F64Array, to_numpy};
use affcorr::geom::{AffineCorrespondence, Mat3, Vec2};
use affcorr::solvers::homography as h;
use numpy::PyArrayDyn;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(homography_4pt, m)?)?;
    m.add_function(wrap_pyfunction!(homography_2ac, m)?)?;
    m.add_function(wrap_pyfunction!(homography_1ac_given_f, m)?)?;
    m.add_function(wrap_pyfunction!(homography_lsq, m)?)?;
    m.add_function(wrap_pyfunction!(homography_ac_lsq, m)?)?;
    Ok(())
}

type Models<'py> = Vec<Bound<'py, PyArrayDyn<f64>>>;

/// Points `(n, 2)` (`n` fixed) or `(N, 2)` with N ≥ `min` (`n` = None), finite.
pub(super) fn read_points(
    obj: &Bound<'_, PyAny>,
    name: &'static str,
    n: Option<usize>,
    min: usize,
) -> PyResult<Vec<Vec2>> {
    let rows = match n {
        Some(n) => Dim::Is(n),
        None => Dim::Any("N"),
    };
    let a = F64Array::extract(obj, name)?.expect(&[rows, Dim::Is(2)])?;
    check_finite(a.as_slice(), name)?;
    let pts: Vec<Vec2> = a
        .rows::<2>()
        .iter()
        .map(|r| Vec2::new(r[0], r[1]))
        .collect();
    if pts.len() < min {
        return Err(PyValueError::new_err(format!(
            "{name} needs at least {min} points, got {}",
            pts.len()
        )));
    }
    Ok(pts)
}

/// ACs `(n, 8)` (`n` fixed) or `(N, 8)` with N ≥ `min`, finite.
pub(super) fn read_acs(
    obj: &Bound<'_, PyAny>,
    name: &'static str,
    n: Option<usize>,
    min: usize,
) -> PyResult<Vec<AffineCorrespondence>> {
    let rows = match n {
        Some(n) => Dim::Is(n),
        None => Dim::Any("N"),
    };
    let a = F64Array::extract(obj, name)?.expect(&[rows, Dim::Is(8)])?;
    check_finite(a.as_slice(), name)?;
    let acs: Vec<AffineCorrespondence> = a
        .rows::<8>()
        .iter()
        .map(AffineCorrespondence::from_row)
        .collect();
    if acs.len() < min {
        return Err(PyValueError::new_err(format!(
            "{name} needs at least {min} correspondences, got {}",
            acs.len()
        )));
    }
    Ok(acs)
}

/// x1 and x2 must have the same length.
pub(super) fn same_length(x1: &[Vec2], x2: &[Vec2]) -> PyResult<()> {
    if x1.len() != x2.len() {
        return Err(PyValueError::new_err(format!(
            "x1 and x2 must have the same length, got {} and {}",
            x1.len(),
            x2.len()
        )));
    }
    Ok(())
}

fn check_finite(data: &[f64], name: &str) -> PyResult<()> {
    if data.iter().any(|v| !v.is_finite()) {
        return Err(PyValueError::new_err(format!(
            "{name} contains NaN or infinity"
        )));
    }
    Ok(())
}

/// The first `n` models as (3, 3) arrays.
pub(super) fn models<'py>(py: Python<'py>, out: &[Mat3], n: usize) -> PyResult<Models<'py>> {
    out[..n]
        .iter()
        .map(|m| to_numpy(py, &[3, 3], affcorr::geom::types::mat3_to_row(m).to_vec()))
        .collect()
}

#[pyfunction]
fn homography_4pt<'py>(
    py: Python<'py>,
    x1: &Bound<'py, PyAny>,
    x2: &Bound<'py, PyAny>,
) -> PyResult<Models<'py>> {
    let x1 = read_points(x1, "x1", Some(4), 4)?;
    let x2 = read_points(x2, "x2", Some(4), 4)?;
    let mut out = [Mat3::zeros(); h::HOMOGRAPHY_4PT_MAX_SOLUTIONS];
    let n = h::homography_4pt(&x1, &x2, &mut out);
    models(py, &out, n)
}

#[pyfunction]
fn homography_2ac<'py>(py: Python<'py>, corrs: &Bound<'py, PyAny>) -> PyResult<Models<'py>> {
    let acs = read_acs(corrs, "corrs", Some(2), 2)?;
    let mut out = [Mat3::zeros(); h::HOMOGRAPHY_2AC_MAX_SOLUTIONS];
    let n = h::homography_2ac(&acs, &mut out);
    models(py, &out, n)
}

#[pyfunction]
#[pyo3(signature = (corrs, F))]
#[allow(non_snake_case)]
fn homography_1ac_given_f<'py>(
    py: Python<'py>,
    corrs: &Bound<'py, PyAny>,
    F: &Bound<'py, PyAny>,
) -> PyResult<Models<'py>> {
    let acs = read_acs(corrs, "corrs", Some(1), 1)?;
    let f = crate::geom::matrix3(F, "F")?;
    let mut out = [Mat3::zeros(); h::HOMOGRAPHY_1AC_GIVEN_F_MAX_SOLUTIONS];
    let n = h::homography_1ac_given_f(&acs, &f, &mut out);
    models(py, &out, n)
}

#[pyfunction]
fn homography_lsq<'py>(
    py: Python<'py>,
    x1: &Bound<'py, PyAny>,
    x2: &Bound<'py, PyAny>,
) -> PyResult<Models<'py>> {
    let x1 = read_points(x1, "x1", None, 4)?;
    let x2 = read_points(x2, "x2", None, 4)?;
    same_length(&x1, &x2)?;
    let mut out = [Mat3::zeros(); h::HOMOGRAPHY_LSQ_MAX_SOLUTIONS];
    let n = py.detach(|| h::homography_lsq(&x1, &x2, &mut out));
    models(py, &out, n)
}

#[pyfunction]
fn homography_ac_lsq<'py>(py: Python<'py>, corrs: &Bound<'py, PyAny>) -> PyResult<Models<'py>> {
    let acs = read_acs(corrs, "corrs", None, 2)?;
    let mut out = [Mat3::zeros(); h::HOMOGRAPHY_AC_LSQ_MAX_SOLUTIONS];
    let n = py.detach(|| h::homography_ac_lsq(&acs, &mut out));
    models(py, &out, n)
}
