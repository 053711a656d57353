//! Helpers for affcorr's own tests and benches, never a dependency of a library crate: where
//! the checkout is, which ONNX Runtime library its tests load, and image files tagged with an
//! EXIF orientation. The libraries themselves take the ONNX Runtime library from the caller or
//! `ORT_DYLIB_PATH` only.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// The environment variable naming the ONNX Runtime library.
pub const ORT_DYLIB_ENV: &str = "ORT_DYLIB_PATH";

/// The repository root (this crate lives in `crates/affcorr-devtools`).
pub fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The bundled models (`python/affcorr/models`).
pub fn models_dir() -> PathBuf {
    repo_root().join("python/affcorr/models")
}

/// Finds an ONNX Runtime library for the checkout at `root`: `$ORT_DYLIB_PATH` (a relative
/// path that does not exist from the current directory is taken relative to `root`, because
/// cargo runs tests and benches in the package directory), else the `onnxruntime` wheel's
/// library in `root/.venv` (`lib/python*/site-packages/onnxruntime/capi/libonnxruntime.so*`),
/// which `scripts/setup.sh` installs.
pub fn locate_ort_library(root: &Path) -> Option<PathBuf> {
    if let Some(p) = std::env::var_os(ORT_DYLIB_ENV).filter(|p| !p.is_empty()) {
        let p = PathBuf::from(p);
        return Some(if p.is_relative() && !p.exists() {
            root.join(p)
        } else {
            p
        });
    }
    std::fs::read_dir(root.join(".venv/lib"))
        .ok()?
        .flatten()
        .find_map(|d| {
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
}

/// [`locate_ort_library`] for this checkout, or a panic that says how to get one: tests that
/// need ONNX Runtime must not pass silently without it.
pub fn ort_library() -> PathBuf {
    let root = repo_root();
    locate_ort_library(&root).unwrap_or_else(|| {
        panic!(
            "ONNX Runtime not found: set ORT_DYLIB_PATH to libonnxruntime.so (scripts/test.sh \
             does), or run scripts/setup.sh so that {} holds the onnxruntime wheel",
            root.join(".venv/lib").display()
        )
    })
}

/// Graffiti's ground-truth homography H1to3p (p3 ~ H p1), row-major, from its OpenCV XML.
pub fn graffiti_homography() -> [f64; 9] {
    let xml = std::fs::read_to_string(repo_root().join("data/graffiti/H1to3p.xml"))
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

/// Writes the dense test model (`python -m affcorr.export.dense_test_model`: a graph whose warp
/// is graffiti's ground-truth homography, 800×640 on both sides) to `out`, with `args` added to
/// the script's command line, using the checkout's `.venv` Python (scripts/setup.sh with
/// `AFFCORR_WITH_TORCH=1` installs its `onnx`). Panics with the script's error otherwise.
pub fn write_dense_test_model(out: &Path, args: &[&str]) {
    let python = repo_root().join(".venv/bin/python");
    let h: Vec<String> = graffiti_homography()
        .iter()
        .map(|v| v.to_string())
        .collect();
    let status = std::process::Command::new(&python)
        .args(["-m", "affcorr.export.dense_test_model"])
        .arg(out)
        .arg("--homography")
        .args(&h)
        .args(["--size-a", "800", "640", "--size-b", "800", "640"])
        .args(args)
        .output()
        .unwrap_or_else(|e| {
            panic!(
                "cannot run {} (run scripts/setup.sh with AFFCORR_WITH_TORCH=1 for onnx): {e}",
                python.display()
            )
        });
    assert!(
        status.status.success(),
        "dense_test_model failed (needs the onnx package: AFFCORR_WITH_TORCH=1 scripts/setup.sh): {}",
        String::from_utf8_lossy(&status.stderr)
    );
}

/// The dense test model written with `args` ([`write_dense_test_model`]) into this process's
/// temporary directory as `name`, once per process.
pub fn dense_test_model(name: &str, args: &[&str]) -> PathBuf {
    static DIR: OnceLock<tempfile::TempDir> = OnceLock::new();
    let dir = DIR.get_or_init(|| tempfile::tempdir().expect("a temporary directory"));
    let out = dir.path().join(name);
    if !out.is_file() {
        write_dense_test_model(&out, args);
    }
    out
}

/// Whether the models exported at setup time (`benches/eval/setup.sh`, not committed) are in
/// the models directory: `file` is one of them. Missing: a note on stderr and `false`, or a
/// failure under `AFFCORR_REQUIRE_EXPORTED_MODELS=1` (scripts/test.sh), naming `command`.
pub fn exported(file: &str, what: &str, command: &str) -> bool {
    let dir = models_dir();
    if dir.join(file).is_file() {
        return true;
    }
    let required = std::env::var("AFFCORR_REQUIRE_EXPORTED_MODELS").is_ok_and(|v| v == "1");
    assert!(
        !required,
        "the {what} models are missing from {}: run `{command}`",
        dir.display()
    );
    eprintln!("note: {what} not exported ({command}); its tests not run");
    false
}

/// A JPEG or PNG file's bytes with an EXIF block holding only the orientation `tag` (any
/// value, valid or not), for tests: an APP1 segment after a JPEG's start-of-image marker, an
/// eXIf chunk after a PNG's header chunk.
pub fn with_exif_orientation(file: &[u8], tag: u16) -> Vec<u8> {
    // A little-endian TIFF header, one IFD with one entry (0x0112, SHORT, count 1), no next IFD.
    let mut tiff = b"II*\0".to_vec();
    tiff.extend_from_slice(&8u32.to_le_bytes());
    tiff.extend_from_slice(&1u16.to_le_bytes());
    tiff.extend_from_slice(&0x0112u16.to_le_bytes());
    tiff.extend_from_slice(&3u16.to_le_bytes());
    tiff.extend_from_slice(&1u32.to_le_bytes());
    tiff.extend_from_slice(&tag.to_le_bytes());
    tiff.extend_from_slice(&[0, 0]);
    tiff.extend_from_slice(&0u32.to_le_bytes());
    let mut out = Vec::with_capacity(file.len() + tiff.len() + 32);
    if file.starts_with(&[0xFF, 0xD8]) {
        let payload = [b"Exif\0\0".as_slice(), &tiff].concat();
        out.extend_from_slice(&file[..2]);
        out.extend_from_slice(&[0xFF, 0xE1]);
        out.extend_from_slice(&((payload.len() + 2) as u16).to_be_bytes());
        out.extend_from_slice(&payload);
        out.extend_from_slice(&file[2..]);
    } else {
        // PNG: the signature (8 bytes) and IHDR (4 + 4 + 13 + 4) come first.
        let at = 8 + 25;
        let mut chunk = (tiff.len() as u32).to_be_bytes().to_vec();
        let body = [b"eXIf".as_slice(), &tiff].concat();
        chunk.extend_from_slice(&body);
        chunk.extend_from_slice(&crc32fast::hash(&body).to_be_bytes());
        out.extend_from_slice(&file[..at]);
        out.extend_from_slice(&chunk);
        out.extend_from_slice(&file[at..]);
    }
    out
}
