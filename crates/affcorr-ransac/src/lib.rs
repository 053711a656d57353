//! Robust estimation (DESIGN.md §5): one hypothesise-and-verify engine and the problems people
//! use it for.
//!
//! Module map (the axes vary independently, as in kornia-rs's `ransac`):
//! - [`problem`]: the [`Problem`] trait — data, minimal/non-minimal solvers, residuals, refinement.
//! - [`sampler`]: uniform and PROSAC sampling.
//! - [`score`]: MSAC (and MAGSAC++) scoring with an exact bail-out.
//! - [`engine`]: the loop — adaptive termination, local optimisation, final refinement.
//! - [`options`]: [`RansacOptions`] with documented defaults.
//! - [`error`]: [`RansacError`].

pub mod engine;
pub mod error;
pub mod options;
pub mod problem;
pub mod sampler;
pub mod score;

pub use engine::{Estimate, estimate};
pub use error::{RansacError, Result};
pub use options::RansacOptions;
pub use problem::Problem;
