//! The typed error of the robust estimators.

/// Why an estimation could not run or found nothing.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RansacError {
    /// Fewer data than a minimal sample.
    #[error("{what}: need at least {needed} correspondences, got {got}")]
    NotEnoughData {
        /// Argument name.
        what: &'static str,
        /// Minimal sample size.
        needed: usize,
        /// Data given.
        got: usize,
    },
    /// An option out of its valid range.
    #[error("{name} = {value} is invalid: {reason}")]
    InvalidOption {
        /// Option name.
        name: &'static str,
        /// Its value, formatted.
        value: String,
        /// The valid range.
        reason: &'static str,
    },
    /// An input array with NaN or infinity.
    #[error("{what}[{index}] contains NaN or infinity")]
    NonFinite {
        /// Argument name.
        what: &'static str,
        /// Row index.
        index: usize,
    },
    /// Invalid geometric input (e.g. intrinsics).
    #[error(transparent)]
    Geometry(#[from] affcorr_geom::GeomError),
    /// No sample gave a model with a single inlier.
    #[error(
        "no model found in {iterations} iterations: every sample was degenerate or had no inlier"
    )]
    NoModel {
        /// Iterations run (minimal samples drawn) before giving up.
        iterations: usize,
    },
}

/// Result alias of this crate.
pub type Result<T> = std::result::Result<T, RansacError>;
