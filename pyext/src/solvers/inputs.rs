//! What the solver bindings share: reading samples of points and ACs (finite, of the right
//! shape and size, errors naming the argument) and returning models as (3, 3) arrays.

use crate::arrays::{Dim, F64Array, mat3_to_numpy};
use affcorr::geom::{AffineCorrespondence, Mat3, Vec2};
use numpy::PyArrayDyn;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

/// The models a solver found, as (3, 3) arrays.
pub(super) type Models<'py> = Vec<Bound<'py, PyArrayDyn<f64>>>;

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

/// A hybrid sample: one AC `corr` (1, 8) and `points` point correspondences `x1`, `x2`
/// (`points`, 2), each finite.
pub(super) fn read_hybrid(
    corr: &Bound<'_, PyAny>,
    x1: &Bound<'_, PyAny>,
    x2: &Bound<'_, PyAny>,
    points: usize,
) -> PyResult<(AffineCorrespondence, Vec<Vec2>, Vec<Vec2>)> {
    let ac = read_acs(corr, "corr", Some(1), 1)?[0];
    let x1 = read_points(x1, "x1", Some(points), points)?;
    let x2 = read_points(x2, "x2", Some(points), points)?;
    Ok((ac, x1, x2))
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
    out[..n].iter().map(|m| mat3_to_numpy(py, m)).collect()
}
