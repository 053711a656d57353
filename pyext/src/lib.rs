//! The `affcorr._native` extension module: thin bindings over the facade crate.
//!
//! - `arrays`: numpy in/out, dtype and contiguity conversion, shape checks that name the
//!   argument, and the mapping of Rust errors to Python exceptions.
//! - `geom`: synthesis, decomposition, homography ACs, normalisation, LAFs, epipolar utilities.
//! - `sampson`: Sampson distances and their gradients.
//! - `solvers`: minimal and non-minimal solvers (`solvers/inputs.rs`: what they share).
//! - `ransac`: the robust estimators and their keyword options.
//! - `image`: image decoding, patch extraction, the affine Lucas–Kanade refinement.
//! - `runner`: the shape network and ONNX Runtime's loading.
//! - `pipeline`: the end-to-end pipeline: images → matches → ACs → H, F or relative pose, with
//!   its defaults, matcher names and model files.
//! - `errors`: Rust errors to Python exceptions.
//! - `interrupt`: the per-process thread pool (fork safety) and interruptible long calls
//!   (Ctrl-C).
//!
//! Every function validates its inputs here or in Rust and raises `ValueError` naming the bad
//! argument; no Rust panic can cross this boundary because the core crates return `Result`s.
//! Long batched calls release the GIL; parallel work runs on a pool rebuilt in a forked child,
//! and the long calls (estimators, batches, the pipeline, the shape network) return promptly
//! with `KeyboardInterrupt` on Ctrl-C (`interrupt.rs`).

use pyo3::prelude::*;

mod arrays;
mod errors;
mod geom;
mod image;
mod interrupt;
mod pipeline;
mod ransac;
mod runner;
mod sampson;
mod solvers;

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    geom::register(m)?;
    image::register(m)?;
    pipeline::register(m)?;
    ransac::register(m)?;
    runner::register(m)?;
    sampson::register(m)?;
    solvers::register(m)?;
    Ok(())
}
