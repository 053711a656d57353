//! The typed error of the geometry crate.

/// Everything that can go wrong in affcorr-geom. Each variant names the offending input, and
/// the row index for batched calls, so bindings can pass the message straight to the user.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GeomError {
    /// `det A ≤ 0`: a reflection or a degenerate map, which has no `s·R(θ)·A′` form.
    #[error("{what}[{index}]: det A = {det:e} is not positive (reflection or degenerate affine)")]
    NonPositiveDeterminant {
        /// Argument name.
        what: &'static str,
        /// Row index.
        index: usize,
        /// The offending determinant.
        det: f64,
    },
    /// A value that must be strictly positive is not.
    #[error("{what}[{index}] = {value:e} must be positive")]
    NotPositive {
        /// Argument name.
        what: &'static str,
        /// Row index.
        index: usize,
        /// The offending value.
        value: f64,
    },
    /// NaN or infinity in an input.
    #[error("{what}[{index}] contains NaN or infinity")]
    NonFinite {
        /// Argument name.
        what: &'static str,
        /// Row index.
        index: usize,
    },
    /// Two batched inputs of different lengths.
    #[error("{what}: expected {expected} rows, got {got}")]
    LengthMismatch {
        /// Argument name.
        what: &'static str,
        /// Expected length.
        expected: usize,
        /// Actual length.
        got: usize,
    },
    /// A camera matrix that is not a valid intrinsic matrix.
    #[error("{what} is not a valid intrinsic matrix: {reason}")]
    InvalidIntrinsics {
        /// Argument name (`K1`, `K2`, ...).
        what: &'static str,
        /// Why it was rejected.
        reason: &'static str,
    },
    /// A point maps to infinity under a homography (`h₃ · p = 0`).
    #[error("x1[{index}] maps to infinity under H (h3 · p1 = {w:e})")]
    PointAtInfinity {
        /// Row index.
        index: usize,
        /// The vanishing denominator.
        w: f64,
    },
    /// A matrix that the operation needs to be invertible or of a given rank is not.
    #[error("{what} is degenerate: {reason}")]
    Degenerate {
        /// Argument name.
        what: &'static str,
        /// Why it was rejected.
        reason: &'static str,
    },
    /// A result that does not fit in f64, from finite inputs (e.g. `s · A′` past 1.8e308).
    #[error("{what}[{index}]: the result overflows f64 ({reason})")]
    Overflow {
        /// Argument name.
        what: &'static str,
        /// Row index.
        index: usize,
        /// What overflowed.
        reason: &'static str,
    },
}

/// Result alias for this crate.
pub type Result<T> = std::result::Result<T, GeomError>;
