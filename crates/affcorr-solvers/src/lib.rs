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
//!
//! # Example
//!
//! Every solver writes its candidate models into a caller-owned buffer and returns how many it
//! wrote (a degenerate sample gives 0); H and F solvers take pixels, essential solvers
//! normalised coordinates.
//!
//! ```
//! use affcorr_geom::{Mat3, Vec2};
//! use affcorr_solvers::homography::homography_4pt;
//!
//! let h = Mat3::new(1.1, 0.1, 5.0, -0.05, 0.9, 3.0, 1e-4, 2e-4, 1.0);
//! let x1 = [Vec2::new(0.0, 0.0), Vec2::new(100.0, 0.0), Vec2::new(100.0, 80.0), Vec2::new(10.0, 90.0)];
//! let x2 = x1.map(|p| {
//!     let q = h * p.push(1.0);
//!     Vec2::new(q.x / q.z, q.y / q.z)
//! });
//! let mut out = [Mat3::zeros(); 1];
//! assert_eq!(homography_4pt(&x1, &x2, &mut out), 1);
//! assert!((out[0] / out[0][(2, 2)] - h).norm() < 1e-9);
//! assert!((out[0].norm() - 1.0).abs() < 1e-12); // unit Frobenius norm
//!
//! // Collinear points: no model.
//! let line = [0.0, 1.0, 2.0, 3.0].map(|t| Vec2::new(t, 2.0 * t));
//! assert_eq!(homography_4pt(&line, &x2, &mut out), 0);
//! ```

pub mod essential;
pub mod fundamental;
pub mod homography;
mod linalg;
mod normalization;
pub mod poly;
pub mod relpose;
