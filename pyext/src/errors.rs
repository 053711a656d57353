//! Rust errors to Python exceptions, in one place for every crate's error type.
//!
//! - A missing file (image or model) is `FileNotFoundError`.
//! - Bad arguments, images and options (shapes, NaN, undecodable images, bad values) are
//!   `ValueError`.
//! - ONNX Runtime and model problems (library not found, not ONNX, contract violations,
//!   inference failures) are `RuntimeError`.
//!
//! `what`, when given, names the argument: the message is prefixed with it unless it already
//! starts with it.

use affcorr::image::ImageError;
use affcorr::pipeline::PipelineError;
use affcorr::runner::RunnerError;
use pyo3::PyErr;
use pyo3::exceptions::{PyFileNotFoundError, PyRuntimeError, PyValueError};

/// Which exception a Rust error becomes.
enum Kind {
    FileNotFound,
    Value,
    Runtime,
}

fn image_kind(e: &ImageError) -> Kind {
    match e {
        ImageError::Open { path, .. } if !path.exists() => Kind::FileNotFound,
        _ => Kind::Value,
    }
}

fn runner_kind(e: &RunnerError) -> Kind {
    match e {
        RunnerError::ModelOpen { path, .. } if !path.exists() => Kind::FileNotFound,
        RunnerError::Image(e) => image_kind(e),
        RunnerError::InvalidInput { .. } => Kind::Value,
        _ => Kind::Runtime,
    }
}

fn raise(kind: Kind, text: String, what: Option<&str>) -> PyErr {
    let msg = match what {
        Some(w) if !text.starts_with(w) => format!("{w}: {text}"),
        _ => text,
    };
    match kind {
        Kind::FileNotFound => PyFileNotFoundError::new_err(msg),
        Kind::Value => PyValueError::new_err(msg),
        Kind::Runtime => PyRuntimeError::new_err(msg),
    }
}

/// An image error as the exception its kind calls for.
pub fn image_error(e: ImageError, what: Option<&str>) -> PyErr {
    raise(image_kind(&e), e.to_string(), what)
}

/// A runner error as the exception its kind calls for.
pub fn runner_error(e: RunnerError, what: Option<&str>) -> PyErr {
    raise(runner_kind(&e), e.to_string(), what)
}

/// A pipeline error as the exception its stage's error calls for; estimation errors are
/// `ValueError`s (bad options, too few matches).
pub fn pipeline_error(e: PipelineError, what: Option<&str>) -> PyErr {
    let kind = match &e {
        PipelineError::Image(e) => image_kind(e),
        PipelineError::Runner(e) => runner_kind(e),
        _ => Kind::Value,
    };
    raise(kind, e.to_string(), what)
}

/// Whether `e` must reach the caller unchanged: anything that is not an `Exception`
/// (`KeyboardInterrupt`, `SystemExit`, ...), which no `except ValueError` may swallow. Code
/// that rewraps an error into a `ValueError` with more context checks this first.
pub fn passes_through(py: pyo3::Python<'_>, e: &PyErr) -> bool {
    !e.is_instance_of::<pyo3::exceptions::PyException>(py)
}

/// `e` itself when it [`passes_through`], else `rewrap(e)`.
pub fn rewrap(e: PyErr, rewrap: impl FnOnce(PyErr) -> PyErr) -> PyErr {
    if pyo3::Python::attach(|py| passes_through(py, &e)) {
        e
    } else {
        rewrap(e)
    }
}
