//! Shared by the pipeline's integration tests.
#![allow(dead_code, unused_imports)]

pub use affcorr_devtools::{graffiti_homography, models_dir, ort_library, repo_root as root};

/// The bundled shape network.
pub fn bundled_model() -> std::path::PathBuf {
    models_dir().join("shape.onnx")
}

/// Initialises ONNX Runtime for this test binary.
pub fn init() {
    affcorr_pipeline::init_ort(Some(&ort_library())).expect("ONNX Runtime loads");
}
