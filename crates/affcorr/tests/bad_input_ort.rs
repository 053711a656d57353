//! Bad ONNX Runtime libraries: missing, not ONNX Runtime, too old, or with a broken C
//! API. Each is a typed [`RunnerError`], never a panic or an abort.
//!
//! Its own test binary, because ONNX Runtime is loaded once per process: nothing here loads a
//! working library. The fake libraries are compiled with the system C compiler (`cc`); without
//! one those cases are skipped with a message.

use std::path::{Path, PathBuf};
use std::process::Command;

use affcorr::runner::{RunnerError, init_ort, ort_library};

/// `tests/data/fake_ort/fake_ort.c` built as a library whose `GetVersionString` returns
/// `version` and whose `GetApi` returns NULL (no API at any level), as an old or broken build.
fn fake_ort(dir: &Path, version: &str) -> Option<PathBuf> {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/data/fake_ort/fake_ort.c");
    let lib = dir.join(format!("libonnxruntime.so.{version}"));
    let ok = Command::new("cc")
        .args(["-shared", "-fPIC"])
        .arg(format!("-DFAKE_ORT_VERSION=\"{version}\""))
        .arg("-o")
        .arg(&lib)
        .arg(&src)
        .status()
        .is_ok_and(|s| s.success());
    ok.then_some(lib)
}

/// A real shared library that is not ONNX Runtime: the C library this process runs on.
fn libc_path() -> Option<PathBuf> {
    std::fs::read_to_string("/proc/self/maps")
        .ok()?
        .lines()
        .filter_map(|l| l.split_whitespace().nth(5))
        .find(|p| p.contains("/libc.so") || p.contains("/libc-"))
        .map(PathBuf::from)
}

fn load_error(path: &Path) -> String {
    match init_ort(Some(path)) {
        Err(e @ RunnerError::OrtLibraryLoad { .. }) => {
            let msg = e.to_string();
            assert!(msg.contains(&path.display().to_string()), "{msg}");
            msg
        }
        other => panic!("{}: expected OrtLibraryLoad, got {other:?}", path.display()),
    }
}

// One test, in this order: the last case leaves ort holding the fake library (its loader
// caches a library that passed the version check before the API turned out to be missing).
#[test]
fn bad_libraries_are_typed_errors() {
    let dir = tempfile::tempdir().unwrap();

    let missing = dir.path().join("libonnxruntime.so.1.31.1");
    let r = init_ort(Some(&missing));
    assert!(
        matches!(
            r,
            Err(RunnerError::OrtLibraryNotFound {
                origin: "the caller",
                ..
            })
        ),
        "{r:?}"
    );
    assert!(
        r.unwrap_err()
            .to_string()
            .contains("libonnxruntime.so.1.31.1")
    );

    let text = dir.path().join("libonnxruntime.so");
    std::fs::write(&text, "not a shared library").unwrap();
    assert!(load_error(&text).contains("failed to load"));

    match libc_path() {
        Some(libc) => assert!(load_error(&libc).contains("does not export `OrtGetApiBase`")),
        None => eprintln!("skipped: libc not found in /proc/self/maps"),
    }

    match (
        fake_ort(dir.path(), "1.10.0"),
        fake_ort(dir.path(), "1.31.0"),
    ) {
        (Some(old), Some(broken)) => {
            let msg = load_error(&old);
            assert!(msg.contains("1.10.0") && msg.contains(">= '1.20"), "{msg}");
            // The version passes, the API is missing: ort panics inside; we get an error.
            load_error(&broken);
        }
        _ => eprintln!("skipped: no C compiler (cc) for the fake ONNX Runtime libraries"),
    }
    // Nothing was loaded.
    assert!(ort_library().is_none());
}
