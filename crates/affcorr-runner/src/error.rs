//! The typed error of the runner.
//!
//! Every variant says what went wrong and names the offending input (argument name and row,
//! file path, metadata key, ...), so bindings can pass the message straight to the user.

use std::path::PathBuf;

/// Everything that can go wrong in affcorr-runner.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RunnerError {
    /// No ONNX Runtime library was given and `ORT_DYLIB_PATH` is not set.
    #[error(
        "no ONNX Runtime library configured: set ORT_DYLIB_PATH to the path of libonnxruntime \
         (the PyPI wheel `pip install onnxruntime` ships it as \
         <site-packages>/onnxruntime/capi/libonnxruntime.so.<version>), or pass the path to \
         init_ort"
    )]
    OrtNotConfigured,
    /// The ONNX Runtime library path does not name an existing file.
    #[error(
        "ONNX Runtime library `{path}` (from {origin}) does not exist; set ORT_DYLIB_PATH to \
         libonnxruntime (e.g. from `pip install onnxruntime`)"
    )]
    OrtLibraryNotFound {
        /// The path that was tried.
        path: PathBuf,
        /// Where the path came from: `"the caller"` or `"ORT_DYLIB_PATH"`.
        origin: &'static str,
    },
    /// The library exists but could not be loaded: not a shared library, no ONNX Runtime C API,
    /// or a version older than the API level the runner needs (1.20).
    #[error("could not load the ONNX Runtime library `{path}`: {reason}")]
    OrtLibraryLoad {
        /// The library path.
        path: PathBuf,
        /// Why loading failed.
        reason: String,
    },
    /// An ONNX Runtime call failed after the library was loaded.
    #[error("ONNX Runtime error while {context}: {message}")]
    Ort {
        /// What the runner was doing.
        context: String,
        /// ONNX Runtime's message.
        message: String,
    },
    /// An image problem: a file that cannot be opened or decoded, a bad buffer, bad patch
    /// centres.
    #[error(transparent)]
    Image(#[from] affcorr_image::ImageError),
    /// A batched input with a bad shape or length, or a bad option.
    #[error("{what}: {reason}")]
    InvalidInput {
        /// Argument name.
        what: &'static str,
        /// What is wrong.
        reason: String,
    },
    /// A model file that does not exist or cannot be read.
    #[error("cannot read model `{path}`: {reason}")]
    ModelOpen {
        /// The file path.
        path: PathBuf,
        /// The I/O error.
        reason: String,
    },
    /// Bytes that ONNX Runtime cannot load as a model (not ONNX, corrupt, unsupported opset).
    #[error("cannot load model {model} with ONNX Runtime (not a valid ONNX model?): {reason}")]
    ModelLoad {
        /// The file path in backquotes, or `"from memory"`.
        model: String,
        /// ONNX Runtime's message.
        reason: String,
    },
    /// A valid ONNX model that breaks the network's contract (docs/design.md §6): wrong or missing
    /// inputs, outputs or metadata, or logits whose widths differ from the bin counts.
    #[error("model {model} violates the {contract} contract: {reason}")]
    Contract {
        /// The file path in backquotes, or `"from memory"`.
        model: String,
        /// The contract that was checked (`shape-v1`).
        contract: &'static str,
        /// What is wrong.
        reason: String,
    },
    /// The model produced an output the contract rules out (wrong shape, NaN).
    #[error("model output {what}: {reason}")]
    ModelOutput {
        /// Output name.
        what: &'static str,
        /// What is wrong.
        reason: String,
    },
    /// Affine synthesis rejected a decoded shape.
    #[error(transparent)]
    Geom(#[from] affcorr_geom::GeomError),
}

/// `Result` with [`RunnerError`].
pub type Result<T, E = RunnerError> = std::result::Result<T, E>;

impl RunnerError {
    /// An [`RunnerError::Ort`] from any ONNX Runtime error.
    pub(crate) fn ort(context: impl Into<String>, e: impl std::fmt::Display) -> Self {
        Self::Ort {
            context: context.into(),
            message: e.to_string(),
        }
    }

    /// An [`RunnerError::InvalidInput`].
    pub(crate) fn invalid(what: &'static str, reason: impl Into<String>) -> Self {
        Self::InvalidInput {
            what,
            reason: reason.into(),
        }
    }
}
