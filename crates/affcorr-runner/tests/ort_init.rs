//! Loading ONNX Runtime: every failure is a typed error, never a panic; the first success wins.
//! One test in its own binary, because the environment is process-wide.

mod common;

use std::path::{Path, PathBuf};

use affcorr_runner::{RunnerError, init_ort, ort_library};

#[test]
fn bad_libraries_are_errors_and_a_good_one_then_loads() {
    assert!(ort_library().is_none());

    let missing = Path::new("/nonexistent/dir/libonnxruntime.so.1.31.1");
    let e = init_ort(Some(missing)).unwrap_err();
    assert!(
        matches!(e, RunnerError::OrtLibraryNotFound { ref path, origin: "the caller" } if path == missing),
        "{e:?}"
    );
    assert!(e.to_string().contains("ORT_DYLIB_PATH"), "{e}");

    // A file that is not a shared library.
    let dir = tempfile::tempdir().unwrap();
    let text = dir.path().join("libonnxruntime.so");
    std::fs::write(&text, b"not a library").unwrap();
    let e = init_ort(Some(&text)).unwrap_err();
    assert!(matches!(e, RunnerError::OrtLibraryLoad { .. }), "{e:?}");
    assert!(e.to_string().contains("libonnxruntime.so"), "{e}");

    // A real shared library without the ONNX Runtime API.
    let libm: Option<PathBuf> = [
        "/lib/x86_64-linux-gnu/libm.so.6",
        "/usr/lib/x86_64-linux-gnu/libm.so.6",
        "/lib/aarch64-linux-gnu/libm.so.6",
        "/usr/lib64/libm.so.6",
    ]
    .iter()
    .map(PathBuf::from)
    .find(|p| p.is_file());
    if let Some(libm) = libm {
        let e = init_ort(Some(&libm)).unwrap_err();
        assert!(matches!(e, RunnerError::OrtLibraryLoad { .. }), "{e:?}");
        assert!(e.to_string().contains("OrtGetApiBase"), "{e}");
    }
    assert!(ort_library().is_none(), "failed attempts are not cached");

    let good = common::ort_library();
    init_ort(Some(&good)).unwrap();
    assert_eq!(
        ort_library(),
        Some(std::fs::canonicalize(&good).unwrap().as_path())
    );
    // Later calls keep the loaded library.
    init_ort(Some(missing)).unwrap();
    init_ort(None).unwrap();
    assert_eq!(
        ort_library(),
        Some(std::fs::canonicalize(&good).unwrap().as_path())
    );
}
