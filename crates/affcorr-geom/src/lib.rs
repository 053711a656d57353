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
//!
//! # Example
//!
//! The AC a homography induces at a point, its decomposition `A = s·R(θ)·A′`, and its
//! affine Sampson distances under an F compatible with H (`F = [e]× H`), which vanish:
//!
//! ```
//! use affcorr_geom::affine::decompose;
//! use affcorr_geom::epipolar::skew;
//! use affcorr_geom::homography::ac_from_homography;
//! use affcorr_geom::sampson::{sampson_affine, sampson_point};
//! use affcorr_geom::{Mat3, Vec2, Vec3};
//!
//! let h = Mat3::new(0.76, -0.30, 225.7, 0.33, 1.01, -77.0, 3.5e-4, -1.4e-5, 1.0);
//! let ac = ac_from_homography(&h, &Vec2::new(100.0, 200.0), 0)?;
//! let shape = decompose(&ac.a, 0)?; // orientation (rad), scale, residual shape
//! assert!((shape.scale - ac.a.determinant().sqrt()).abs() < 1e-12);
//!
//! let f = skew(&Vec3::new(1500.0, -400.0, 1.0)) * h;
//! let f = f / f.norm();
//! assert!(sampson_point(&f, &ac.points()).abs() < 1e-9);
//! assert!(sampson_affine(&f, &ac).iter().all(|d| d.abs() < 1e-9));
//! # Ok::<(), affcorr_geom::GeomError>(())
//! ```

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
