//! Bindings of the homography solvers (`affcorr_solvers::homography`). Each solver returns a list of (3, 3) arrays with ‖H‖_F = 1; a
//! degenerate sample (collinear or coincident points, det A ≤ 0, rank-deficient system) gives an
//! empty list. Bad shapes and NaN/infinity raise `ValueError` naming the argument.

use super::inputs::{Models, models, read_acs, read_hybrid, read_points, same_length};
use affcorr::geom::Mat3;
use affcorr::solvers::homography as h;
use pyo3::prelude::*;

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(homography_4pt, m)?)?;
    m.add_function(wrap_pyfunction!(homography_2ac, m)?)?;
    m.add_function(wrap_pyfunction!(homography_1ac2pt, m)?)?;
    m.add_function(wrap_pyfunction!(homography_1ac_given_f, m)?)?;
    m.add_function(wrap_pyfunction!(homography_lsq, m)?)?;
    m.add_function(wrap_pyfunction!(homography_ac_lsq, m)?)?;
    Ok(())
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

/// One AC `corr` (1, 8) and 2 points `x1`, `x2` (2, 2): the hybrid minimal sample.
#[pyfunction]
fn homography_1ac2pt<'py>(
    py: Python<'py>,
    corr: &Bound<'py, PyAny>,
    x1: &Bound<'py, PyAny>,
    x2: &Bound<'py, PyAny>,
) -> PyResult<Models<'py>> {
    let (ac, x1, x2) = read_hybrid(corr, x1, x2, 2)?;
    let mut out = [Mat3::zeros(); h::HOMOGRAPHY_1AC2PT_MAX_SOLUTIONS];
    let n = h::homography_1ac2pt(&ac, &x1, &x2, &mut out);
    models(py, &out, n)
}
