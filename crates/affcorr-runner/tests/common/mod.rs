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
    if let Some(p) = std::env::var_os("ORT_DYLIB_PATH").filter(|p| !p.is_empty()) {
        // cargo runs tests and benches in the package directory: a relative path given at the
        // repository root is resolved there.
        let p = PathBuf::from(p);
        return if p.is_relative() && !p.exists() {
            root().join(p)
        } else {
            p
        };
    }
    let lib = root().join(".venv/lib");
    let found = std::fs::read_dir(&lib).ok().and_then(|dirs| {
        dirs.flatten().find_map(|d| {
            let capi = d.path().join("site-packages/onnxruntime/capi");
            std::fs::read_dir(capi)
                .ok()?
                .flatten()
                .map(|f| f.path())
                .find(|p| {
                    p.file_name()
                        .and_then(|n| n.to_str())
                        .is_some_and(|n| n.starts_with("libonnxruntime.so"))
                })
        })
    });
    found.unwrap_or_else(|| {
        panic!(
            "ONNX Runtime not found: set ORT_DYLIB_PATH to libonnxruntime.so (scripts/test.sh \
             does), or run scripts/setup.sh so that {} holds the onnxruntime wheel",
            lib.display()
        )
    })
}

/// Initialises ONNX Runtime for this test binary.
pub fn init() {
    affcorr_runner::init_ort(Some(&ort_library())).expect("ONNX Runtime loads");
}
