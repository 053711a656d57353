//! Bindings of the fundamental-matrix solvers (`affcorr_solvers::fundamental`). Each solver
//! returns a list of (3, 3) arrays with ‖F‖_F = 1 (p2ᵀ F p1 = 0); a degenerate sample (all on one
//! plane, coincident points, det A ≤ 0, rank-deficient system) gives an empty list. Bad shapes
//! and NaN/infinity raise `ValueError` naming the argument.

use super::inputs::{models, read_acs, read_hybrid, read_points, same_length};
use affcorr::geom::Mat3;
use affcorr::solvers::fundamental as f;
use numpy::PyArrayDyn;
use pyo3::prelude::*;

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(fundamental_7pt, m)?)?;
    m.add_function(wrap_pyfunction!(fundamental_8pt, m)?)?;
    m.add_function(wrap_pyfunction!(fundamental_3ac, m)?)?;
    m.add_function(wrap_pyfunction!(fundamental_1ac4pt, m)?)?;
    m.add_function(wrap_pyfunction!(fundamental_ac_lsq, m)?)?;
    Ok(())
}

type Models<'py> = Vec<Bound<'py, PyArrayDyn<f64>>>;

#[pyfunction]
fn fundamental_7pt<'py>(
    py: Python<'py>,
    x1: &Bound<'py, PyAny>,
    x2: &Bound<'py, PyAny>,
) -> PyResult<Models<'py>> {
    let x1 = read_points(x1, "x1", Some(7), 7)?;
    let x2 = read_points(x2, "x2", Some(7), 7)?;
    let mut out = [Mat3::zeros(); f::FUNDAMENTAL_7PT_MAX_SOLUTIONS];
    let n = f::fundamental_7pt(&x1, &x2, &mut out);
    models(py, &out, n)
}

#[pyfunction]
fn fundamental_8pt<'py>(
    py: Python<'py>,
    x1: &Bound<'py, PyAny>,
    x2: &Bound<'py, PyAny>,
) -> PyResult<Models<'py>> {
    let x1 = read_points(x1, "x1", None, 8)?;
    let x2 = read_points(x2, "x2", None, 8)?;
    same_length(&x1, &x2)?;
    let mut out = [Mat3::zeros(); f::FUNDAMENTAL_8PT_MAX_SOLUTIONS];
    let n = py.detach(|| f::fundamental_8pt(&x1, &x2, &mut out));
    models(py, &out, n)
}

#[pyfunction]
fn fundamental_3ac<'py>(py: Python<'py>, corrs: &Bound<'py, PyAny>) -> PyResult<Models<'py>> {
    let acs = read_acs(corrs, "corrs", Some(3), 3)?;
    let mut out = [Mat3::zeros(); f::FUNDAMENTAL_3AC_MAX_SOLUTIONS];
    let n = f::fundamental_3ac(&acs, &mut out);
    models(py, &out, n)
}

#[pyfunction]
fn fundamental_ac_lsq<'py>(py: Python<'py>, corrs: &Bound<'py, PyAny>) -> PyResult<Models<'py>> {
    let acs = read_acs(corrs, "corrs", None, 3)?;
    let mut out = [Mat3::zeros(); f::FUNDAMENTAL_AC_LSQ_MAX_SOLUTIONS];
    let n = py.detach(|| f::fundamental_ac_lsq(&acs, &mut out));
    models(py, &out, n)
}

/// One AC `corr` (1, 8) and 4 points `x1`, `x2` (4, 2): the hybrid minimal sample.
#[pyfunction]
fn fundamental_1ac4pt<'py>(
    py: Python<'py>,
    corr: &Bound<'py, PyAny>,
    x1: &Bound<'py, PyAny>,
    x2: &Bound<'py, PyAny>,
) -> PyResult<Models<'py>> {
    let (ac, x1, x2) = read_hybrid(corr, x1, x2, 4)?;
    let mut out = [Mat3::zeros(); f::FUNDAMENTAL_1AC4PT_MAX_SOLUTIONS];
    let n = f::fundamental_1ac4pt(&ac, &x1, &x2, &mut out);
    models(py, &out, n)
}
