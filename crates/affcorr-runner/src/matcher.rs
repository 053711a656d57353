//! The matchers as one object: which ONNX models each needs, loading them, and running them on
//! an image pair to matched points with certainties.
//!
//! | [`Matcher`] | models | certainty |
//! |---|---|---|
//! | `"xfeat"` | backbone; mutual nearest neighbours in Rust | cosine similarity |
//! | `"xfeat-star"` | backbone at scales 0.6 and 1.3, MNN, refinement MLP | refinement confidence |
//! | `"xfeat-lighterglue"` | backbone, LighterGlue | match score |
//! | `"disk-lightglue"` | DISK backbone, LightGlue in pieces (adaptive loop) | match score |
//! | `"aliked-lightglue"` | ALIKED backbone + SDDH head, LightGlue in pieces (adaptive loop) | match score |
//! | `"dense"` | a `dense-warp-v1` model (DKM, RoMa), DKM's balanced sampling | the model's |
//!
//! Points are in pixels of the images given (pixel centres at integers); the caller orders,
//! caps and maps them (the pipeline crate).

use std::fmt;
use std::path::PathBuf;
use std::str::FromStr;
use std::time::{Duration, Instant};

use affcorr_image::{GrayImage, RgbImage};

use crate::aliked::AlikedBackbone;
use crate::dense::{DenseMatcher, SamplingOptions, balanced_sample};
use crate::disk::{DiskBackbone, export_hint};
use crate::error::{Result, RunnerError};
use crate::features::{
    Backbone, DenseFeatures, SparseFeatures, dense_split, detect_and_compute, plane, preprocess,
    star_scale_inputs,
};
use crate::lightglue::GluePieceFiles;
use crate::matching::{
    LighterGlue, LighterGlueOptions, RefineModel, mutual_nearest_neighbours,
    normalize_keypoints_lighterglue, refine_matches,
};

/// Which matcher gives the points.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Matcher {
    /// Sparse XFeat keypoints matched by mutual nearest neighbours (`"xfeat"`).
    XFeatMnn,
    /// Semi-dense XFeat*: reliable cells at two scales, mutual nearest neighbours, sub-pixel
    /// refinement (`"xfeat-star"`).
    XFeatStar,
    /// Sparse XFeat keypoints matched by LighterGlue (`"xfeat-lighterglue"`).
    XFeatLighterGlue,
    /// A dense matcher (`dense-warp-v1`: DKM, RoMa) with DKM's balanced sampling (`"dense"`).
    Dense,
    /// DISK keypoints (`features-disk-v1`) matched by LightGlue's adaptive loop
    /// (`"disk-lightglue"`; models made by [`crate::disk::EXPORT_COMMAND`], not shipped).
    DiskLightGlue,
    /// ALIKED keypoints (`features-aliked-v1` + `features-aliked-sddh-v1`) matched by
    /// LightGlue's adaptive loop (`"aliked-lightglue"`; models made by
    /// [`crate::disk::EXPORT_COMMAND`], not shipped).
    AlikedLightGlue,
}

/// A model a matcher runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ModelRole {
    /// The XFeat backbone (`features-backbone-v1`).
    Backbone,
    /// The XFeat* refinement MLP (`features-refine-v1`).
    Refine,
    /// LighterGlue (`matcher-lighterglue-v1`).
    LighterGlue,
    /// A dense matcher (`dense-warp-v1`).
    Dense,
    /// The DISK backbone (`features-disk-v1`).
    DiskBackbone,
    /// DISK's LightGlue: the path `<dir>/disk_lightglue.onnx` names its pieces
    /// `disk_lightglue_{encode,layer,assign}.onnx` beside it ([`GluePieceFiles::beside`]; there
    /// is no one-graph file).
    DiskLightGlue,
    /// The ALIKED backbone (`features-aliked-v1`); its SDDH descriptor head
    /// (`features-aliked-sddh-v1`) is `aliked_sddh.onnx` beside it
    /// ([`crate::aliked::sddh_path`]).
    AlikedBackbone,
    /// ALIKED's LightGlue: `<dir>/aliked_lightglue.onnx` names its pieces
    /// `aliked_lightglue_{encode,layer,assign}.onnx` beside it.
    AlikedLightGlue,
}

impl ModelRole {
    /// Every role.
    pub const ALL: [ModelRole; 8] = [
        Self::Backbone,
        Self::Refine,
        Self::LighterGlue,
        Self::Dense,
        Self::DiskBackbone,
        Self::DiskLightGlue,
        Self::AlikedBackbone,
        Self::AlikedLightGlue,
    ];

    /// The name of the role in APIs (`"backbone"`, `"refine"`, `"lighterglue"`, `"dense"`,
    /// `"disk_backbone"`, `"disk_lightglue"`, `"aliked_backbone"`, `"aliked_lightglue"`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Backbone => "backbone",
            Self::Refine => "refine",
            Self::LighterGlue => "lighterglue",
            Self::Dense => "dense",
            Self::DiskBackbone => "disk_backbone",
            Self::DiskLightGlue => "disk_lightglue",
            Self::AlikedBackbone => "aliked_backbone",
            Self::AlikedLightGlue => "aliked_lightglue",
        }
    }
}

impl Matcher {
    /// Every matcher.
    pub const ALL: [Matcher; 6] = [
        Self::XFeatLighterGlue,
        Self::XFeatMnn,
        Self::XFeatStar,
        Self::Dense,
        Self::DiskLightGlue,
        Self::AlikedLightGlue,
    ];

    /// The name used by the Python API and the CLI.
    pub fn name(self) -> &'static str {
        match self {
            Self::XFeatMnn => "xfeat",
            Self::XFeatStar => "xfeat-star",
            Self::XFeatLighterGlue => "xfeat-lighterglue",
            Self::Dense => "dense",
            Self::DiskLightGlue => "disk-lightglue",
            Self::AlikedLightGlue => "aliked-lightglue",
        }
    }

    /// The models this matcher runs.
    pub fn models(self) -> &'static [ModelRole] {
        match self {
            Self::XFeatMnn => &[ModelRole::Backbone],
            Self::XFeatStar => &[ModelRole::Backbone, ModelRole::Refine],
            Self::XFeatLighterGlue => &[ModelRole::Backbone, ModelRole::LighterGlue],
            Self::Dense => &[ModelRole::Dense],
            Self::DiskLightGlue => &[ModelRole::DiskBackbone, ModelRole::DiskLightGlue],
            Self::AlikedLightGlue => &[ModelRole::AlikedBackbone, ModelRole::AlikedLightGlue],
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
    /// (`"lighterglue"`), `"dense"` (`"dense-warp"`), `"disk-lightglue"` (`"disk"`),
    /// `"aliked-lightglue"` (`"aliked"`), case-insensitive.
    fn from_str(s: &str) -> Result<Self> {
        match s.to_ascii_lowercase().replace('_', "-").as_str() {
            "xfeat" | "xfeat-mnn" => Ok(Self::XFeatMnn),
            "xfeat-star" | "xfeat*" => Ok(Self::XFeatStar),
            "xfeat-lighterglue" | "lighterglue" => Ok(Self::XFeatLighterGlue),
            "dense" | "dense-warp" => Ok(Self::Dense),
            "disk-lightglue" | "disk" => Ok(Self::DiskLightGlue),
            "aliked-lightglue" | "aliked" => Ok(Self::AlikedLightGlue),
            _ => Err(RunnerError::invalid(
                "matcher",
                format!(
                    "unknown matcher {s:?}; expected one of {}",
                    Self::ALL.map(|m| format!("{:?}", m.name())).join(", ")
                ),
            )),
        }
    }
}

/// The model files of a matcher; each must be set for the roles [`Matcher::models`] lists.
#[derive(Debug, Clone, Default)]
pub struct MatcherFiles {
    /// The XFeat backbone.
    pub backbone: Option<PathBuf>,
    /// The XFeat* refinement MLP.
    pub refine: Option<PathBuf>,
    /// LighterGlue.
    pub lighterglue: Option<PathBuf>,
    /// A dense matcher.
    pub dense: Option<PathBuf>,
    /// The DISK backbone.
    pub disk_backbone: Option<PathBuf>,
    /// DISK's LightGlue (`<dir>/disk_lightglue.onnx`: its pieces lie beside that path).
    pub disk_lightglue: Option<PathBuf>,
    /// The ALIKED backbone (its SDDH head `aliked_sddh.onnx` lies beside it).
    pub aliked_backbone: Option<PathBuf>,
    /// ALIKED's LightGlue (`<dir>/aliked_lightglue.onnx`: its pieces lie beside that path).
    pub aliked_lightglue: Option<PathBuf>,
}

impl MatcherFiles {
    /// The file of `role`.
    pub fn get(&self, role: ModelRole) -> Option<&PathBuf> {
        match role {
            ModelRole::Backbone => self.backbone.as_ref(),
            ModelRole::Refine => self.refine.as_ref(),
            ModelRole::LighterGlue => self.lighterglue.as_ref(),
            ModelRole::Dense => self.dense.as_ref(),
            ModelRole::DiskBackbone => self.disk_backbone.as_ref(),
            ModelRole::DiskLightGlue => self.disk_lightglue.as_ref(),
            ModelRole::AlikedBackbone => self.aliked_backbone.as_ref(),
            ModelRole::AlikedLightGlue => self.aliked_lightglue.as_ref(),
        }
    }

    /// Sets the file of `role`.
    pub fn set(&mut self, role: ModelRole, path: PathBuf) {
        let slot = match role {
            ModelRole::Backbone => &mut self.backbone,
            ModelRole::Refine => &mut self.refine,
            ModelRole::LighterGlue => &mut self.lighterglue,
            ModelRole::Dense => &mut self.dense,
            ModelRole::DiskBackbone => &mut self.disk_backbone,
            ModelRole::DiskLightGlue => &mut self.disk_lightglue,
            ModelRole::AlikedBackbone => &mut self.aliked_backbone,
            ModelRole::AlikedLightGlue => &mut self.aliked_lightglue,
        };
        *slot = Some(path);
    }
}

/// Wall time of a matcher's stages on one pair.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct MatcherTimings {
    /// Resizing to the network's multiples of 32 (XFeat matchers).
    pub preprocess: Duration,
    /// The backbone network(s), or the dense matcher (with the resizing to its input).
    pub network: Duration,
    /// Keypoints and descriptors from the backbone's maps (0 for a dense matcher).
    pub detection: Duration,
    /// Mutual nearest neighbours, the refinement model or LighterGlue; a dense matcher's
    /// balanced sampling.
    pub matching: Duration,
}

/// Matched points of one pair, in the pixels of the images given, in the matcher's order.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PointMatches {
    /// Points in image A.
    pub x1: Vec<[f32; 2]>,
    /// Points in image B.
    pub x2: Vec<[f32; 2]>,
    /// The matcher's certainty of each match, higher is better.
    pub certainty: Vec<f32>,
    /// Keypoints (or semi-dense cells) found in image A and in image B; for a dense matcher the
    /// cells of its grid with certainty > 0 that warp into B (the same number twice).
    pub num_keypoints: (usize, usize),
    /// Wall time per stage.
    pub timings: MatcherTimings,
}

/// What a matcher needs of one image to match it against others ([`PointMatcher::extract`]):
/// computed once per image and matched with any number of others
/// ([`PointMatcher::match_features`]), with the results of [`PointMatcher::match_images`].
#[derive(Debug, Clone, PartialEq)]
pub enum FeatureData {
    /// Sparse keypoints and descriptors (`"xfeat"`, `"xfeat-lighterglue"`, `"disk-lightglue"`,
    /// `"aliked-lightglue"`).
    Sparse(SparseFeatures),
    /// The semi-dense cells of XFeat* at both scales (`"xfeat-star"`).
    SemiDense(DenseFeatures),
    /// A dense matcher runs on the pair: the colour image is kept (`"dense"`).
    Colour(RgbImage),
}

/// One image's features ([`PointMatcher::extract`]); cloneable and independent of the matcher
/// object that computed them (any [`PointMatcher`] of the same kind, models and options
/// matches them).
#[derive(Debug, Clone, PartialEq)]
pub struct ImageFeatures {
    /// The matcher that computed them.
    pub matcher: Matcher,
    /// (W, H) of the gray image given.
    pub image_size: (usize, usize),
    /// The features.
    pub data: FeatureData,
    /// Wall time of the extraction (`preprocess`, `network`, `detection`; `matching` 0).
    pub timings: MatcherTimings,
}

impl ImageFeatures {
    /// Keypoints (or semi-dense cells) found; 0 for a dense matcher.
    pub fn len(&self) -> usize {
        match &self.data {
            FeatureData::Sparse(f) => f.len(),
            FeatureData::SemiDense(f) => f.len(),
            FeatureData::Colour(_) => 0,
        }
    }

    /// Whether no keypoint was found (always for a dense matcher).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The keypoints (cells) in the pixels of the image given; empty for a dense matcher.
    pub fn keypoints(&self) -> &[[f32; 2]] {
        match &self.data {
            FeatureData::Sparse(f) => &f.keypoints,
            FeatureData::SemiDense(f) => &f.keypoints,
            FeatureData::Colour(_) => &[],
        }
    }
}

/// A loaded matcher; `Send` and `Sync` (inference runs under each model's mutex).
#[derive(Debug)]
pub struct PointMatcher {
    kind: Matcher,
    backbone: Option<Backbone>,
    disk: Option<DiskBackbone>,
    aliked: Option<AlikedBackbone>,
    refine: Option<RefineModel>,
    lighterglue: Option<LighterGlue>,
    dense: Option<DenseMatcher>,
    max_keypoints: usize,
    seed: u64,
}

fn elapsed(t: &mut Instant) -> Duration {
    let now = Instant::now();
    let d = now - *t;
    *t = now;
    d
}

impl PointMatcher {
    /// Loads and checks the models `kind` needs from `files`, with `threads` ONNX Runtime
    /// intra-op threads each. `max_keypoints`: keypoints (semi-dense cells) per image, default
    /// the backbone's `affcorr.detection.top_k`; for a dense matcher the matches it draws
    /// (required). `seed`: a dense matcher's balanced sampling.
    pub fn load(
        kind: Matcher,
        files: &MatcherFiles,
        max_keypoints: Option<usize>,
        seed: u64,
        threads: usize,
    ) -> Result<Self> {
        if max_keypoints == Some(0) {
            return Err(RunnerError::invalid("max_keypoints", "must be at least 1"));
        }
        let file = |role: ModelRole, what: &'static str| -> Result<&PathBuf> {
            files
                .get(role)
                .ok_or_else(|| RunnerError::invalid(what, "no model file given"))
        };
        let needs = |role| kind.models().contains(&role);
        let dense = if needs(ModelRole::Dense) {
            Some(DenseMatcher::load(
                file(ModelRole::Dense, "dense_matcher")?,
                Some(threads),
            )?)
        } else {
            None
        };
        let backbone = if needs(ModelRole::Backbone) {
            Some(Backbone::load(
                file(ModelRole::Backbone, "backbone_model")?,
                Some(threads),
            )?)
        } else {
            None
        };
        let disk = if needs(ModelRole::DiskBackbone) {
            Some(DiskBackbone::load(
                file(ModelRole::DiskBackbone, "disk_backbone_model")?,
                Some(threads),
            )?)
        } else {
            None
        };
        let aliked = if needs(ModelRole::AlikedBackbone) {
            Some(AlikedBackbone::load(
                file(ModelRole::AlikedBackbone, "aliked_backbone_model")?,
                Some(threads),
            )?)
        } else {
            None
        };
        // (descriptor length, default keypoint budget) of the sparse backbone
        let sparse = match (&backbone, &disk, &aliked) {
            (Some(b), _, _) => Some((b.config().descriptor_dim, b.config().top_k)),
            (None, Some(d), _) => Some((d.config().descriptor_dim, d.config().top_k)),
            (None, None, Some(a)) => Some((a.config().descriptor_dim, a.config().top_k)),
            (None, None, None) => None,
        };
        let dim = sparse.map_or(0, |s| s.0);
        let refine = if needs(ModelRole::Refine) {
            let r = RefineModel::load(file(ModelRole::Refine, "refine_model")?, Some(threads))?;
            check_dim("refine_model", r.source(), r.dim(), dim)?;
            Some(r)
        } else {
            None
        };
        let lighterglue = if needs(ModelRole::LighterGlue) {
            let g = LighterGlue::load(
                file(ModelRole::LighterGlue, "lighterglue_model")?,
                Some(threads),
            )?;
            check_dim("lighterglue_model", g.source(), g.dim(), dim)?;
            Some(g)
        } else if let Some((role, what, hint)) = [
            (
                ModelRole::DiskLightGlue,
                "disk_lightglue_model",
                "DISK + LightGlue",
            ),
            (
                ModelRole::AlikedLightGlue,
                "aliked_lightglue_model",
                "ALIKED + LightGlue",
            ),
        ]
        .into_iter()
        .find(|(role, _, _)| needs(*role))
        {
            // Only the pieces exist (no one-graph LightGlue is exported for DISK or ALIKED);
            // the environment's depth/width overrides apply as for LighterGlue.
            let pieces = GluePieceFiles::beside(file(role, what)?);
            let g =
                LighterGlue::load_pieces(&pieces, Some(threads), &LighterGlueOptions::from_env()?)
                    .map_err(|e| export_hint(e, hint))?;
            check_dim(what, g.source(), g.dim(), dim)?;
            Some(g)
        } else {
            None
        };
        let max_keypoints = match (sparse, max_keypoints) {
            (_, Some(n)) => n,
            (Some((_, top_k)), None) => top_k,
            (None, None) => {
                return Err(RunnerError::invalid(
                    "max_keypoints",
                    "a dense matcher needs the number of matches to draw",
                ));
            }
        };
        Ok(Self {
            kind,
            backbone,
            disk,
            aliked,
            refine,
            lighterglue,
            dense,
            max_keypoints,
            seed,
        })
    }

    /// The matcher.
    pub fn kind(&self) -> Matcher {
        self.kind
    }

    /// Keypoints (or semi-dense cells) per image; for a dense matcher the matches it draws.
    pub fn max_keypoints(&self) -> usize {
        self.max_keypoints
    }

    /// The seed of a dense matcher's sampling.
    pub fn seed(&self) -> u64 {
        self.seed
    }

    /// The score a keypoint needs (above it) in the detector's map: XFeat's heatmap (the
    /// metadata's 0.05), DISK's logits (0) or ALIKED's scores (upstream's 0.2). `None` for the
    /// matchers that keep no keypoints by score (`"xfeat-star"`, `"dense"`). Over the keypoint
    /// budget the highest scores are kept either way, so 0 (DISK's) keeps the top
    /// `max_keypoints` of the local maxima.
    pub fn detection_threshold(&self) -> Option<f32> {
        match self.kind {
            Matcher::XFeatMnn | Matcher::XFeatLighterGlue => Some(self.xfeat().config().threshold),
            Matcher::DiskLightGlue => self.disk.as_ref().map(|d| d.config().threshold),
            Matcher::AlikedLightGlue => self.aliked.as_ref().map(|a| a.config().threshold),
            Matcher::XFeatStar | Matcher::Dense => None,
        }
    }

    /// Keypoints need a score above `threshold` ([`Self::detection_threshold`]) from now on.
    /// An error names `detection_threshold` when it is not finite, or when the matcher keeps
    /// no keypoints by score.
    pub fn set_detection_threshold(&mut self, threshold: f32) -> Result<()> {
        if !threshold.is_finite() {
            return Err(RunnerError::invalid(
                "detection_threshold",
                format!("must be a finite number, got {threshold}"),
            ));
        }
        match (
            self.kind,
            &mut self.backbone,
            &mut self.disk,
            &mut self.aliked,
        ) {
            (Matcher::XFeatMnn | Matcher::XFeatLighterGlue, Some(b), _, _) => {
                b.set_detection_threshold(threshold)
            }
            (Matcher::DiskLightGlue, _, Some(d), _) => d.set_detection_threshold(threshold),
            (Matcher::AlikedLightGlue, _, _, Some(a)) => a.set_detection_threshold(threshold),
            _ => {
                return Err(RunnerError::invalid(
                    "detection_threshold",
                    format!(
                        "the {} matcher keeps no keypoints by score (it applies to \"xfeat\", \
                         \"xfeat-lighterglue\", \"disk-lightglue\" and \"aliked-lightglue\")",
                        self.kind
                    ),
                ));
            }
        }
        Ok(())
    }

    /// The XFeat backbone (`None` for a dense matcher, DISK and ALIKED).
    pub fn backbone(&self) -> Option<&Backbone> {
        self.backbone.as_ref()
    }

    /// The DISK backbone (`Some` for [`Matcher::DiskLightGlue`]).
    pub fn disk_backbone(&self) -> Option<&DiskBackbone> {
        self.disk.as_ref()
    }

    /// The ALIKED backbone (`Some` for [`Matcher::AlikedLightGlue`]).
    pub fn aliked_backbone(&self) -> Option<&AlikedBackbone> {
        self.aliked.as_ref()
    }

    /// The LightGlue of the matcher (LighterGlue for XFeat, LightGlue for DISK and ALIKED; `None` for
    /// the others).
    pub fn glue(&self) -> Option<&LighterGlue> {
        self.lighterglue.as_ref()
    }

    /// The dense matcher (`Some` for [`Matcher::Dense`]).
    pub fn dense_matcher(&self) -> Option<&DenseMatcher> {
        self.dense.as_ref()
    }

    /// Matches of a pair. `colour`: the same images in colour, which a dense matcher takes
    /// (required for it; the others ignore it). The same as [`Self::extract`] of each image,
    /// then [`Self::match_features`].
    pub fn match_images(
        &self,
        a: &GrayImage,
        b: &GrayImage,
        colour: Option<(&RgbImage, &RgbImage)>,
    ) -> Result<PointMatches> {
        if self.kind == Matcher::Dense && colour.is_none() {
            return Err(RunnerError::invalid(
                "colour",
                "a dense matcher needs the colour images",
            ));
        }
        let fa = self.extract(a, colour.map(|c| c.0))?;
        let fb = self.extract(b, colour.map(|c| c.1))?;
        self.match_features(&fa, &fb)
    }

    /// The features of one image (keypoints and descriptors; a dense matcher keeps the colour
    /// image `colour`, which it requires; the others ignore it).
    pub fn extract(&self, img: &GrayImage, colour: Option<&RgbImage>) -> Result<ImageFeatures> {
        let mut timings = MatcherTimings::default();
        let data = match self.kind {
            Matcher::Dense => FeatureData::Colour(
                colour
                    .ok_or_else(|| {
                        RunnerError::invalid("colour", "a dense matcher needs the colour image")
                    })?
                    .clone(),
            ),
            Matcher::XFeatStar => FeatureData::SemiDense(self.dense_features(img, &mut timings)?),
            Matcher::XFeatMnn | Matcher::XFeatLighterGlue => {
                FeatureData::Sparse(self.sparse_features(img, &mut timings)?)
            }
            Matcher::DiskLightGlue => {
                let disk = self
                    .disk
                    .as_ref()
                    .expect("DISK matchers load the DISK backbone");
                let (data, h, w) = plane(img);
                let (f, t) = disk.extract(data, h, w, self.max_keypoints)?;
                timings.preprocess += t.preprocess;
                timings.network += t.network;
                timings.detection += t.detection;
                FeatureData::Sparse(f)
            }
            Matcher::AlikedLightGlue => {
                let aliked = self
                    .aliked
                    .as_ref()
                    .expect("ALIKED matchers load the ALIKED backbone");
                let (data, h, w) = plane(img);
                let (f, t) = aliked.extract(data, h, w, self.max_keypoints)?;
                timings.preprocess += t.preprocess;
                timings.network += t.network;
                timings.detection += t.detection;
                FeatureData::Sparse(f)
            }
        };
        Ok(ImageFeatures {
            matcher: self.kind,
            image_size: (img.width(), img.height()),
            data,
            timings,
        })
    }

    /// Matches of two images' features ([`Self::extract`], by this matcher or one of the same
    /// kind and models); the timings are the extraction's of both plus the matching's, so the
    /// result equals [`Self::match_images`]'s in everything but wall times.
    pub fn match_features(&self, a: &ImageFeatures, b: &ImageFeatures) -> Result<PointMatches> {
        for (f, what) in [(a, "features_a"), (b, "features_b")] {
            if f.matcher != self.kind {
                return Err(RunnerError::invalid(
                    what,
                    format!(
                        "computed by the {} matcher, this one is {}",
                        f.matcher, self.kind
                    ),
                ));
            }
        }
        let mut timings = MatcherTimings::default();
        for f in [a, b] {
            timings.preprocess += f.timings.preprocess;
            timings.network += f.timings.network;
            timings.detection += f.timings.detection;
        }
        let mut m = match (&a.data, &b.data) {
            (FeatureData::Colour(ca), FeatureData::Colour(cb)) => {
                self.match_dense(ca, cb, a.image_size, b.image_size, &mut timings)?
            }
            (FeatureData::SemiDense(fa), FeatureData::SemiDense(fb)) => {
                self.match_star(fa, fb, &mut timings)?
            }
            (FeatureData::Sparse(fa), FeatureData::Sparse(fb)) => {
                self.match_sparse(fa, fb, &mut timings)?
            }
            _ => {
                return Err(RunnerError::invalid(
                    "features_b",
                    "its kind differs from features_a's",
                ));
            }
        };
        m.timings = timings;
        Ok(m)
    }

    /// The XFeat backbone; only called for the XFeat matchers, which load it.
    fn xfeat(&self) -> &Backbone {
        self.backbone
            .as_ref()
            .expect("XFeat matchers load the backbone")
    }

    /// A dense matcher's balanced sample, in pixels of `a`, `b` (the warp's coordinates are
    /// resolution-free, so the colour images need not have their size).
    fn match_dense(
        &self,
        colour_a: &RgbImage,
        colour_b: &RgbImage,
        size_a: (usize, usize),
        size_b: (usize, usize),
        timings: &mut MatcherTimings,
    ) -> Result<PointMatches> {
        let dense = self
            .dense
            .as_ref()
            .expect("dense matchers load the dense model");
        let mut t = Instant::now();
        let warp = dense.run(colour_a, colour_b)?;
        timings.network += elapsed(&mut t);
        let sample = balanced_sample(
            &warp,
            &SamplingOptions {
                num: self.max_keypoints,
                seed: self.seed,
                ..Default::default()
            },
        )?;
        let (x1, x2) = warp.to_pixels(&sample.index, size_a, size_b);
        let to_f32 = |p: Vec<[f64; 2]>| -> Vec<[f32; 2]> {
            p.into_iter().map(|[x, y]| [x as f32, y as f32]).collect()
        };
        let m = PointMatches {
            x1: to_f32(x1),
            x2: to_f32(x2),
            certainty: sample.certainty,
            num_keypoints: (sample.candidates, sample.candidates),
            timings: MatcherTimings::default(),
        };
        timings.matching += elapsed(&mut t);
        Ok(m)
    }

    fn sparse_features(
        &self,
        img: &GrayImage,
        timings: &mut MatcherTimings,
    ) -> Result<SparseFeatures> {
        let mut t = Instant::now();
        let cfg = self.xfeat().config();
        let (data, h, w) = plane(img);
        let input = preprocess(data, h, w, cfg.input_multiple)?;
        timings.preprocess += elapsed(&mut t);
        let maps = self
            .xfeat()
            .run(&input.data, input.height, input.width, true)?;
        timings.network += elapsed(&mut t);
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
        fa: &SparseFeatures,
        fb: &SparseFeatures,
        timings: &mut MatcherTimings,
    ) -> Result<PointMatches> {
        let mut t = Instant::now();
        let num_keypoints = (fa.len(), fb.len());
        let m = match &self.lighterglue {
            None => {
                let m = mutual_nearest_neighbours(&fa.descriptors, &fb.descriptors, fa.dim);
                PointMatches {
                    x1: m.idx1.iter().map(|&i| fa.keypoints[i]).collect(),
                    x2: m.idx2.iter().map(|&j| fb.keypoints[j]).collect(),
                    certainty: m.similarity,
                    num_keypoints,
                    timings: MatcherTimings::default(),
                }
            }
            Some(glue) => {
                let k0 = normalize_keypoints_lighterglue(&fa.keypoints, fa.image_size);
                let k1 = normalize_keypoints_lighterglue(&fb.keypoints, fb.image_size);
                let m = glue.run(&k0, &fa.descriptors, &k1, &fb.descriptors, glue.min_conf())?;
                PointMatches {
                    x1: m.idx0.iter().map(|&i| fa.keypoints[i]).collect(),
                    x2: m.idx1.iter().map(|&j| fb.keypoints[j]).collect(),
                    certainty: m.score,
                    num_keypoints,
                    timings: MatcherTimings::default(),
                }
            }
        };
        timings.matching += elapsed(&mut t);
        Ok(m)
    }

    fn dense_features(
        &self,
        img: &GrayImage,
        timings: &mut MatcherTimings,
    ) -> Result<DenseFeatures> {
        let mut t = Instant::now();
        let cfg = self.xfeat().config();
        let (data, h, w) = plane(img);
        let inputs = star_scale_inputs(data, h, w, &cfg.semidense_scales, cfg.input_multiple)?;
        let split = dense_split(self.max_keypoints, &cfg.semidense_split);
        timings.preprocess += elapsed(&mut t);
        let mut f = DenseFeatures::default();
        for ((s, input), k) in inputs.iter().zip(split) {
            let maps = self
                .xfeat()
                .run(&input.data, input.height, input.width, false)?;
            timings.network += elapsed(&mut t);
            f.push_scale(&maps, k, (input.rh, input.rw), *s);
            timings.detection += elapsed(&mut t);
        }
        Ok(f)
    }

    fn match_star(
        &self,
        fa: &DenseFeatures,
        fb: &DenseFeatures,
        timings: &mut MatcherTimings,
    ) -> Result<PointMatches> {
        let refine = self
            .refine
            .as_ref()
            .expect("XFeat* matchers load the refinement model");
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
        let out = PointMatches {
            x1: keep.iter().map(|&k| x1[k]).collect(),
            x2: keep.iter().map(|&k| fb.keypoints[m.idx2[k]]).collect(),
            certainty: keep.iter().map(|&k| r.confidence[k]).collect(),
            num_keypoints: (fa.len(), fb.len()),
            timings: MatcherTimings::default(),
        };
        timings.matching += elapsed(&mut t);
        Ok(out)
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_unknown_names_list_the_choices() {
        for m in Matcher::ALL {
            assert_eq!(m.name().parse::<Matcher>().unwrap(), m);
            assert_eq!(m.to_string(), m.name());
        }
        assert_eq!("XFeat*".parse::<Matcher>().unwrap(), Matcher::XFeatStar);
        assert_eq!(
            "xfeat_lighterglue".parse::<Matcher>().unwrap(),
            Matcher::XFeatLighterGlue
        );
        let e = "sift".parse::<Matcher>().unwrap_err().to_string();
        assert!(e.starts_with("matcher: unknown matcher \"sift\""), "{e}");
        for m in Matcher::ALL {
            assert!(e.contains(&format!("{:?}", m.name())), "{e}");
        }
    }

    #[test]
    fn every_matcher_needs_its_models() {
        assert_eq!(Matcher::Dense.models(), &[ModelRole::Dense]);
        for m in Matcher::ALL.into_iter().filter(|&m| m != Matcher::Dense) {
            let first = m.models()[0];
            assert!(
                matches!(
                    first,
                    ModelRole::Backbone | ModelRole::DiskBackbone | ModelRole::AlikedBackbone
                ),
                "{m}"
            );
        }
        assert_eq!("DISK".parse::<Matcher>().unwrap(), Matcher::DiskLightGlue);
        assert_eq!(
            "ALIKED".parse::<Matcher>().unwrap(),
            Matcher::AlikedLightGlue
        );
        let files = MatcherFiles::default();
        for m in Matcher::ALL {
            let e = PointMatcher::load(m, &files, Some(10), 0, 1).unwrap_err();
            assert!(e.to_string().contains("no model file given"), "{e}");
        }
    }
}
