//! affcorr: affine correspondences for relative pose, homography and fundamental estimation.
//!
//! This facade re-exports the workspace crates; add only `affcorr` to your `Cargo.toml`.
//! - [`geom`]: conventions, AC synthesis/decomposition, Sampson distances, epipolar utilities.
//! - [`solvers`]: minimal and non-minimal solvers.
//! - [`ransac`]: robust estimation of H, F and relative pose from points or ACs.
//! - [`image`]: images (decoding, gray and colour buffers, resizing), 32×32 patches, and the
//!   affine Lucas–Kanade refinement of ACs.
//! - [`runner`]: the ONNX networks: the XFeat matchers (MNN, XFeat*, LighterGlue), dense
//!   `dense-warp-v1` matchers (DKM, RoMa exports) with DKM's balanced sampling, and the shape
//!   network (images + matches → ACs `A = S_AB·R(O_AB)·A′(A″)`).
//! - [`pipeline`]: [`Pipeline`]: images → matches → ACs → homography, fundamental matrix or
//!   relative pose, timed per stage, with one set of [`pipeline::defaults`].
//!
//! ```
//! use affcorr::geom::{affine::{AffineShape, synthesize, decompose}};
//! let a = synthesize(&AffineShape { orientation: 0.3, scale: 2.0, residual_shape: [0.1, 0.2, 0.0] }, 0).unwrap();
//! let shape = decompose(&a, 0).unwrap();
//! assert!((shape.orientation - 0.3).abs() < 1e-12 && (shape.scale - 2.0).abs() < 1e-12);
//! ```

pub use affcorr_geom as geom;
pub use affcorr_image as image;
pub use affcorr_pipeline as pipeline;
pub use affcorr_ransac as ransac;
pub use affcorr_runner as runner;
pub use affcorr_solvers as solvers;

pub use affcorr_pipeline::{
    Estimated, Geometry, ImageSource, Matcher, Matches, Pipeline, PipelineBuilder, PipelineError,
    Timings,
};
