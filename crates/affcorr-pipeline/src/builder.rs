//! [`PipelineBuilder`]: which models, which options. Every default is [`crate::defaults`]'s.

use std::path::PathBuf;
use std::sync::OnceLock;

use affcorr_image::AffineRefineOptions;
use affcorr_runner::{
    Matcher, MatcherFiles, ModelRole, PointMatcher, ShapeEstimator, ShapeModelOptions,
};

use crate::defaults;
use crate::error::{PipelineError, Result};
use crate::grow::GrowOptions;
use crate::pipeline::Pipeline;
use crate::views::{ViewMode, ViewOptions};

/// The XFeat backbone's file name in a models directory ([`PipelineBuilder::models_dir`]).
pub const BACKBONE_FILE: &str = "xfeat_backbone.onnx";
/// The XFeat* refinement model's file name.
pub const REFINE_FILE: &str = "xfeat_refine.onnx";
/// LighterGlue's file name.
pub const LIGHTERGLUE_FILE: &str = "xfeat_lighterglue.onnx";
/// The DISK backbone's file name (not shipped: `affcorr_runner::disk::EXPORT_COMMAND` makes
/// it).
pub const DISK_BACKBONE_FILE: &str = "disk_backbone.onnx";
/// DISK's LightGlue: the name its pieces `disk_lightglue_{encode,layer,assign}.onnx` derive
/// from (no file of this name exists).
pub const DISK_LIGHTGLUE_FILE: &str = "disk_lightglue.onnx";
/// The ALIKED backbone's file name (not shipped: `affcorr_runner::disk::EXPORT_COMMAND` makes
/// it); its SDDH descriptor head `aliked_sddh.onnx` lies beside it.
pub const ALIKED_BACKBONE_FILE: &str = "aliked_backbone.onnx";
/// ALIKED's LightGlue: the name its pieces `aliked_lightglue_{encode,layer,assign}.onnx` derive
/// from (no file of this name exists).
pub const ALIKED_LIGHTGLUE_FILE: &str = "aliked_lightglue.onnx";
/// The shape network's file name.
pub const SHAPE_FILE: &str = "shape.onnx";
/// A dense matcher's file name in a models directory (none is shipped: DKM/RoMa exports are
/// the user's, docs/matchers.md).
pub const DENSE_FILE: &str = "dense.onnx";

/// The file name of a matcher model in a models directory.
pub fn model_file(role: ModelRole) -> &'static str {
    match role {
        ModelRole::Backbone => BACKBONE_FILE,
        ModelRole::Refine => REFINE_FILE,
        ModelRole::LighterGlue => LIGHTERGLUE_FILE,
        ModelRole::Dense => DENSE_FILE,
        ModelRole::DiskBackbone => DISK_BACKBONE_FILE,
        ModelRole::DiskLightGlue => DISK_LIGHTGLUE_FILE,
        ModelRole::AlikedBackbone => ALIKED_BACKBONE_FILE,
        ModelRole::AlikedLightGlue => ALIKED_LIGHTGLUE_FILE,
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
    disk_backbone: Option<PathBuf>,
    disk_lightglue: Option<PathBuf>,
    aliked_backbone: Option<PathBuf>,
    aliked_lightglue: Option<PathBuf>,
    shape: Option<PathBuf>,
    max_keypoints: Option<usize>,
    detection_threshold: Option<f32>,
    max_matches: Option<usize>,
    max_side: Option<usize>,
    threads: Option<usize>,
    shape_batch_size: usize,
    affine_refinement: Option<AffineRefineOptions>,
    drop_unreliable: bool,
    exif_orientation: bool,
    views: ViewOptions,
    guided_matching: Option<GrowOptions>,
    seed: u64,
}

impl Default for PipelineBuilder {
    fn default() -> Self {
        Self {
            matcher: defaults::MATCHER,
            models_dir: None,
            backbone: None,
            refine: None,
            lighterglue: None,
            dense: None,
            disk_backbone: None,
            disk_lightglue: None,
            aliked_backbone: None,
            aliked_lightglue: None,
            shape: None,
            max_keypoints: None,
            detection_threshold: None,
            max_matches: None,
            max_side: None,
            threads: None,
            shape_batch_size: affcorr_runner::shape::DEFAULT_BATCH_SIZE,
            affine_refinement: defaults::REFINE_AFFINE.then(AffineRefineOptions::default),
            drop_unreliable: false,
            exif_orientation: defaults::EXIF_ORIENTATION,
            views: ViewOptions::default(),
            guided_matching: defaults::GUIDED_MATCHING.then(GrowOptions::default),
            seed: defaults::SEED,
        }
    }
}

impl PipelineBuilder {
    /// The matcher (default [`defaults::MATCHER`]).
    pub fn matcher(mut self, matcher: Matcher) -> Self {
        self.matcher = matcher;
        self
    }

    /// A directory holding `xfeat_backbone.onnx`, `xfeat_refine.onnx`, `xfeat_lighterglue.onnx`
    /// and `shape.onnx` (in the repository: `python/affcorr/models`), and for
    /// [`Matcher::DiskLightGlue`] `disk_backbone.onnx` and `disk_lightglue_*.onnx`, for
    /// [`Matcher::AlikedLightGlue`] `aliked_backbone.onnx`, `aliked_sddh.onnx` and
    /// `aliked_lightglue_*.onnx` (exported there at setup time, docs/matchers.md). Paths set one by one
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

    /// The DISK backbone (`features-disk-v1`; only [`Matcher::DiskLightGlue`]).
    pub fn disk_backbone_model(mut self, path: impl Into<PathBuf>) -> Self {
        self.disk_backbone = Some(path.into());
        self
    }

    /// DISK's LightGlue, as `<dir>/disk_lightglue.onnx`: its three pieces
    /// `disk_lightglue_{encode,layer,assign}.onnx` must lie beside that path (only
    /// [`Matcher::DiskLightGlue`]).
    pub fn disk_lightglue_model(mut self, path: impl Into<PathBuf>) -> Self {
        self.disk_lightglue = Some(path.into());
        self
    }

    /// The ALIKED backbone (`features-aliked-v1`; only [`Matcher::AlikedLightGlue`]); its
    /// SDDH head `aliked_sddh.onnx` must lie beside it.
    pub fn aliked_backbone_model(mut self, path: impl Into<PathBuf>) -> Self {
        self.aliked_backbone = Some(path.into());
        self
    }

    /// ALIKED's LightGlue, as `<dir>/aliked_lightglue.onnx`: its three pieces
    /// `aliked_lightglue_{encode,layer,assign}.onnx` must lie beside that path (only
    /// [`Matcher::AlikedLightGlue`]).
    pub fn aliked_lightglue_model(mut self, path: impl Into<PathBuf>) -> Self {
        self.aliked_lightglue = Some(path.into());
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
    /// over its two scales). Default: [`defaults::MAX_KEYPOINTS`]. LighterGlue's cost grows
    /// with the square of this.
    pub fn max_keypoints(mut self, n: usize) -> Self {
        self.max_keypoints = Some(n);
        self
    }

    /// The score a keypoint needs in the detector's map
    /// ([`PointMatcher::detection_threshold`]; the sparse matchers only). Default:
    /// [`defaults::detection_threshold`] of the matcher, else the model's metadata.
    pub fn detection_threshold(mut self, threshold: f32) -> Self {
        self.detection_threshold = Some(threshold);
        self
    }

    /// Keep at most this many matches, the most certain. Default: all. A dense matcher draws
    /// this many (default [`defaults::DENSE_MATCHES`]).
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
    /// ([`affcorr_image::affine_refine`]; it moves x2 too with `move_points`); `None` turns it
    /// off. Default ([`defaults::REFINE_AFFINE`]): on, with [`AffineRefineOptions::default`];
    /// its effect on affine accuracy and relative pose is measured in
    /// benches/results/eval/affine.md and benches/results/pose_refine.md.
    pub fn affine_refinement(mut self, options: Option<AffineRefineOptions>) -> Self {
        self.affine_refinement = options;
        self
    }

    /// Whether to drop the ACs whose A is not reliable (`Matches::reliable`, see
    /// [`affcorr_image::confidence`]) before they are returned or estimated from. Default
    /// false: every match comes back, each with its `affine_confidence` and `reliable` flag.
    pub fn drop_unreliable(mut self, drop: bool) -> Self {
        self.drop_unreliable = drop;
        self
    }

    /// Whether image files are matched upright, as their EXIF orientation shows them
    /// (module `affcorr_image::orientation`). The ACs and keypoints are in the files' stored
    /// pixels either way (as COLMAP and PIL read them); only the images the matcher sees
    /// differ. Decoded images (arrays) are taken as they are. Default
    /// ([`defaults::EXIF_ORIENTATION`]): on.
    pub fn exif_orientation(mut self, upright: bool) -> Self {
        self.exif_orientation = upright;
        self
    }

    /// The view cascade for pairs the plain matcher cannot solve (rotation, zoom, tilt; see
    /// [`crate::views`]). Default: [`ViewOptions::default`], mode [`defaults::VIEWS`]. Dense
    /// matchers never use it.
    pub fn views(mut self, options: ViewOptions) -> Self {
        self.views = options;
        self
    }

    /// Guided re-matching: more matches around the verified ones, predicted by their ACs and
    /// fitted by the affine refinement (see [`crate::grow`]); `None` turns it off. Default:
    /// [`defaults::GUIDED_MATCHING`]. Sparse matchers only. Off, it still runs (with
    /// [`GrowOptions::default`]) after a view cascade that kept a pass verified with a weak
    /// yield (see [`crate::views`]).
    pub fn guided_matching(mut self, options: Option<GrowOptions>) -> Self {
        self.guided_matching = options;
        self
    }

    fn path(&self, explicit: &Option<PathBuf>, file: &str, what: &'static str) -> Result<PathBuf> {
        explicit
            .clone()
            .or_else(|| self.models_dir.as_ref().map(|d| d.join(file)))
            .ok_or_else(|| {
                PipelineError::invalid(
                    what,
                    format!("no path given: call models_dir() or {what}() on the builder"),
                )
            })
    }

    /// The file of `role`, from its own setter or the models directory.
    fn role_path(&self, role: ModelRole) -> Result<PathBuf> {
        let (explicit, what) = match role {
            ModelRole::Backbone => (&self.backbone, "backbone_model"),
            ModelRole::Refine => (&self.refine, "refine_model"),
            ModelRole::LighterGlue => (&self.lighterglue, "lighterglue_model"),
            ModelRole::Dense => (&self.dense, "dense_matcher"),
            ModelRole::DiskBackbone => (&self.disk_backbone, "disk_backbone_model"),
            ModelRole::DiskLightGlue => (&self.disk_lightglue, "disk_lightglue_model"),
            ModelRole::AlikedBackbone => (&self.aliked_backbone, "aliked_backbone_model"),
            ModelRole::AlikedLightGlue => (&self.aliked_lightglue, "aliked_lightglue_model"),
        };
        self.path(explicit, model_file(role), what)
    }

    /// The matcher whose features screen the view cascade's groups in place of the pipeline's
    /// own ([`defaults::view_screen`]), at the same keypoint budget: loaded when the cascade is
    /// on and `view_screen` names one. Its model (XFeat's backbone) is looked up like the
    /// matcher's ([`Self::backbone_model`] or [`Self::models_dir`]); where there is none, the
    /// cascade screens with the matcher's own features, and says so in the log.
    fn load_screener(&self, max_keypoints: usize, threads: usize) -> Result<Option<PointMatcher>> {
        let Some(kind) = defaults::view_screen(self.matcher) else {
            return Ok(None);
        };
        if self.views.mode == ViewMode::Off {
            return Ok(None);
        }
        let mut files = MatcherFiles::default();
        for &role in kind.models() {
            let path = self.role_path(role).ok().filter(|p| p.is_file());
            let Some(path) = path else {
                tracing::warn!(
                    model = model_file(role),
                    "no {} model for the view cascade's screen: the {} matcher's own features \
                     screen the views",
                    kind,
                    self.matcher
                );
                return Ok(None);
            };
            files.set(role, path);
        }
        let mut screener = PointMatcher::load(kind, &files, Some(max_keypoints), 0, threads)?;
        if let Some(t) = defaults::detection_threshold(kind) {
            screener.set_detection_threshold(t)?;
        }
        Ok(Some(screener))
    }

    /// Loads and checks the models the matcher needs, and the shape network.
    pub fn build(self) -> Result<Pipeline> {
        let config = self.clone();
        if self.max_keypoints == Some(0) {
            return Err(PipelineError::invalid(
                "max_keypoints",
                "must be at least 1",
            ));
        }
        if self.max_matches == Some(0) {
            return Err(PipelineError::invalid("max_matches", "must be at least 1"));
        }
        if let Some(s) = self.max_side
            && s < 32
        {
            return Err(PipelineError::invalid(
                "max_side",
                format!("{s} is below the matcher's minimum of 32 pixels"),
            ));
        }
        self.views.validate()?;
        if let Some(g) = &self.guided_matching {
            g.validate()?;
        }
        let threads = affcorr_runner::resolve_threads(self.threads)?;
        let mut files = MatcherFiles::default();
        for &role in self.matcher.models() {
            files.set(role, self.role_path(role)?);
        }
        // A dense matcher draws `max_matches` and keeps them all.
        let (max_keypoints, max_matches) = match self.matcher {
            Matcher::Dense => {
                let n = self.max_matches.unwrap_or(defaults::DENSE_MATCHES);
                (n, Some(n))
            }
            _ => (
                self.max_keypoints.unwrap_or(defaults::MAX_KEYPOINTS),
                self.max_matches,
            ),
        };
        let mut matcher = PointMatcher::load(
            self.matcher,
            &files,
            Some(max_keypoints),
            self.seed,
            threads,
        )?;
        if let Some(t) = self
            .detection_threshold
            .or(defaults::detection_threshold(self.matcher))
        {
            matcher.set_detection_threshold(t)?;
        }
        let screener = self.load_screener(max_keypoints, threads)?;
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
                PipelineError::invalid("threads", format!("cannot start the thread pool: {e}"))
            })?;
        Ok(Pipeline {
            matcher,
            screener,
            shape,
            affine_refinement: self.affine_refinement.clone(),
            drop_unreliable: self.drop_unreliable,
            exif_orientation: self.exif_orientation,
            views: self.views.clone(),
            guided_matching: self.guided_matching.clone(),
            max_matches,
            max_side: self.max_side,
            threads,
            pool,
            config,
            workers: OnceLock::new(),
        })
    }
}
