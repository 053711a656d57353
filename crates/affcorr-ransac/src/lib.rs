//! Robust estimation (docs/design.md §5): one hypothesise-and-verify engine and the problems people
//! use it for.
//!
//! Module map (the axes vary independently, as in kornia-rs's `ransac`):
//! - [`problem`]: the [`Problem`] trait: data, minimal/non-minimal solvers, residuals, refinement.
//! - [`sampler`]: uniform and PROSAC sampling.
//! - [`score`]: MSAC and MAGSAC++ scoring, the [`score::Scoring`] trait.
//! - [`loss`]: the robust losses of the refinements and the tabulated MAGSAC++ loss (its
//!   closed form).
//! - [`refine`]: Levenberg–Marquardt with robust losses, used by local optimisation and the
//!   final refinement.
//! - [`graph_cut`]: inlier labelling by a minimum cut with spatial coherence (GC-RANSAC's
//!   local optimisation).
//! - [`engine`]: the loop: sampling, verification, adaptive termination, final refinement.
//! - `verify` (private): one hypothesis scored over all data with an exact bail-out, the
//!   residual cache, inlier collection.
//! - `sprt` (private): Wald's sequential probability ratio test of a hypothesis.
//! - `local_opt` (private): local optimisation: the threshold schedule, iterated least squares,
//!   the graph-cut glue.
//! - [`options`]: [`RansacOptions`] with documented defaults.
//! - [`error`]: the typed error, [`RansacError`].
//! - [`problems`]: homography, fundamental matrix and relative pose, with point or AC samples.
//! - [`estimators`]: the entry points `estimate_*` and their parallel `_batch` forms.
//!
//! # Example
//!
//! A relative pose from 300 ACs of a seeded three-plane scene with 30% outliers; the
//! homography and the fundamental matrix work alike ([`estimate_homography`],
//! [`estimate_fundamental`]).
//!
//! ```
//! use affcorr_geom::synthetic::{NoiseModel, PlaneScene, noisy_correspondences};
//! use affcorr_ransac::{Correspondences, EstimatorOptions, estimate_relative_pose};
//! use rand::{SeedableRng, rngs::StdRng};
//!
//! let mut rng = StdRng::seed_from_u64(5);
//! let scene = PlaneScene::random(&mut rng);
//! let noise = NoiseModel { planes: 3, outlier_ratio: 0.3, pixel_noise: 0.5, affine_noise: 0.01 };
//! let (acs, truth) = noisy_correspondences(&mut rng, &scene, 300, &noise);
//!
//! let mut opts = EstimatorOptions::default();
//! opts.ransac.threshold = 1.0; // pixels
//! let data = Correspondences::from_acs(&acs)?;
//! let est = estimate_relative_pose(&data, &scene.k1, &scene.k2, &opts)?;
//!
//! let r_err = ((est.model.pose.r.transpose() * scene.pose.r).trace() - 1.0) / 2.0;
//! assert!(r_err.clamp(-1.0, 1.0).acos().to_degrees() < 0.5);
//! // Most true inliers are found, few outliers are taken.
//! let hits = est.inliers.iter().zip(&truth).filter(|(e, t)| **e && **t).count();
//! assert!(hits as f64 > 0.9 * truth.iter().filter(|t| **t).count() as f64);
//! assert!(est.num_inliers - hits < 10);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod engine;
pub mod error;
pub mod estimators;
pub mod graph_cut;
mod local_opt;
pub mod loss;
pub mod options;
pub mod planar;
pub mod problem;
pub mod problems;
pub mod refine;
pub mod sampler;
pub mod score;
mod sprt;
mod verify;

pub use engine::{Estimate, estimate};
pub use error::{RansacError, Result};
pub use estimators::{
    BatchOptions, DEFAULT_AFFINE_FALLBACK, DEFAULT_AFFINE_WEIGHT, EstimatorOptions, SamplerKind,
    ScoringKind, estimate_fundamental, estimate_fundamental_batch, estimate_homography,
    estimate_homography_batch, estimate_relative_pose, estimate_relative_pose_batch,
};
pub use options::{AffineRefinement, LoKind, LoSchedule, RansacOptions};
pub use planar::{PLANAR_SHARE, PlanarTwin, planar_twin};
pub use problem::Problem;
pub use problems::{Correspondences, SampleKind};
