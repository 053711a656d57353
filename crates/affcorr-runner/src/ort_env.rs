//! The process-wide ONNX Runtime environment (docs/design.md §6).
//!
//! The runner loads ONNX Runtime at run time (`ort`'s `load-dynamic`): nothing is linked or
//! downloaded at build time. The library is the one the PyPI wheel `onnxruntime` ships
//! (`onnxruntime/capi/libonnxruntime.so.<version>`) or any other build of version ≥ 1.20.
//!
//! ONNX Runtime allows one environment per process, so it lives in a [`OnceLock`]: the first
//! successful [`init_ort`] wins and later calls are no-ops. A failed attempt is not cached, so
//! it can be retried with another path. Loading never panics: a missing file, a file that is
//! not a shared library, a library without the ONNX Runtime C API and a version older than 1.20
//! are all [`RunnerError`]s.

use std::ffi::OsString;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};
use std::sync::{Mutex, OnceLock};

use ort::environment::Environment;

use crate::error::{Result, RunnerError};

/// The environment variable naming the ONNX Runtime library.
pub const ORT_DYLIB_ENV: &str = "ORT_DYLIB_PATH";

struct OrtState {
    environment: Environment,
    library: PathBuf,
}

static STATE: OnceLock<OrtState> = OnceLock::new();
/// Serialises initialisation attempts (a failed one must not be cached by the `OnceLock`).
static INIT: Mutex<()> = Mutex::new(());

/// Loads ONNX Runtime and creates the process-wide environment.
///
/// The library is `path` when given, else `$ORT_DYLIB_PATH`; with neither, the error
/// [`RunnerError::OrtNotConfigured`] says how to get one. If ONNX Runtime is already loaded this
/// returns `Ok(())` and keeps the library loaded first (see [`ort_library`]).
///
/// ```no_run
/// affcorr_runner::init_ort(Some(std::path::Path::new(
///     ".venv/lib/python3.11/site-packages/onnxruntime/capi/libonnxruntime.so.1.31.1",
/// )))?;
/// # Ok::<(), affcorr_runner::RunnerError>(())
/// ```
pub fn init_ort(path: Option<&Path>) -> Result<()> {
    environment_from(path).map(|_| ())
}

/// The library the environment was created from, if ONNX Runtime is loaded.
pub fn ort_library() -> Option<&'static Path> {
    STATE.get().map(|s| s.library.as_path())
}

/// The default number of intra-op threads: every core [`std::thread::available_parallelism`]
/// reports.
pub fn default_threads() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// The environment, initialising it from `$ORT_DYLIB_PATH` on first use.
pub(crate) fn environment() -> Result<&'static Environment> {
    environment_from(None)
}

fn environment_from(path: Option<&Path>) -> Result<&'static Environment> {
    if let Some(state) = STATE.get() {
        return Ok(&state.environment);
    }
    let _guard = INIT.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
    if let Some(state) = STATE.get() {
        return Ok(&state.environment);
    }
    let library = resolve_library(path, std::env::var_os(ORT_DYLIB_ENV))?;
    let environment = load(&library)?;
    let state = STATE.get_or_init(|| OrtState {
        environment,
        library,
    });
    Ok(&state.environment)
}

/// Which library to load: `explicit`, else `env` (the value of `ORT_DYLIB_PATH`), made
/// absolute. Errors when neither is given or the file does not exist.
pub fn resolve_library(explicit: Option<&Path>, env: Option<OsString>) -> Result<PathBuf> {
    let (path, origin) = match (explicit, env) {
        (Some(p), _) => (p.to_path_buf(), "the caller"),
        (None, Some(v)) if !v.is_empty() => (PathBuf::from(v), ORT_DYLIB_ENV),
        _ => return Err(RunnerError::OrtNotConfigured),
    };
    if !path.is_file() {
        return Err(RunnerError::OrtLibraryNotFound { path, origin });
    }
    // ort resolves relative paths against the executable's directory first; make ours absolute
    // so the current directory is what counts.
    Ok(std::fs::canonicalize(&path).unwrap_or(path))
}

fn load(library: &Path) -> Result<Environment> {
    let load_error = |reason: String| RunnerError::OrtLibraryLoad {
        path: library.to_path_buf(),
        reason,
    };
    // ort checks the exported API and the version and returns errors for both; the panic guard
    // covers the remaining `expect`s inside ort (e.g. a library whose `GetApi` returns null).
    let attempt = catch_unwind(AssertUnwindSafe(|| {
        let builder = ort::init_from(library).map_err(|e| load_error(e.to_string()))?;
        builder
            .with_name("affcorr")
            .with_telemetry(false)
            .build()
            .map_err(|e| RunnerError::ort("creating the environment", e))
    }));
    match attempt {
        Ok(result) => result,
        Err(panic) => {
            let message = panic
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_else(|| "ONNX Runtime initialisation panicked".to_string());
            Err(load_error(message))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn neither_path_nor_env_says_how_to_fix_it() {
        let e = resolve_library(None, None).unwrap_err();
        assert!(matches!(e, RunnerError::OrtNotConfigured));
        let msg = e.to_string();
        assert!(msg.contains("ORT_DYLIB_PATH") && msg.contains("pip install onnxruntime"));
        let e = resolve_library(None, Some(OsString::new())).unwrap_err();
        assert!(matches!(e, RunnerError::OrtNotConfigured));
    }

    #[test]
    fn missing_files_are_named_with_their_origin() {
        let e = resolve_library(None, Some("/nonexistent/libonnxruntime.so".into())).unwrap_err();
        assert!(matches!(
            e,
            RunnerError::OrtLibraryNotFound {
                origin: "ORT_DYLIB_PATH",
                ..
            }
        ));
        assert!(e.to_string().contains("/nonexistent/libonnxruntime.so"));
        let e =
            resolve_library(Some(Path::new("/nonexistent/x.so")), Some("/tmp".into())).unwrap_err();
        assert!(matches!(
            e,
            RunnerError::OrtLibraryNotFound {
                origin: "the caller",
                ..
            }
        ));
        // A directory is not a library either.
        let e = resolve_library(Some(Path::new("/")), None).unwrap_err();
        assert!(matches!(e, RunnerError::OrtLibraryNotFound { .. }));
    }

    #[test]
    fn explicit_path_wins_over_the_environment() {
        let file = std::env::current_exe().unwrap();
        let p = resolve_library(Some(&file), Some("/nonexistent".into())).unwrap();
        assert_eq!(p, std::fs::canonicalize(&file).unwrap());
    }
}
