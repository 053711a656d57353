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

/// [`affcorr_devtools::exported`], with ONNX Runtime initialised.
pub fn exported(file: &str, what: &str, command: &str) -> bool {
    init();
    affcorr_devtools::exported(file, what, command)
}

/// A fresh directory for one test (per process and thread).
pub fn temp_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!(
        "affcorr-{tag}-test-{}-{:?}",
        std::process::id(),
        std::thread::current().id()
    ));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A graffiti image (`data/graffiti/<name>`).
pub fn graffiti(name: &str) -> affcorr_image::GrayImage {
    affcorr_image::GrayImage::open(root().join("data/graffiti").join(name)).unwrap()
}

/// How many matches (x1 in graf1, x2 in graf3) lie within `px` pixels of graffiti's
/// homography.
pub fn graffiti_correct(x1: &[[f32; 2]], x2: &[[f32; 2]], px: f64) -> usize {
    let h = affcorr_geom::Mat3::from_row_slice(&graffiti_homography());
    x1.iter()
        .zip(x2)
        .filter(|(p, q)| {
            let t = h * affcorr_geom::Vec3::new(p[0] as f64, p[1] as f64, 1.0);
            let (dx, dy) = (t[0] / t[2] - q[0] as f64, t[1] / t[2] - q[1] as f64);
            (dx * dx + dy * dy).sqrt() <= px
        })
        .count()
}
