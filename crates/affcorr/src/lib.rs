//! affcorr: affine correspondences for relative pose, homography and fundamental estimation.
//!
//! This facade re-exports the workspace crates; add only `affcorr` to your `Cargo.toml`.
//! - [`geom`]: conventions, AC synthesis/decomposition, Sampson distances, epipolar utilities.
//! - [`solvers`]: minimal and non-minimal solvers.
//! - [`ransac`]: robust estimation of H, F and relative pose from points or ACs.
//! - [`runner`]: ONNX Runtime runner: image decoding, the XFeat matchers (MNN, XFeat*,
//!   LighterGlue), dense `dense-warp-v1` matchers (DKM, RoMa exports) with DKM's balanced
//!   sampling, 32×32 patch extraction and the shape network (images + matches → ACs
//!   `A = S_AB·R(O_AB)·A′(A″)`).
//! - [`Pipeline`]: images → matches → ACs → homography / relative pose, timed per stage
//!   (re-exported from [`runner::pipeline`]).
//!
//! ```
//! use affcorr::geom::{affine::{AffineShape, synthesize, decompose}};
//! let a = synthesize(&AffineShape { orientation: 0.3, scale: 2.0, residual_shape: [0.1, 0.2, 0.0] }, 0).unwrap();
//! let shape = decompose(&a, 0).unwrap();
//! assert!((shape.orientation - 0.3).abs() < 1e-12 && (shape.scale - 2.0).abs() < 1e-12);
//! ```

pub use affcorr_geom as geom;
pub use affcorr_ransac as ransac;
pub use affcorr_runner as runner;
pub use affcorr_solvers as solvers;

pub use affcorr_runner::pipeline::{
    Estimated, ImageSource, Matcher, Matches, Pipeline, PipelineBuilder, PipelineError, Timings,
};
pub use affcorr_runner::{DenseMatcher, RgbImage, SamplingOptions};
