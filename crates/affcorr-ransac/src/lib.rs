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

pub mod engine;
pub mod error;
pub mod estimators;
pub mod graph_cut;
mod local_opt;
pub mod loss;
pub mod options;
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
    BatchOptions, EstimatorOptions, SamplerKind, ScoringKind, estimate_fundamental,
    estimate_fundamental_batch, estimate_homography, estimate_homography_batch,
    estimate_relative_pose, estimate_relative_pose_batch,
};
pub use options::{LoKind, RansacOptions};
pub use problem::Problem;
pub use problems::{Correspondences, SampleKind};
