//! The typed error of the pipeline: which stage failed, with that stage's own error.

use affcorr_image::ImageError;
use affcorr_ransac::RansacError;
use affcorr_runner::RunnerError;

/// What can go wrong in a pipeline.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PipelineError {
    /// Images: a file that cannot be opened or decoded, a bad buffer, points outside.
    #[error(transparent)]
    Image(#[from] ImageError),
    /// The networks: loading, contracts, inference.
    #[error(transparent)]
    Runner(#[from] RunnerError),
    /// Robust estimation (e.g. fewer matches than a minimal sample).
    #[error(transparent)]
    Ransac(#[from] RansacError),
    /// A bad option or argument of the pipeline itself.
    #[error("{what}: {reason}")]
    InvalidInput {
        /// Argument name.
        what: &'static str,
        /// What is wrong.
        reason: String,
    },
}

/// `Result` with [`PipelineError`].
pub type Result<T, E = PipelineError> = std::result::Result<T, E>;

impl PipelineError {
    /// A [`PipelineError::InvalidInput`].
    pub(crate) fn invalid(what: &'static str, reason: impl Into<String>) -> Self {
        Self::InvalidInput {
            what,
            reason: reason.into(),
        }
    }

    /// An image error of argument `what`: a bad buffer is named after the argument; file errors
    /// name their file already.
    pub(crate) fn image(e: ImageError, what: &'static str) -> Self {
        match e {
            ImageError::Buffer { reason } => Self::invalid(what, reason),
            other => Self::Image(other),
        }
    }
}
