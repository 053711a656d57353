//! Bindings of affcorr-solvers, one file per problem. Each solver returns a list of (3, 3) arrays.

use pyo3::prelude::*;

mod essential;
mod fundamental;
mod homography;
mod inputs;

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    homography::register(m)?;
    fundamental::register(m)?;
    essential::register(m)?;
    Ok(())
}
