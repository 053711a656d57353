//! ONNX runner of affcorr's networks (docs/design.md §6): images and matches in, affine
//! correspondences out.
//!
//! - [`ort_env`]: loads ONNX Runtime at run time (`ORT_DYLIB_PATH` or [`init_ort`]); one
//!   environment per process.
//! - [`affine_refine`]: affine Lucas–Kanade refinement of ACs against the two images.
//! - [`image`]: PNG/JPEG decoding and raw buffers to grayscale `f32` in [0, 1].
//! - [`patches`]: 32×32 bilinear patches at sub-pixel centres, `(N, 1, 32, 32)`.
//! - [`shape`]: the shape network's ONNX contract (`shape-v1`), batched inference and the
//!   softmax-mean decoding of its orientation and scale logits.
//! - [`estimator`]: the ACs A = S_AB · R(O_AB) · A′(A″) of matched points.
//! - [`features`]: the XFeat backbone (`features-backbone-v1`) and sparse / semi-dense feature
//!   extraction from its maps (the specification is `python/affcorr/export/xfeat_reference.py`).
//! - [`matching`]: mutual nearest neighbours, the XFeat* refinement model and LighterGlue.
//! - [`dense`]: dense matchers (DKM, RoMa) under `dense-warp-v1` and DKM's balanced sampling
//!   of matches from their certainty map.
//! - [`contract`]: the matcher models' ONNX contracts (docs/matchers.md), checked on loading.
//! - [`pipeline`]: [`Pipeline`]: images → matches → ACs → homography / relative pose, timed per
//!   stage.
//! - [`error`]: [`RunnerError`], which names what went wrong.
//!
//! Conventions are docs/design.md §2's: pixels (x, y) with x right and y down, pixel centres at
//! integer coordinates, ACs `[x1, y1, x2, y2, a11, a12, a21, a22]` with A = ∂x2/∂x1, radians.
//!
//! # Example
//!
//! ```no_run
//! use affcorr_runner::{GrayImage, ShapeEstimator, ShapeModelOptions, init_ort};
//!
//! // The library from the `onnxruntime` PyPI wheel, or leave it to ORT_DYLIB_PATH with `None`.
//! init_ort(Some("/path/to/onnxruntime/capi/libonnxruntime.so.1.31.1".as_ref()))?;
//! let options = ShapeModelOptions { threads: Some(2), ..Default::default() };
//! let estimator = ShapeEstimator::load("models/shape.onnx", &options)?;
//! let (a, b) = (GrayImage::open("a.png")?, GrayImage::open("b.jpg")?);
//! let est = estimator.estimate(&a, &b, &[[120.5, 80.0]], &[[131.2, 77.9]])?;
//! let [x1, y1, x2, y2, a11, a12, a21, a22] = est.corrs[0];
//! println!("({x1}, {y1}) -> ({x2}, {y2}), A = [[{a11}, {a12}], [{a21}, {a22}]]");
//! # Ok::<(), affcorr_runner::RunnerError>(())
//! ```

pub mod affine_refine;
pub mod contract;
pub mod dense;
pub mod error;
pub mod estimator;
pub mod features;
pub mod image;
pub mod matching;
pub mod ort_env;
pub mod patches;
pub mod pipeline;
pub mod shape;

pub use affine_refine::{AffineRefineOptions, AffineRefinement, refine_affine};
pub use error::{Result, RunnerError};
pub use estimator::{ShapeEstimate, ShapeEstimator};
pub use image::{GrayImage, PixelData};
pub use ort_env::{init_ort, ort_library};
pub use patches::{PATCH_SIZE, Patches, extract_patches};
pub use shape::{ShapeBins, ShapeModel, ShapeModelOptions, ShapeOutputs, ShapePrediction};

pub use dense::{DenseMatcher, DenseSample, DenseWarp, RgbImage, SamplingOptions, balanced_sample};
pub use features::{Backbone, BackboneConfig, BackboneMaps, DenseFeatures, SparseFeatures};
pub use matching::{GlueMatches, LighterGlue, MnnMatches, RefineModel, mutual_nearest_neighbours};
pub use pipeline::{
    Estimated, ImageSource, Matcher, Matches, Pipeline, PipelineBuilder, PipelineError, Timings,
};
