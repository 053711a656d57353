//! Bindings of the essential solvers (`affcorr_solvers::essential`). Inputs are in normalised
//! coordinates (x̂ = K⁻¹p, Â = K2[:2,:2]⁻¹ A K1[:2,:2]: `affcorr.normalize_correspondences`).
//! Each solver returns a list of (3, 3) arrays with ‖E‖_F = 1 (sign arbitrary); a degenerate
//! sample (repeated points, det A ≤ 0, rank-deficient system) gives an empty list. Bad shapes and
//! NaN/infinity raise `ValueError` naming the argument.

use super::inputs::{models, read_acs, read_hybrid, read_points, same_length};
use affcorr::geom::Mat3;
use affcorr::solvers::essential as e;
use numpy::PyArrayDyn;
use pyo3::prelude::*;

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(essential_5pt, m)?)?;
    m.add_function(wrap_pyfunction!(essential_2ac, m)?)?;
    m.add_function(wrap_pyfunction!(essential_1ac2pt, m)?)?;
    m.add_function(wrap_pyfunction!(essential_8pt, m)?)?;
    m.add_function(wrap_pyfunction!(essential_lsq, m)?)?;
    Ok(())
}

type Models<'py> = Vec<Bound<'py, PyArrayDyn<f64>>>;

#[pyfunction]
fn essential_5pt<'py>(
    py: Python<'py>,
    x1: &Bound<'py, PyAny>,
    x2: &Bound<'py, PyAny>,
) -> PyResult<Models<'py>> {
    let x1 = read_points(x1, "x1", Some(5), 5)?;
    let x2 = read_points(x2, "x2", Some(5), 5)?;
    let mut out = [Mat3::zeros(); e::ESSENTIAL_5PT_MAX_SOLUTIONS];
    let n = e::essential_5pt(&x1, &x2, &mut out);
    models(py, &out, n)
}

#[pyfunction]
fn essential_2ac<'py>(py: Python<'py>, corrs: &Bound<'py, PyAny>) -> PyResult<Models<'py>> {
    let acs = read_acs(corrs, "corrs", Some(2), 2)?;
    let mut out = [Mat3::zeros(); e::ESSENTIAL_2AC_MAX_SOLUTIONS];
    let n = e::essential_2ac(&acs, &mut out);
    models(py, &out, n)
}

#[pyfunction]
fn essential_8pt<'py>(
    py: Python<'py>,
    x1: &Bound<'py, PyAny>,
    x2: &Bound<'py, PyAny>,
) -> PyResult<Models<'py>> {
    let x1 = read_points(x1, "x1", None, 8)?;
    let x2 = read_points(x2, "x2", None, 8)?;
    same_length(&x1, &x2)?;
    let mut out = [Mat3::zeros(); e::ESSENTIAL_8PT_MAX_SOLUTIONS];
    let n = py.detach(|| e::essential_8pt(&x1, &x2, &mut out));
    models(py, &out, n)
}

#[pyfunction]
#[pyo3(signature = (x1, x2, corrs = None))]
fn essential_lsq<'py>(
    py: Python<'py>,
    x1: &Bound<'py, PyAny>,
    x2: &Bound<'py, PyAny>,
    corrs: Option<&Bound<'py, PyAny>>,
) -> PyResult<Models<'py>> {
    let x1 = read_points(x1, "x1", None, 0)?;
    let x2 = read_points(x2, "x2", None, 0)?;
    same_length(&x1, &x2)?;
    let acs = match corrs {
        Some(c) => read_acs(c, "corrs", None, 0)?,
        None => Vec::new(),
    };
    if x1.len() + 3 * acs.len() < 8 {
        return Err(pyo3::exceptions::PyValueError::new_err(format!(
            "x1 and corrs need len(x1) + 3·len(corrs) >= 8 equations, got {}",
            x1.len() + 3 * acs.len()
        )));
    }
    let mut out = [Mat3::zeros(); e::ESSENTIAL_8PT_MAX_SOLUTIONS];
    let n = py.detach(|| e::essential_lsq(&x1, &x2, &acs, &mut out));
    models(py, &out, n)
}

/// One AC `corr` (1, 8) and 2 points `x1`, `x2` (2, 2): the hybrid minimal sample.
#[pyfunction]
fn essential_1ac2pt<'py>(
    py: Python<'py>,
    corr: &Bound<'py, PyAny>,
    x1: &Bound<'py, PyAny>,
    x2: &Bound<'py, PyAny>,
) -> PyResult<Models<'py>> {
    let (ac, x1, x2) = read_hybrid(corr, x1, x2, 2)?;
    let mut out = [Mat3::zeros(); e::ESSENTIAL_1AC2PT_MAX_SOLUTIONS];
    let n = e::essential_1ac2pt(&ac, &x1, &x2, &mut out);
    models(py, &out, n)
}
