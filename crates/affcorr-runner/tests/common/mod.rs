//! Shared by the runner's integration tests: where ONNX Runtime and the fixtures are.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

/// The repository root.
pub fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// A fixture model of `tests/data/shape/` (written by `make_fixtures.py` there).
pub fn fixture(name: &str) -> PathBuf {
    root().join("tests/data/shape").join(name)
}

/// The bundled shape network.
pub fn bundled_model() -> PathBuf {
    root().join("python/affcorr/models/shape.onnx")
}

/// The ONNX Runtime library: `$ORT_DYLIB_PATH` (scripts/test.sh sets it), else the one in the
/// repository's `.venv` (from the `onnxruntime` wheel). Panics, saying how to fix it, when
/// there is neither: these tests must not pass silently without ONNX Runtime.
pub fn ort_library() -> PathBuf {
    affcorr_runner::ort_env::locate_library(&root()).unwrap_or_else(|| {
        panic!(
            "ONNX Runtime not found: set ORT_DYLIB_PATH to libonnxruntime.so (scripts/test.sh \
             does), or run scripts/setup.sh so that {} holds the onnxruntime wheel",
            root().join(".venv/lib").display()
        )
    })
}

/// Initialises ONNX Runtime for this test binary.
pub fn init() {
    affcorr_runner::init_ort(Some(&ort_library())).expect("ONNX Runtime loads");
}

/// Graffiti's ground-truth homography H1to3p (p3 ~ H p1), row-major, from its OpenCV XML.
pub fn graffiti_homography() -> [f64; 9] {
    let xml = std::fs::read_to_string(root().join("data/graffiti/H1to3p.xml"))
        .expect("data/graffiti/H1to3p.xml is readable");
    let body = xml
        .split("<data>")
        .nth(1)
        .and_then(|s| s.split("</data>").next())
        .expect("H1to3p.xml has a <data> element");
    let v: Vec<f64> = body
        .split_whitespace()
        .map(|s| s.parse().expect("H1to3p.xml holds numbers"))
        .collect();
    v.try_into().expect("H1to3p.xml holds 9 numbers")
}
