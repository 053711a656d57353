//! Shared by the runner's integration tests: where ONNX Runtime and the fixtures are.
#![allow(dead_code, unused_imports)]

use std::path::PathBuf;

pub use affcorr_devtools::{graffiti_homography, ort_library, repo_root as root};

/// A fixture model of `tests/data/shape/` (written by `make_fixtures.py` there).
pub fn fixture(name: &str) -> PathBuf {
    root().join("tests/data/shape").join(name)
}

/// The bundled shape network.
pub fn bundled_model() -> PathBuf {
    affcorr_devtools::models_dir().join("shape.onnx")
}

/// Initialises ONNX Runtime for this test binary.
pub fn init() {
    affcorr_runner::init_ort(Some(&ort_library())).expect("ONNX Runtime loads");
}
