//! Images in, affine correspondences and geometry out: the matcher (XFeat, XFeat*,
//! XFeat + LighterGlue, or a dense `dense-warp-v1` model such as DKM or RoMa) gives the points,
//! the shape network the affine maps at them, the affine Lucas–Kanade refinement sharpens them
//! against the images, and affcorr-ransac estimates the homography, the fundamental matrix or
//! the relative pose. This is the only crate that needs both the ONNX runner and the robust
//! estimators; the Python package and the CLI bind it.
//!
//! ```no_run
//! use affcorr_pipeline::{Geometry, Pipeline, init_ort};
//!
//! init_ort(None)?; // ORT_DYLIB_PATH
//! let pipeline = Pipeline::builder()
//!     .models_dir("python/affcorr/models") // xfeat_*.onnx and shape.onnx
//!     .threads(2)
//!     .build()?;
//! let (a, b) = ("data/graffiti/graf1.png", "data/graffiti/graf3.png");
//! let m = pipeline.match_pair(a, b)?;
//! println!("{} ACs; {}", m.corrs.len(), m.timings);
//! let h = pipeline.homography(a, b, &Geometry::Homography.default_options())?;
//! println!("H = {}, {} inliers", h.estimate.model, h.estimate.num_inliers);
//! # Ok::<(), affcorr_pipeline::PipelineError>(())
//! ```
//!
//! # What `match_pair` does
//!
//! 1. **decode**: file paths are decoded to grayscale ([`GrayImage`]) and turned upright by the
//!    turn of their EXIF orientation (a photograph taken in portrait;
//!    [`PipelineBuilder::exif_orientation`], on by default; `affcorr_image::orientation`); an
//!    image whose longer side exceeds [`PipelineBuilder::max_side`] is downscaled
//!    (antialiased triangle filter) by s = max_side / max(W, H) to its *working resolution*
//!    ([`affcorr_image::limit_side`]);
//!    the matcher's inputs are resized to multiples of 32.
//! 2. **matcher**: the backbone network (once per image; twice for XFeat*, at scales 0.6 and
//!    1.3), or the dense matcher on the pair (colour images resized to its input size).
//! 3. **detection**: sparse keypoints and descriptors, or the semi-dense cells of XFeat* (none
//!    for a dense matcher).
//! 4. **matching**: mutual nearest neighbours (certainty = cosine similarity), then the XFeat*
//!    refinement model (certainty = its confidence), or LighterGlue (certainty = its match
//!    score); for a dense matcher DKM's balanced sampling of [`PipelineBuilder::max_matches`]
//!    (default [`defaults::DENSE_MATCHES`]) cells from its certainty map, seeded by
//!    [`PipelineBuilder::seed`]. Steps 2–4 are [`affcorr_runner::PointMatcher`]'s. Matches are
//!    sorted by decreasing certainty (stable) and cut to [`PipelineBuilder::max_matches`].
//! 5. **patches** and **shape net**: 32×32 patches around the matched points in the working
//!    images, the shape network's A at them ([`affcorr_runner::ShapeEstimator`]).
//! 6. **affine refine**: affine Lucas–Kanade against the working images
//!    ([`affcorr_image::refine_affine`]; on by default, [`PipelineBuilder::affine_refinement`]).
//! 7. **views**: unless the plain pair verifies (a fundamental matrix with enough inliers),
//!    synthetic views (rotations, zooms, tilts) are matched until one does, and their ACs are
//!    mapped back through the view's warp ([`views`]; on by default, [`ViewMode::Auto`]).
//! 8. The ACs are mapped back to the original pixels (pixel centres at integers, image edges
//!    aligned): x = (x_work + 0.5)/s − 0.5 per axis, and A = diag(1/s_B) · A_work · diag(s_A)
//!    (A = ∂x2/∂x1, docs/design.md §2; [`affcorr_image::ac_to_original`]), then turned back
//!    into a file's stored pixels (exact: [`affcorr_image::ac_from_views`] with the turn's
//!    [`affcorr_image::Orientation::display_warp`]).
//!
//! [`Pipeline::homography`], [`Pipeline::fundamental`] and [`Pipeline::relative_pose`] add
//! **ransac**: affcorr-ransac's estimators on the ACs (AC samples unless the options say
//! otherwise). With PROSAC sampling and no `quality`, the certainties are the quality.
//! [`Geometry::default_options`] gives each geometry's default options.
//!
//! Every stage's wall time is in [`Timings`]. The pipeline emits [`tracing`](https://docs.rs/tracing)
//! events (target `affcorr_pipeline`): `debug` per pair with its stage timings and per view of
//! the cascade, `info` when a pair falls back to synthetic views; install a subscriber (e.g.
//! `tracing-subscriber`) to see them. The defaults are in [`defaults`], one set for
//! Rust, Python and the CLI.
//!
//! # Modules
//!
//! - [`defaults`]: the one set of defaults, and [`Geometry`].
//! - [`builder`]: [`PipelineBuilder`], model paths and options.
//! - [`pipeline`]: [`Pipeline`]: `match_pair`, `match_pairs` and the estimators.
//! - [`features`]: [`Features`], one image's features: [`Pipeline::extract`] once per image,
//!   [`Pipeline::match_features`] per pair (what `match_pairs` does for shared images).
//! - [`source`]: [`ImageSource`], the image arguments (files, gray or colour buffers).
//! - [`views`]: the view cascade for rotated, zoomed and tilted pairs.
//! - [`result`]: [`Matches`], [`Timings`] and [`Estimated`].
//! - [`error`]: [`PipelineError`], which says which stage failed.

pub mod builder;
pub mod defaults;
pub mod error;
pub mod features;
pub mod grow;
pub mod pipeline;
pub mod result;
pub mod source;
pub mod views;

pub use builder::{
    BACKBONE_FILE, DENSE_FILE, LIGHTERGLUE_FILE, PipelineBuilder, REFINE_FILE, SHAPE_FILE,
    model_file,
};
pub use defaults::Geometry;
pub use error::{PipelineError, Result};
pub use features::Features;
pub use grow::{GrowOptions, Grown};
pub use pipeline::{MAX_WORKING_PIXELS, Pipeline};
pub use result::{Estimated, Matches, Timings};
pub use source::ImageSource;
pub use views::{ViewImage, ViewMode, ViewOptions, ViewReport, ViewSpec};

pub use affcorr_image::{AffineRefineOptions, GrayImage, RgbImage};
pub use affcorr_ransac::EstimatorOptions;
pub use affcorr_runner::{Matcher, ModelRole, init_ort};
