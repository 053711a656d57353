//! ONNX runner of affcorr's networks (docs/design.md §6): the matchers and the shape network.
//! Images, patches and the affine refinement are `affcorr-image`'s; the end-to-end pipeline
//! (with robust estimation) is `affcorr-pipeline`'s.
//!
//! - [`ort_env`]: loads ONNX Runtime at run time (`ORT_DYLIB_PATH` or [`init_ort`]); one
//!   environment per process.
//! - [`shape`]: the shape network's ONNX contract (`shape-v1`), batched inference and the
//!   softmax-mean decoding of its orientation and scale logits.
//! - [`estimator`]: the ACs A = S_AB · R(O_AB) · A′(A″) of matched points.
//! - [`features`]: the XFeat backbone (`features-backbone-v1`) and sparse / semi-dense feature
//!   extraction from its maps (the specification is `python/affcorr/export/xfeat_reference.py`).
//! - [`aliked`]: the ALIKED backbone (`features-aliked-v1`), ALIKED's keypoint detection (DKD)
//!   and its SDDH descriptor head (the specification is `python/affcorr/export/aliked.py`).
//! - [`disk`]: the DISK backbone (`features-disk-v1`) and DISK's detection and descriptor
//!   sampling (the specification is `python/affcorr/export/lightglue_models.py`).
//! - [`matching`]: mutual nearest neighbours, the XFeat* refinement model and LighterGlue.
//! - [`lightglue`]: LightGlue's adaptive layer loop (early exit, point pruning) over the
//!   network exported in pieces; generic over sizes and layers.
//! - [`dense`]: dense matchers (DKM, RoMa) under `dense-warp-v1` and DKM's balanced sampling
//!   of matches from their certainty map.
//! - [`contract`]: the matcher models' ONNX contracts (docs/matchers.md), checked on loading.
//! - [`matcher`]: [`Matcher`] names, the models each needs, and [`PointMatcher`], which loads
//!   them and matches an image pair to points with certainties.
//! - [`error`]: [`RunnerError`], which names what went wrong.
//!
//! Conventions are docs/design.md §2's: pixels (x, y) with x right and y down, pixel centres at
//! integer coordinates, ACs `[x1, y1, x2, y2, a11, a12, a21, a22]` with A = ∂x2/∂x1, radians.
//!
//! # Example
//!
//! ```no_run
//! use affcorr_image::GrayImage;
//! use affcorr_runner::{ShapeEstimator, ShapeModelOptions, init_ort};
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

pub mod aliked;
pub mod contract;
pub mod dense;
pub mod disk;
pub mod error;
pub mod estimator;
pub mod features;
pub mod lightglue;
pub mod matcher;
pub mod matching;
pub mod ort_env;
pub mod shape;

pub use error::{Result, RunnerError};
pub use estimator::{ShapeEstimate, ShapeEstimator};
pub use ort_env::{init_ort, ort_library};
pub use shape::{ShapeBins, ShapeModel, ShapeModelOptions, ShapeOutputs, ShapePrediction};

pub use aliked::{AlikedBackbone, AlikedConfig};
pub use contract::resolve_threads;
pub use dense::{DenseMatcher, DenseSample, DenseWarp, SamplingOptions, balanced_sample};
pub use disk::{DiskBackbone, DiskConfig};
pub use features::{Backbone, BackboneConfig, BackboneMaps, DenseFeatures, SparseFeatures};
pub use lightglue::{AdaptiveGlue, GlueConfig, GlueDims, GluePieceFiles, GlueTrace};
pub use matcher::{
    FeatureData, ImageFeatures, Matcher, MatcherFiles, MatcherTimings, ModelRole, PointMatcher,
    PointMatches,
};
pub use matching::{
    GlueMatches, GlueMode, LighterGlue, LighterGlueOptions, MnnMatches, RefineModel,
    mutual_nearest_neighbours,
};
