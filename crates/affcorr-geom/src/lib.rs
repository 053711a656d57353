//! Geometry core of affcorr: the conventions of docs/design.md §2–3 in one place.
//!
//! Module map:
//! - [`types`]: the affine correspondence (AC) and the `(N, 8)` / `(N, 4)` row layouts.
//! - [`error`]: the typed error every fallible function here returns.
//! - [`camera`]: intrinsics and conversion of ACs to normalised coordinates.
//! - [`affine`]: synthesis `A = s·R(θ)·A′(A″)` and its inverse, ACs from local affine frames,
//!   kornia LAF interop.
//! - [`homography`]: the AC a homography induces at a point.
//! - [`sampson`]: point and affine Sampson distances with analytic gradients.
//! - [`epipolar`]: E from a pose, F from E, decomposition of E and cheirality.
//! - [`synthetic`]: exact plane-induced scenes, the ground truth our tests stand on.
//! - [`batch`]: the rayon policy shared by all batched functions.
//!
//! Every batched function has a scalar twin that the hot loops of later crates call.

pub mod affine;
pub mod batch;
pub mod camera;
pub mod epipolar;
pub mod error;
pub mod homography;
pub mod sampson;
pub mod synthetic;
pub mod types;

pub use error::{GeomError, Result};
pub use types::{AffineCorrespondence, Mat2, Mat3, PointCorrespondence, Vec2, Vec3};
