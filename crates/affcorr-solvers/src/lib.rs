//! Minimal and non-minimal solvers (docs/design.md §4).
//!
//! Module map:
//! - [`poly`]: real roots of univariate polynomials (Sturm sequences), shared by the solvers.
//! - [`homography`]: H from 4 points, 2 ACs, 1 AC + F, and non-minimal least squares.
//! - [`fundamental`]: F from 7 points, N ≥ 8 points, 3 ACs, and non-minimal AC least squares.
//! - [`essential`]: E from 5 points, 2 ACs, N ≥ 8 points (+ ACs); calibrated, normalised input.
//! - [`relpose`]: relative poses (R, t) from those solvers, via decomposition + cheirality.
//! - `normalization` (private): Hartley normalisation, the weighting of affine rows in the AC
//!   systems and the input check of the indexed solvers, shared by the H and F solvers.
//! - `linalg` (private): the allocation-free linear algebra the H and F solvers share
//!   (complete-pivoting Gauss–Jordan, streaming Householder QR with inverse iteration, the
//!   smallest singular vector of a 3×3 matrix).

pub mod essential;
pub mod fundamental;
pub mod homography;
mod linalg;
mod normalization;
pub mod poly;
pub mod relpose;
