//! Minimal and non-minimal solvers (docs/design.md §4).
//!
//! Module map:
//! - [`poly`]: real roots of univariate polynomials (Sturm sequences), shared by the solvers.
//! - [`homography`]: H from 4 points, 2 ACs, 1 AC + F, and non-minimal least squares.
//! - [`fundamental`]: F from 7 points, N ≥ 8 points, 3 ACs, and non-minimal AC least squares.
//! - [`essential`]: E from 5 points, 2 ACs, N ≥ 8 points (+ ACs); calibrated, normalised input.
//! - [`relpose`]: relative poses (R, t) from those solvers, via decomposition + cheirality.
//! - `normalization` (private): Hartley normalisation and the allocation-free linear algebra
//!   (complete-pivoting Gauss–Jordan, streaming Householder QR, inverse iteration) shared by the
//!   H and F solvers.
//!
//! Solvers are being added (issue #3).

pub mod essential;
pub mod fundamental;
pub mod homography;
mod normalization;
pub mod poly;
pub mod relpose;
