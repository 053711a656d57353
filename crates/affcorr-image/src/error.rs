//! The typed error of the image crate.
//!
//! Every variant names the offending input (file path, argument name and row), so bindings can
//! pass the message straight to the user.

use std::path::PathBuf;

/// Everything that can go wrong in affcorr-image.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ImageError {
    /// An image file that does not exist or cannot be opened.
    #[error("cannot open image `{path}`: {reason}")]
    Open {
        /// The file path.
        path: PathBuf,
        /// The I/O error.
        reason: String,
    },
    /// Image bytes that cannot be decoded (unknown format, truncated or corrupt data).
    #[error("cannot decode image {source_name}: {reason}")]
    Decode {
        /// The file path in backquotes, or `"from memory"`.
        source_name: String,
        /// The decoder's message.
        reason: String,
    },
    /// A raw pixel buffer that does not describe an image (size mismatch, zero size, bad
    /// channel count, non-finite values).
    #[error("invalid image buffer: {reason}")]
    Buffer {
        /// What is wrong.
        reason: String,
    },
    /// A batched input with a bad shape or length, or a bad option.
    #[error("{what}: {reason}")]
    InvalidInput {
        /// Argument name.
        what: &'static str,
        /// What is wrong.
        reason: String,
    },
    /// NaN or infinity in an input row.
    #[error("{what}[{row}] contains NaN or infinity")]
    NonFinite {
        /// Argument name.
        what: &'static str,
        /// Row index.
        row: usize,
    },
}

/// `Result` with [`ImageError`].
pub type Result<T, E = ImageError> = std::result::Result<T, E>;

impl ImageError {
    /// An [`ImageError::InvalidInput`].
    pub fn invalid(what: &'static str, reason: impl Into<String>) -> Self {
        Self::InvalidInput {
            what,
            reason: reason.into(),
        }
    }
}
