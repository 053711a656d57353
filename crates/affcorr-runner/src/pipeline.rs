//! Images in, affine correspondences and geometry out: the matcher (XFeat, XFeat*,
//! XFeat + LighterGlue, or a dense `dense-warp-v1` model such as DKM or RoMa) gives the points,
//! the shape network the affine maps at them, and affcorr-ransac the homography or relative
//! pose (issue 6).
//!
//! ```no_run
//! use affcorr_runner::{init_ort, Matcher, Pipeline};
//! use affcorr_ransac::EstimatorOptions;
//!
//! init_ort(None)?; // ORT_DYLIB_PATH
//! let pipeline = Pipeline::builder()
//!     .matcher(Matcher::XFeatMnn)
//!     .models_dir("python/affcorr/models") // xfeat_*.onnx and shape.onnx
//!     .max_keypoints(4096)
//!     .threads(2)
//!     .build()?;
//! let m = pipeline.match_pair("data/graffiti/graf1.png", "data/graffiti/graf3.png")?;
//! println!("{} ACs; {}", m.corrs.len(), m.timings);
//! let mut opts = EstimatorOptions::default();
//! opts.ransac.threshold = 3.0;
//! let h = pipeline.homography("data/graffiti/graf1.png", "data/graffiti/graf3.png", &opts)?;
//! println!("H = {}, {} inliers", h.estimate.model, h.estimate.num_inliers);
//! # Ok::<(), affcorr_runner::PipelineError>(())
//! ```
//!
//! # What `match_pair` does
//!
//! 1. **decode**: file paths are decoded to grayscale ([`GrayImage`]); an image whose longer
//!    side exceeds [`PipelineBuilder::max_side`] is downscaled (antialiased triangle filter) by
//!    s = max_side / max(W, H) to its *working resolution*; the matcher's inputs are resized to
//!    multiples of 32 ([`crate::features::preprocess`]).
//! 2. **matcher**: the backbone network (once per image; twice for XFeat*, at scales 0.6 and
//!    1.3), or the dense matcher on the pair (colour images resized to its input size,
//!    [`crate::dense`]).
//! 3. **detection**: sparse keypoints and descriptors, or the semi-dense cells of XFeat* (none
//!    for a dense matcher).
//! 4. **matching**: mutual nearest neighbours (certainty = cosine similarity), then the XFeat*
//!    refinement model (certainty = its confidence), or LighterGlue (certainty = its match
//!    score); for a dense matcher DKM's balanced sampling of
//!    [`PipelineBuilder::max_matches`] (default [`DEFAULT_DENSE_MATCHES`]) cells from its
//!    certainty map, seeded by [`PipelineBuilder::seed`] (certainty = the model's), mapped to
//!    pixels of the working images by x = W/2 · (u + 1) − 0.5. Matches are sorted by decreasing
//!    certainty (stable) and cut to [`PipelineBuilder::max_matches`].
//! 5. **patches** and **shape net**: 32×32 patches around the matched points in the working
//!    images, the shape network's A at them ([`crate::estimator`]).
//! 6. The ACs are mapped back to the original pixels (pixel centres at integers, image edges
//!    aligned): x = (x_work + 0.5)/s − 0.5 per axis, and A = diag(1/s_B) · A_work · diag(s_A)
//!    (A = ∂x2/∂x1, docs/design.md §2).
//!
//! [`Pipeline::homography`] and [`Pipeline::relative_pose`] add **ransac**: affcorr-ransac's
//! estimators on the ACs (2-AC samples unless the options say otherwise). With PROSAC sampling
//! and no `quality`, the certainties are the quality.
//!
//! Every stage's wall time is in [`Timings`].

use std::borrow::Cow;
use std::fmt;
use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::sync::OnceLock;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use affcorr_geom::Mat3;
use affcorr_geom::camera::Intrinsics;
use affcorr_ransac::problems::relpose::PoseModel;
use affcorr_ransac::{
    Correspondences, Estimate, EstimatorOptions, RansacError, SamplerKind, estimate_homography,
    estimate_relative_pose,
};

use crate::affine_refine::{AffineRefineOptions, refine_affine};
use crate::dense::{DenseMatcher, RgbImage, SamplingOptions, balanced_sample};
use crate::error::{Result, RunnerError};
use crate::estimator::ShapeEstimator;
use crate::features::{
    Backbone, DenseFeatures, SparseFeatures, dense_split, detect_and_compute, plane, preprocess,
    star_scale_inputs,
};
use crate::image::{GrayImage, gray_from_dynamic, open_dynamic};
use crate::matching::{
    LighterGlue, RefineModel, mutual_nearest_neighbours, normalize_keypoints_lighterglue,
    refine_matches,
};
use crate::patches::extract_named;
use crate::shape::ShapeModelOptions;

/// File names of the models in a models directory ([`PipelineBuilder::models_dir`]).
pub const BACKBONE_FILE: &str = "xfeat_backbone.onnx";
/// The XFeat* refinement model's file name.
pub const REFINE_FILE: &str = "xfeat_refine.onnx";
/// LighterGlue's file name.
pub const LIGHTERGLUE_FILE: &str = "xfeat_lighterglue.onnx";
/// The shape network's file name.
pub const SHAPE_FILE: &str = "shape.onnx";
/// A dense matcher's file name in a models directory (none is shipped: DKM/RoMa exports are
/// the user's, docs/matchers.md).
pub const DENSE_FILE: &str = "dense.onnx";
/// Matches a dense matcher draws when [`PipelineBuilder::max_matches`] is not set. DKM draws
/// 10 000; each costs a shape-network evaluation (~0.6 ms on 2 cores), so fewer by default.
pub const DEFAULT_DENSE_MATCHES: usize = 2000;

/// Which matcher gives the points.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Matcher {
    /// Sparse XFeat keypoints matched by mutual nearest neighbours (`"xfeat"`).
    #[default]
    XFeatMnn,
    /// Semi-dense XFeat*: reliable cells at two scales, mutual nearest neighbours, sub-pixel
    /// refinement (`"xfeat-star"`).
    XFeatStar,
    /// Sparse XFeat keypoints matched by LighterGlue (`"xfeat-lighterglue"`).
    XFeatLighterGlue,
    /// A dense matcher (`dense-warp-v1`: DKM, RoMa) with DKM's balanced sampling (`"dense"`);
    /// see [`PipelineBuilder::dense_matcher`].
    Dense,
}

impl Matcher {
    /// Every matcher.
    pub const ALL: [Matcher; 4] = [
        Self::XFeatMnn,
        Self::XFeatStar,
        Self::XFeatLighterGlue,
        Self::Dense,
    ];

    /// The name used by the Python API and the CLI.
    pub fn name(self) -> &'static str {
        match self {
            Self::XFeatMnn => "xfeat",
            Self::XFeatStar => "xfeat-star",
            Self::XFeatLighterGlue => "xfeat-lighterglue",
            Self::Dense => "dense",
        }
    }
}

impl fmt::Display for Matcher {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Matcher {
    type Err = RunnerError;

    /// `"xfeat"` (also `"xfeat-mnn"`), `"xfeat-star"` (`"xfeat*"`), `"xfeat-lighterglue"`
    /// (`"lighterglue"`), `"dense"` (`"dense-warp"`), case-insensitive.
    fn from_str(s: &str) -> Result<Self> {
        match s.to_ascii_lowercase().replace('_', "-").as_str() {
            "xfeat" | "xfeat-mnn" => Ok(Self::XFeatMnn),
            "xfeat-star" | "xfeat*" => Ok(Self::XFeatStar),
            "xfeat-lighterglue" | "lighterglue" => Ok(Self::XFeatLighterGlue),
            "dense" | "dense-warp" => Ok(Self::Dense),
            _ => Err(RunnerError::invalid(
                "matcher",
                format!(
                    "unknown matcher {s:?}; expected \"xfeat\", \"xfeat-star\", \"xfeat-lighterglue\" or \"dense\""
                ),
            )),
        }
    }
}

/// What can go wrong in a pipeline: the runner (models, images, inputs) or the estimation.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PipelineError {
    /// Loading, decoding, inference.
    #[error(transparent)]
    Runner(#[from] RunnerError),
    /// Robust estimation (e.g. fewer matches than a minimal sample).
    #[error(transparent)]
    Ransac(#[from] RansacError),
}

/// Wall time of each stage of one pair (see the module docs for what each covers).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Timings {
    /// Decoding, downscaling to `max_side`, resizing to the network's multiples of 32.
    pub decode: Duration,
    /// The backbone network(s), or the dense matcher (with the resizing to its input).
    pub matcher: Duration,
    /// Keypoints and descriptors from the backbone's maps (0 for a dense matcher).
    pub detection: Duration,
    /// Mutual nearest neighbours, the refinement model or LighterGlue; a dense matcher's
    /// balanced sampling.
    pub matching: Duration,
    /// Cutting the 32×32 patches.
    pub patches: Duration,
    /// The shape network and the synthesis of A.
    pub shape_net: Duration,
    /// The affine Lucas–Kanade refinement of the ACs (0 unless enabled,
    /// [`PipelineBuilder::affine_refinement`]).
    pub affine_refine: Duration,
    /// Robust estimation (0 for `match_pair`).
    pub ransac: Duration,
    /// The whole call.
    pub total: Duration,
}

impl Timings {
    /// (name, duration) of each stage in order, then `"total"`.
    pub fn stages(&self) -> [(&'static str, Duration); 9] {
        [
            ("decode", self.decode),
            ("matcher", self.matcher),
            ("detection", self.detection),
            ("matching", self.matching),
            ("patches", self.patches),
            ("shape_net", self.shape_net),
            ("affine_refine", self.affine_refine),
            ("ransac", self.ransac),
            ("total", self.total),
        ]
    }
}

impl fmt::Display for Timings {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let parts: Vec<String> = self
            .stages()
            .iter()
            .map(|(n, d)| format!("{n} {:.1} ms", d.as_secs_f64() * 1e3))
            .collect();
        f.write_str(&parts.join(", "))
    }
}

/// The ACs of one image pair.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Matches {
    /// `[x1, y1, x2, y2, a11, a12, a21, a22]` in the original images' pixels, A = ∂x2/∂x1,
    /// sorted by decreasing certainty.
    pub corrs: Vec<[f64; 8]>,
    /// The matcher's certainty of each match (MNN: cosine similarity; XFeat*: refinement
    /// confidence; LighterGlue: match score; dense: the certainty map), higher is better.
    pub certainty: Vec<f64>,
    /// Keypoints (or semi-dense cells) found in image A and in image B; for a dense matcher the
    /// cells of its grid with certainty > 0 that warp into B (the same number twice).
    pub num_keypoints: (usize, usize),
    /// Wall time per stage.
    pub timings: Timings,
}

impl Matches {
    /// The number of ACs.
    pub fn len(&self) -> usize {
        self.corrs.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.corrs.is_empty()
    }
}

/// Matches and the model estimated from them.
#[derive(Debug, Clone)]
pub struct Estimated<M> {
    /// The ACs the model was estimated from (their `timings.ransac` is set).
    pub matches: Matches,
    /// The robust estimate; `inliers` indexes `matches.corrs`.
    pub estimate: Estimate<M>,
}

/// An image argument: decoded already, or a file to decode (PNG, JPEG).
#[derive(Debug, Clone, Copy)]
pub enum ImageSource<'a> {
    /// A decoded image.
    Image(&'a GrayImage),
    /// A decoded colour image: a dense matcher sees its colour, everything else its BT.601
    /// luma.
    Rgb(&'a RgbImage),
    /// A file path.
    Path(&'a Path),
}

impl<'a> From<&'a RgbImage> for ImageSource<'a> {
    fn from(img: &'a RgbImage) -> Self {
        Self::Rgb(img)
    }
}

impl<'a> From<&'a GrayImage> for ImageSource<'a> {
    fn from(img: &'a GrayImage) -> Self {
        Self::Image(img)
    }
}

impl<'a> From<&'a Path> for ImageSource<'a> {
    fn from(p: &'a Path) -> Self {
        Self::Path(p)
    }
}

impl<'a> From<&'a PathBuf> for ImageSource<'a> {
    fn from(p: &'a PathBuf) -> Self {
        Self::Path(p)
    }
}

impl<'a> From<&'a str> for ImageSource<'a> {
    fn from(p: &'a str) -> Self {
        Self::Path(Path::new(p))
    }
}

impl<'a> ImageSource<'a> {
    fn load(self) -> Result<Cow<'a, GrayImage>> {
        match self {
            Self::Image(img) => Ok(Cow::Borrowed(img)),
            Self::Rgb(img) => img.to_gray().map(Cow::Owned),
            Self::Path(p) => GrayImage::open(p).map(Cow::Owned),
        }
    }

    /// The gray image and the colour one a dense matcher takes, decoded once (a gray image
    /// gives R = G = B).
    fn load_with_colour(self) -> Result<(Cow<'a, GrayImage>, RgbImage)> {
        match self {
            Self::Image(img) => Ok((Cow::Borrowed(img), RgbImage::from_gray(img))),
            Self::Rgb(img) => Ok((Cow::Owned(img.to_gray()?), img.clone())),
            Self::Path(p) => {
                let (img, name) = open_dynamic(p)?;
                let gray = gray_from_dynamic(&img, &name)?;
                Ok((Cow::Owned(gray), RgbImage::from_dynamic(&img)))
            }
        }
    }
}

/// Builds a [`Pipeline`]; see each method for its default.
#[derive(Debug, Clone)]
pub struct PipelineBuilder {
    matcher: Matcher,
    models_dir: Option<PathBuf>,
    backbone: Option<PathBuf>,
    refine: Option<PathBuf>,
    lighterglue: Option<PathBuf>,
    dense: Option<PathBuf>,
    shape: Option<PathBuf>,
    max_keypoints: Option<usize>,
    max_matches: Option<usize>,
    max_side: Option<usize>,
    threads: Option<usize>,
    shape_batch_size: usize,
    affine_refinement: Option<AffineRefineOptions>,
    seed: u64,
}

impl Default for PipelineBuilder {
    fn default() -> Self {
        Self {
            matcher: Matcher::default(),
            models_dir: None,
            backbone: None,
            refine: None,
            lighterglue: None,
            dense: None,
            shape: None,
            max_keypoints: None,
            max_matches: None,
            max_side: None,
            threads: None,
            shape_batch_size: crate::shape::DEFAULT_BATCH_SIZE,
            affine_refinement: Some(AffineRefineOptions::default()),
            seed: 0,
        }
    }
}

impl PipelineBuilder {
    /// The matcher (default [`Matcher::XFeatMnn`]).
    pub fn matcher(mut self, matcher: Matcher) -> Self {
        self.matcher = matcher;
        self
    }

    /// A directory holding `xfeat_backbone.onnx`, `xfeat_refine.onnx`, `xfeat_lighterglue.onnx`
    /// and `shape.onnx` (in the repository: `python/affcorr/models`). Paths set one by one
    /// take precedence. There is no default: the Rust API takes explicit paths.
    pub fn models_dir(mut self, dir: impl Into<PathBuf>) -> Self {
        self.models_dir = Some(dir.into());
        self
    }

    /// The backbone model (`features-backbone-v1`).
    pub fn backbone_model(mut self, path: impl Into<PathBuf>) -> Self {
        self.backbone = Some(path.into());
        self
    }

    /// The XFeat* refinement model (`features-refine-v1`; only [`Matcher::XFeatStar`]).
    pub fn refine_model(mut self, path: impl Into<PathBuf>) -> Self {
        self.refine = Some(path.into());
        self
    }

    /// The LighterGlue model (`matcher-lighterglue-v1`; only [`Matcher::XFeatLighterGlue`]).
    pub fn lighterglue_model(mut self, path: impl Into<PathBuf>) -> Self {
        self.lighterglue = Some(path.into());
        self
    }

    /// A dense matcher (`dense-warp-v1`, e.g. a DKM or RoMa export; docs/matchers.md), and
    /// selects [`Matcher::Dense`]. No XFeat model is loaded then. Without this call a dense
    /// pipeline looks for `dense.onnx` in [`Self::models_dir`].
    pub fn dense_matcher(mut self, path: impl Into<PathBuf>) -> Self {
        self.dense = Some(path.into());
        self.matcher = Matcher::Dense;
        self
    }

    /// Seed of a dense matcher's balanced sampling (default 0): a seed gives the same matches
    /// on every run and thread count.
    pub fn seed(mut self, seed: u64) -> Self {
        self.seed = seed;
        self
    }

    /// The shape network (`shape-v1`).
    pub fn shape_model(mut self, path: impl Into<PathBuf>) -> Self {
        self.shape = Some(path.into());
        self
    }

    /// Keypoints per image (sparse) or semi-dense cells per image (XFeat*, split 20 % / 80 %
    /// over its two scales). Default: the backbone's `affcorr.detection.top_k` (4096).
    /// LighterGlue's cost grows with the square of this.
    pub fn max_keypoints(mut self, n: usize) -> Self {
        self.max_keypoints = Some(n);
        self
    }

    /// Keep at most this many matches, the most certain. Default: all. A dense matcher draws
    /// this many (default [`DEFAULT_DENSE_MATCHES`]).
    pub fn max_matches(mut self, n: usize) -> Self {
        self.max_matches = Some(n);
        self
    }

    /// Downscale images whose longer side exceeds this many pixels before matching (the
    /// resolution). Default: none (full resolution).
    pub fn max_side(mut self, n: usize) -> Self {
        self.max_side = Some(n);
        self
    }

    /// Threads for ONNX Runtime (intra-op, per model) and for the Rust stages (a rayon pool of
    /// this size). Default: every core.
    pub fn threads(mut self, n: usize) -> Self {
        self.threads = Some(n);
        self
    }

    /// Patch pairs per shape-network run (default 512).
    pub fn shape_batch_size(mut self, n: usize) -> Self {
        self.shape_batch_size = n;
        self
    }

    /// Refine the network's ACs against the working images by affine Lucas–Kanade
    /// ([`crate::affine_refine`]; it moves x2 too with `move_points`); `None` turns it off.
    /// Default: on, with [`AffineRefineOptions::default`]. At XFeat+LighterGlue's matches on
    /// 31 held-out real pairs it takes the median ‖A − A_gt‖_F from ~0.2 to ~0.01
    /// (benches/results/eval/affine.md) and relative pose's AUC@5 from 52 to 59 %
    /// (benches/results/pose_refine.md), at a few times the shape network's cost.
    pub fn affine_refinement(mut self, options: Option<AffineRefineOptions>) -> Self {
        self.affine_refinement = options;
        self
    }

    fn path(&self, explicit: &Option<PathBuf>, file: &str, what: &'static str) -> Result<PathBuf> {
        explicit
            .clone()
            .or_else(|| self.models_dir.as_ref().map(|d| d.join(file)))
            .ok_or_else(|| {
                RunnerError::invalid(
                    what,
                    format!("no path given: call models_dir() or {what}() on the builder"),
                )
            })
    }

    /// Loads and checks the models the matcher needs, and the shape network.
    pub fn build(self) -> Result<Pipeline> {
        let config = self.clone();
        if self.max_keypoints == Some(0) {
            return Err(RunnerError::invalid("max_keypoints", "must be at least 1"));
        }
        if self.max_matches == Some(0) {
            return Err(RunnerError::invalid("max_matches", "must be at least 1"));
        }
        if let Some(s) = self.max_side
            && s < 32
        {
            return Err(RunnerError::invalid(
                "max_side",
                format!("{s} is below the matcher's minimum of 32 pixels"),
            ));
        }
        let threads = crate::contract::resolve_threads(self.threads)?;
        let dense = match self.matcher {
            Matcher::Dense => Some(DenseMatcher::load(
                self.path(&self.dense, DENSE_FILE, "dense_matcher")?,
                Some(threads),
            )?),
            _ => None,
        };
        let backbone = match self.matcher {
            Matcher::Dense => None,
            _ => Some(Backbone::load(
                self.path(&self.backbone, BACKBONE_FILE, "backbone_model")?,
                Some(threads),
            )?),
        };
        let dim = backbone.as_ref().map_or(0, |b| b.config().descriptor_dim);
        let refine = match self.matcher {
            Matcher::XFeatStar => {
                let r = RefineModel::load(
                    self.path(&self.refine, REFINE_FILE, "refine_model")?,
                    Some(threads),
                )?;
                check_dim("refine_model", r.source(), r.dim(), dim)?;
                Some(r)
            }
            _ => None,
        };
        let lighterglue = match self.matcher {
            Matcher::XFeatLighterGlue => {
                let g = LighterGlue::load(
                    self.path(&self.lighterglue, LIGHTERGLUE_FILE, "lighterglue_model")?,
                    Some(threads),
                )?;
                check_dim("lighterglue_model", g.source(), g.dim(), dim)?;
                Some(g)
            }
            _ => None,
        };
        let shape = ShapeEstimator::load(
            self.path(&self.shape, SHAPE_FILE, "shape_model")?,
            &ShapeModelOptions {
                threads: Some(threads),
                batch_size: self.shape_batch_size,
            },
        )?;
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .thread_name(|i| format!("affcorr-pipeline-{i}"))
            .build()
            .map_err(|e| {
                RunnerError::invalid("threads", format!("cannot start the thread pool: {e}"))
            })?;
        let (max_keypoints, max_matches) = match &backbone {
            Some(b) => (
                self.max_keypoints.unwrap_or(b.config().top_k),
                self.max_matches,
            ),
            None => {
                let n = self.max_matches.unwrap_or(DEFAULT_DENSE_MATCHES);
                (n, Some(n))
            }
        };
        Ok(Pipeline {
            matcher: self.matcher,
            backbone,
            refine,
            lighterglue,
            dense,
            shape,
            affine_refinement: self.affine_refinement.clone(),
            max_keypoints,
            max_matches,
            seed: self.seed,
            max_side: self.max_side,
            threads,
            pool,
            config,
            workers: OnceLock::new(),
        })
    }
}

/// The most pixels the XFeat matchers take at the working resolution. Their memory grows with
/// the pixels, ≈160 MB per megapixel (benches/results/bad_input_scale.md: 12 MP 2.0 GB, 48 MP
/// 7.9 GB), so 64 MP is ≈10 GB; larger images would end in an out-of-memory abort instead of
/// an error.
pub const MAX_WORKING_PIXELS: usize = 64_000_000;

fn check_working_size(img: &GrayImage, what: &'static str) -> Result<()> {
    let (w, h) = (img.width(), img.height());
    if w.saturating_mul(h) > MAX_WORKING_PIXELS {
        return Err(RunnerError::invalid(
            what,
            format!(
                "{w}×{h} pixels is over the matcher's limit of {} MP at the working resolution \
                 (≈160 MB per megapixel): set max_side (e.g. 4096)",
                MAX_WORKING_PIXELS / 1_000_000
            ),
        ));
    }
    Ok(())
}

fn check_dim(what: &'static str, source: &str, got: usize, want: usize) -> Result<()> {
    if got == want {
        Ok(())
    } else {
        Err(RunnerError::invalid(
            what,
            format!("{source} takes {got}-dimensional descriptors, the backbone gives {want}"),
        ))
    }
}

/// Matcher, shape network and estimators in one object; `Send` and `Sync` (inference runs
/// under each model's mutex).
#[derive(Debug)]
pub struct Pipeline {
    matcher: Matcher,
    /// The XFeat backbone (every matcher but the dense one).
    backbone: Option<Backbone>,
    refine: Option<RefineModel>,
    lighterglue: Option<LighterGlue>,
    dense: Option<DenseMatcher>,
    shape: ShapeEstimator,
    affine_refinement: Option<AffineRefineOptions>,
    max_keypoints: usize,
    max_matches: Option<usize>,
    seed: u64,
    max_side: Option<usize>,
    threads: usize,
    pool: rayon::ThreadPool,
    /// What the pipeline was built from (for the single-threaded workers of `match_pairs`).
    config: PipelineBuilder,
    /// `threads` single-threaded copies for `match_pairs`, built on its first call (or the
    /// error that prevented it, as text: then batches run one pair after the other).
    workers: OnceLock<std::result::Result<Vec<Pipeline>, String>>,
}

/// Matched points in the working images, with certainties.
struct RawMatches {
    x1: Vec<[f32; 2]>,
    x2: Vec<[f32; 2]>,
    certainty: Vec<f32>,
    num_keypoints: (usize, usize),
}

fn elapsed(t: &mut Instant) -> Duration {
    let now = Instant::now();
    let d = now - *t;
    *t = now;
    d
}

impl Pipeline {
    /// A builder with the defaults.
    pub fn builder() -> PipelineBuilder {
        PipelineBuilder::default()
    }

    /// The matcher.
    pub fn matcher(&self) -> Matcher {
        self.matcher
    }

    /// Keypoints (or semi-dense cells) per image; for a dense matcher the matches it draws.
    pub fn max_keypoints(&self) -> usize {
        self.max_keypoints
    }

    /// The cap on matches, if any.
    pub fn max_matches(&self) -> Option<usize> {
        self.max_matches
    }

    /// The working resolution's longest side, if capped.
    pub fn max_side(&self) -> Option<usize> {
        self.max_side
    }

    /// ONNX Runtime intra-op threads and rayon threads.
    pub fn threads(&self) -> usize {
        self.threads
    }

    /// The XFeat backbone (`None` for a dense matcher).
    pub fn backbone(&self) -> Option<&Backbone> {
        self.backbone.as_ref()
    }

    /// The dense matcher (`Some` for [`Matcher::Dense`]).
    pub fn dense_matcher(&self) -> Option<&DenseMatcher> {
        self.dense.as_ref()
    }

    /// The seed of the dense matcher's sampling.
    pub fn seed(&self) -> u64 {
        self.seed
    }

    /// The shape network.
    pub fn shape_estimator(&self) -> &ShapeEstimator {
        &self.shape
    }

    /// The ACs of an image pair (see the module docs).
    pub fn match_pair<'a>(
        &self,
        image_a: impl Into<ImageSource<'a>>,
        image_b: impl Into<ImageSource<'a>>,
    ) -> Result<Matches> {
        let (a, b) = (image_a.into(), image_b.into());
        self.pool.install(|| self.match_inner(a, b))
    }

    /// [`Self::match_pair`] over many pairs; one result per pair, in order.
    ///
    /// With `threads` > 1 the pairs run in parallel, one per thread, each on a single-threaded
    /// copy of the pipeline (ONNX Runtime and rayon with one thread; the copies are loaded on
    /// the first call and kept). On 2 cores shared with other work this gave 12–20 % more pairs
    /// per second than pairs one after the other with every thread per pair
    /// (benches/results/pipeline_timing.md). The results equal [`Self::match_pair`]'s.
    pub fn match_pairs<'a, A, B>(
        &self,
        pairs: impl IntoIterator<Item = (A, B)>,
    ) -> Vec<Result<Matches>>
    where
        A: Into<ImageSource<'a>>,
        B: Into<ImageSource<'a>>,
    {
        let pairs: Vec<(ImageSource<'a>, ImageSource<'a>)> = pairs
            .into_iter()
            .map(|(a, b)| (a.into(), b.into()))
            .collect();
        let workers = if self.threads > 1 && pairs.len() > 1 {
            match self.workers.get_or_init(|| {
                (0..self.threads)
                    .map(|_| self.config.clone().threads(1).build())
                    .collect::<Result<Vec<_>>>()
                    .map_err(|e| e.to_string())
            }) {
                Ok(w) => w.as_slice(),
                Err(_) => &[],
            }
        } else {
            &[]
        };
        if workers.is_empty() {
            return pairs
                .into_iter()
                .map(|(a, b)| self.match_pair(a, b))
                .collect();
        }
        let next = AtomicUsize::new(0);
        let mut results: Vec<Option<Result<Matches>>> = (0..pairs.len()).map(|_| None).collect();
        std::thread::scope(|scope| {
            let handles: Vec<_> = workers
                .iter()
                .take(pairs.len())
                .map(|w| {
                    let (next, pairs) = (&next, &pairs);
                    scope.spawn(move || {
                        let mut done = Vec::new();
                        loop {
                            let i = next.fetch_add(1, Ordering::Relaxed);
                            let Some(&(a, b)) = pairs.get(i) else { break };
                            done.push((i, w.match_pair(a, b)));
                        }
                        done
                    })
                })
                .collect();
            for h in handles {
                for (i, r) in h.join().expect("a match_pairs worker panicked") {
                    results[i] = Some(r);
                }
            }
        });
        results
            .into_iter()
            .map(|r| r.expect("every pair is matched"))
            .collect()
    }

    /// The homography p2 ~ H p1 (original pixels) of an image pair: [`Self::match_pair`], then
    /// [`estimate_homography`] on the ACs with `options`.
    pub fn homography<'a>(
        &self,
        image_a: impl Into<ImageSource<'a>>,
        image_b: impl Into<ImageSource<'a>>,
        options: &EstimatorOptions,
    ) -> std::result::Result<Estimated<Mat3>, PipelineError> {
        let matches = self.match_pair(image_a, image_b)?;
        self.estimate(matches, options, estimate_homography)
    }

    /// The relative pose X2 = R X1 + t of two calibrated images: [`Self::match_pair`], then
    /// [`estimate_relative_pose`] with the intrinsics `k1`, `k2` (of the original images).
    pub fn relative_pose<'a>(
        &self,
        image_a: impl Into<ImageSource<'a>>,
        image_b: impl Into<ImageSource<'a>>,
        k1: &Intrinsics,
        k2: &Intrinsics,
        options: &EstimatorOptions,
    ) -> std::result::Result<Estimated<PoseModel>, PipelineError> {
        let matches = self.match_pair(image_a, image_b)?;
        self.estimate(matches, options, |d, o| {
            estimate_relative_pose(d, k1, k2, o)
        })
    }

    /// Runs a robust estimator on `matches` (timed into `timings.ransac` and `.total`).
    pub fn estimate<M>(
        &self,
        mut matches: Matches,
        options: &EstimatorOptions,
        estimator: impl Fn(&Correspondences, &EstimatorOptions) -> affcorr_ransac::Result<Estimate<M>>,
    ) -> std::result::Result<Estimated<M>, PipelineError> {
        let t = Instant::now();
        let data = Correspondences::from_ac_rows(&matches.corrs)?;
        let estimate = if options.sampler == SamplerKind::Prosac && options.quality.is_none() {
            let mut o = options.clone();
            o.quality = Some(matches.certainty.clone());
            estimator(&data, &o)?
        } else {
            estimator(&data, options)?
        };
        let d = t.elapsed();
        matches.timings.ransac += d;
        matches.timings.total += d;
        Ok(Estimated { matches, estimate })
    }

    fn match_inner(&self, a: ImageSource<'_>, b: ImageSource<'_>) -> Result<Matches> {
        let start = Instant::now();
        let mut t = start;
        let mut timings = Timings::default();
        let (img_a, img_b, colour) = if self.dense.is_some() {
            let (ga, ca) = a.load_with_colour().map_err(|e| name_image(e, "image_a"))?;
            let (gb, cb) = b.load_with_colour().map_err(|e| name_image(e, "image_b"))?;
            (ga, gb, Some((ca, cb)))
        } else {
            let ga = a.load().map_err(|e| name_image(e, "image_a"))?;
            let gb = b.load().map_err(|e| name_image(e, "image_b"))?;
            (ga, gb, None)
        };
        let (work_a, sa) = self.limit_side(&img_a);
        let (work_b, sb) = self.limit_side(&img_b);
        if self.matcher != Matcher::Dense {
            check_working_size(&work_a, "image_a")?;
            check_working_size(&work_b, "image_b")?;
        }
        timings.decode += elapsed(&mut t);

        let raw = match (self.matcher, &colour) {
            (Matcher::Dense, Some((ca, cb))) => {
                self.match_dense(ca, cb, &work_a, &work_b, &mut timings)?
            }
            (Matcher::XFeatStar, _) => self.match_star(&work_a, &work_b, &mut timings)?,
            _ => self.match_sparse(&work_a, &work_b, &mut timings)?,
        };
        let mut t = Instant::now();

        // Most certain first (stable), then the cap.
        let mut order: Vec<usize> = (0..raw.x1.len()).collect();
        order.sort_by(|&i, &j| {
            raw.certainty[j]
                .partial_cmp(&raw.certainty[i])
                .unwrap_or(std::cmp::Ordering::Equal)
        });
        if let Some(cap) = self.max_matches {
            order.truncate(cap);
        }
        let x1: Vec<[f64; 2]> = order.iter().map(|&i| raw.x1[i].map(f64::from)).collect();
        let x2: Vec<[f64; 2]> = order.iter().map(|&i| raw.x2[i].map(f64::from)).collect();
        let certainty: Vec<f64> = order.iter().map(|&i| raw.certainty[i] as f64).collect();
        timings.matching += elapsed(&mut t);

        let patch_a = extract_named(&work_a, &x1, "x1")?;
        let patch_b = extract_named(&work_b, &x2, "x2")?;
        timings.patches += elapsed(&mut t);

        let prediction = self.shape.model().predict(&patch_a, &patch_b)?;
        let mut work: Vec<[f64; 8]> = prediction
            .affine()?
            .iter()
            .zip(x1.iter().zip(&x2))
            .map(|(m, (p, q))| [p[0], p[1], q[0], q[1], m[0], m[1], m[2], m[3]])
            .collect();
        timings.shape_net += elapsed(&mut t);
        if let Some(options) = &self.affine_refinement {
            work = refine_affine(&work_a, &work_b, &work, options)?.corrs;
            timings.affine_refine += elapsed(&mut t);
        }
        let corrs = work
            .iter()
            .map(|&[p0, p1, q0, q1, m0, m1, m2, m3]| {
                let (p, q, m) = ([p0, p1], [q0, q1], [m0, m1, m2, m3]);
                // Pixel centres at integers, image edges aligned (as the resize samples):
                // x = (x_work + 0.5) / s − 0.5; A = diag(1/s_B) · A_work · diag(s_A).
                let ([ax, ay], [bx, by]) = (sa, sb);
                [
                    (p[0] + 0.5) / ax - 0.5,
                    (p[1] + 0.5) / ay - 0.5,
                    (q[0] + 0.5) / bx - 0.5,
                    (q[1] + 0.5) / by - 0.5,
                    m[0] * ax / bx,
                    m[1] * ay / bx,
                    m[2] * ax / by,
                    m[3] * ay / by,
                ]
            })
            .collect();
        timings.total = start.elapsed();
        Ok(Matches {
            corrs,
            certainty,
            num_keypoints: raw.num_keypoints,
            timings,
        })
    }

    /// The image at the working resolution and the factors (s_x, s_y) = (W′/W, H′/H) of the
    /// downscale (1 when the image is not downscaled).
    fn limit_side<'i>(&self, img: &'i GrayImage) -> (Cow<'i, GrayImage>, [f64; 2]) {
        let side = img.width().max(img.height());
        match self.max_side {
            Some(m) if side > m => {
                let s = m as f64 / side as f64;
                let w = ((img.width() as f64 * s).round() as usize).clamp(1, m);
                let h = ((img.height() as f64 * s).round() as usize).clamp(1, m);
                let buf = image::ImageBuffer::<image::Luma<f32>, Vec<f32>>::from_raw(
                    img.width() as u32,
                    img.height() as u32,
                    img.data().to_vec(),
                )
                .expect("sizes match");
                // Triangle filter: antialiased (its support widens by the downscale factor);
                // output pixel i reads the input around (i + 0.5)·W/W′ − 0.5.
                let small = image::imageops::resize(
                    &buf,
                    w as u32,
                    h as u32,
                    image::imageops::FilterType::Triangle,
                );
                let small = GrayImage::new(w, h, small.into_raw())
                    .expect("the resize of a finite image is finite");
                let factors = [
                    w as f64 / img.width() as f64,
                    h as f64 / img.height() as f64,
                ];
                (Cow::Owned(small), factors)
            }
            _ => (Cow::Borrowed(img), [1.0, 1.0]),
        }
    }

    /// The XFeat backbone; only called for the XFeat matchers, which load it.
    fn xfeat(&self) -> &Backbone {
        self.backbone
            .as_ref()
            .expect("XFeat pipelines load the backbone")
    }

    /// A dense matcher's balanced sample, in pixels of the working images `a`, `b` (the warp's
    /// coordinates are resolution-free, so the colour images need not be downscaled).
    fn match_dense(
        &self,
        colour_a: &RgbImage,
        colour_b: &RgbImage,
        a: &GrayImage,
        b: &GrayImage,
        timings: &mut Timings,
    ) -> Result<RawMatches> {
        let dense = self
            .dense
            .as_ref()
            .expect("dense pipelines load the dense matcher");
        let mut t = Instant::now();
        let warp = dense.run(colour_a, colour_b)?;
        timings.matcher += elapsed(&mut t);
        let sample = balanced_sample(
            &warp,
            &SamplingOptions {
                num: self.max_keypoints,
                seed: self.seed,
                ..Default::default()
            },
        )?;
        let (x1, x2) = warp.to_pixels(
            &sample.index,
            (a.width(), a.height()),
            (b.width(), b.height()),
        );
        let to_f32 = |p: Vec<[f64; 2]>| -> Vec<[f32; 2]> {
            p.into_iter().map(|[x, y]| [x as f32, y as f32]).collect()
        };
        let raw = RawMatches {
            x1: to_f32(x1),
            x2: to_f32(x2),
            certainty: sample.certainty,
            num_keypoints: (sample.candidates, sample.candidates),
        };
        timings.matching += elapsed(&mut t);
        Ok(raw)
    }

    fn sparse_features(&self, img: &GrayImage, timings: &mut Timings) -> Result<SparseFeatures> {
        let mut t = Instant::now();
        let cfg = self.xfeat().config();
        let (data, h, w) = plane(img);
        let input = preprocess(data, h, w, cfg.input_multiple)?;
        timings.decode += elapsed(&mut t);
        let maps = self
            .xfeat()
            .run(&input.data, input.height, input.width, true)?;
        timings.matcher += elapsed(&mut t);
        let f = detect_and_compute(
            &maps,
            self.max_keypoints,
            cfg.threshold,
            cfg.nms_size,
            (input.rh, input.rw),
            (w, h),
        );
        timings.detection += elapsed(&mut t);
        Ok(f)
    }

    fn match_sparse(
        &self,
        a: &GrayImage,
        b: &GrayImage,
        timings: &mut Timings,
    ) -> Result<RawMatches> {
        let fa = self.sparse_features(a, timings)?;
        let fb = self.sparse_features(b, timings)?;
        let mut t = Instant::now();
        let num_keypoints = (fa.len(), fb.len());
        let raw = match &self.lighterglue {
            None => {
                let m = mutual_nearest_neighbours(&fa.descriptors, &fb.descriptors, fa.dim);
                RawMatches {
                    x1: m.idx1.iter().map(|&i| fa.keypoints[i]).collect(),
                    x2: m.idx2.iter().map(|&j| fb.keypoints[j]).collect(),
                    certainty: m.similarity,
                    num_keypoints,
                }
            }
            Some(glue) => {
                let k0 = normalize_keypoints_lighterglue(&fa.keypoints, fa.image_size);
                let k1 = normalize_keypoints_lighterglue(&fb.keypoints, fb.image_size);
                let m = glue.run(&k0, &fa.descriptors, &k1, &fb.descriptors, glue.min_conf())?;
                RawMatches {
                    x1: m.idx0.iter().map(|&i| fa.keypoints[i]).collect(),
                    x2: m.idx1.iter().map(|&j| fb.keypoints[j]).collect(),
                    certainty: m.score,
                    num_keypoints,
                }
            }
        };
        timings.matching += elapsed(&mut t);
        Ok(raw)
    }

    fn dense_features(&self, img: &GrayImage, timings: &mut Timings) -> Result<DenseFeatures> {
        let mut t = Instant::now();
        let cfg = self.xfeat().config();
        let (data, h, w) = plane(img);
        let inputs = star_scale_inputs(data, h, w, &cfg.semidense_scales, cfg.input_multiple)?;
        let split = dense_split(self.max_keypoints, &cfg.semidense_split);
        timings.decode += elapsed(&mut t);
        let mut f = DenseFeatures::default();
        for ((s, input), k) in inputs.iter().zip(split) {
            let maps = self
                .xfeat()
                .run(&input.data, input.height, input.width, false)?;
            timings.matcher += elapsed(&mut t);
            f.push_scale(&maps, k, (input.rh, input.rw), *s);
            timings.detection += elapsed(&mut t);
        }
        Ok(f)
    }

    fn match_star(
        &self,
        a: &GrayImage,
        b: &GrayImage,
        timings: &mut Timings,
    ) -> Result<RawMatches> {
        let refine = self
            .refine
            .as_ref()
            .expect("XFeat* pipelines load the refinement model");
        let fa = self.dense_features(a, timings)?;
        let fb = self.dense_features(b, timings)?;
        let mut t = Instant::now();
        let d = fa.dim;
        let m = mutual_nearest_neighbours(&fa.descriptors, &fb.descriptors, d);
        let mut pair = vec![0f32; m.len() * 2 * d];
        for (row, (&i, &j)) in pair.chunks_mut(2 * d).zip(m.idx1.iter().zip(&m.idx2)) {
            row[..d].copy_from_slice(&fa.descriptors[i * d..(i + 1) * d]);
            row[d..].copy_from_slice(&fb.descriptors[j * d..(j + 1) * d]);
        }
        let r = refine.run(&pair)?;
        let mut x1: Vec<[f32; 2]> = m.idx1.iter().map(|&i| fa.keypoints[i]).collect();
        let inv: Vec<f32> = m.idx1.iter().map(|&i| fa.inv_scale[i]).collect();
        let keep = refine_matches(&mut x1, &inv, &r, refine.min_confidence());
        let raw = RawMatches {
            x1: keep.iter().map(|&k| x1[k]).collect(),
            x2: keep.iter().map(|&k| fb.keypoints[m.idx2[k]]).collect(),
            certainty: keep.iter().map(|&k| r.confidence[k]).collect(),
            num_keypoints: (fa.len(), fb.len()),
        };
        timings.matching += elapsed(&mut t);
        Ok(raw)
    }
}

/// Prefixes image errors with the argument they came from.
fn name_image(e: RunnerError, what: &'static str) -> RunnerError {
    match e {
        RunnerError::ImageOpen { .. } | RunnerError::ImageDecode { .. } => e,
        RunnerError::ImageBuffer { reason } => RunnerError::invalid(what, reason),
        other => other,
    }
}
