//! The pipeline's one set of defaults, used by the Rust API, the Python API
//! (`affcorr.PIPELINE_DEFAULTS`) and the CLI alike.
//!
//! Each value is chosen by a measurement; docs/pipeline.md gives the table and the command
//! (`python -m affcorr_bench.defaults`) behind it. The low-level estimators
//! (`affcorr_ransac::estimate_*` on the caller's own correspondences) keep their generic
//! default threshold, [`affcorr_ransac::RansacOptions`]'s; the pipeline's thresholds suit the
//! matchers it runs.

use affcorr_ransac::EstimatorOptions;
use affcorr_runner::Matcher;

use crate::views::ViewMode;

/// The default matcher: XFeat keypoints matched by LighterGlue (the most correct matches of
/// the shipped matchers).
pub const MATCHER: Matcher = Matcher::XFeatLighterGlue;

/// Keypoints per image (semi-dense cells for XFeat*). 1024: the fastest configuration within
/// 5 points of the best on every family of benches/results/defaults.md (2048 was, before the
/// view cascade solved the extreme tilts at 1024), and as successful as 2048 at about half
/// its time against SIFT + PoseLib in benches/results/speed_tiers.md. LighterGlue's cost
/// grows with the square of this number.
pub const MAX_KEYPOINTS: usize = 1024;

/// The score ALIKED's keypoints need: none (0, the scores are sigmoids), so that the top
/// `max_keypoints` local maxima are kept, as DISK's are and as upstream runs ALIKED with
/// `detection_threshold=0`. Upstream's default 0.2 left texture-poor rooms a few dozen
/// matches (docs/matchers.md, benches/results/matchers_rooms.md).
pub const ALIKED_DETECTION_THRESHOLD: f32 = 0.0;

/// The pipeline's detection threshold for `matcher` ([`crate::PipelineBuilder::detection_threshold`]):
/// [`ALIKED_DETECTION_THRESHOLD`] for ALIKED, `None` (the model's metadata) for the others.
pub fn detection_threshold(matcher: Matcher) -> Option<f32> {
    (matcher == Matcher::AlikedLightGlue).then_some(ALIKED_DETECTION_THRESHOLD)
}

/// The median match certainty below which a verified plain pass is still rivalled by the
/// rotated views ([`crate::views`]): 0.35 for XFeat + LighterGlue and DISK + LightGlue, 0.3
/// for ALIKED + LightGlue (their match probabilities; chosen from their matches' certainty on
/// solved and wrongly registered pairs, docs/pipeline.md "Rotated pairs"), `None` (not used)
/// for the others, whose certainties are other quantities (XFeat's cosine similarity,
/// XFeat*'s confidence, a dense warp's certainty).
pub fn rival_certainty(matcher: Matcher) -> Option<f64> {
    match matcher {
        Matcher::XFeatLighterGlue => Some(XFEAT_LIGHTERGLUE_RIVAL_CERTAINTY),
        Matcher::AlikedLightGlue => Some(ALIKED_LIGHTGLUE_RIVAL_CERTAINTY),
        Matcher::DiskLightGlue => Some(DISK_LIGHTGLUE_RIVAL_CERTAINTY),
        _ => None,
    }
}

/// The share of a plain pass's matches that must verify for it to verify strongly
/// ([`crate::views`]; under it the rotated views rival the pass): [`crate::views::WEAK_RATIO`],
/// and [`XFEAT_MNN_WEAK_RATIO`] for XFeat's mutual nearest neighbours.
pub fn weak_ratio(matcher: Matcher) -> f64 {
    match matcher {
        Matcher::XFeatMnn => XFEAT_MNN_WEAK_RATIO,
        _ => crate::views::WEAK_RATIO,
    }
}

/// [`weak_ratio`] of XFeat (mutual nearest neighbours), whose correct plain passes keep many
/// outliers: at [`crate::views::WEAK_RATIO`] a third of the rendered scenes' correct passes
/// and most of the stereo and board views' verified weakly and paid for the rotated rivals.
/// At 0.4 the easy pairs cost their plain pass and the rotated sets keep their pairs but one
/// (docs/pipeline.md, "XFeat's mutual nearest neighbours verify strongly at 0.4").
pub const XFEAT_MNN_WEAK_RATIO: f64 = 0.4;

/// [`rival_certainty`] of XFeat + LighterGlue.
pub const XFEAT_LIGHTERGLUE_RIVAL_CERTAINTY: f64 = 0.35;

/// [`rival_certainty`] of ALIKED + LightGlue.
pub const ALIKED_LIGHTGLUE_RIVAL_CERTAINTY: f64 = 0.3;

/// [`rival_certainty`] of DISK + LightGlue.
pub const DISK_LIGHTGLUE_RIVAL_CERTAINTY: f64 = 0.35;

/// The matcher whose features screen the view cascade's groups ([`crate::views::screen`]) when
/// it is not the pipeline's own: XFeat's keypoints (mutual nearest neighbours) for DISK +
/// LightGlue and ALIKED + LightGlue, and for XFeat*. The slow matchers' extractions cost 10–30×
/// XFeat's, and a screened group extracts every warped image of it (seven rotations of B) where
/// only the views that run need the matcher's features. XFeat*'s semi-dense cells have no
/// keypoint descriptors to screen with: its groups were matched in their order, unranked.
/// (docs/pipeline.md, "Screening with XFeat".) `None`: the matcher's own features (the sparse
/// XFeat matchers), or none (a dense matcher, which runs no cascade).
pub fn view_screen(matcher: Matcher) -> Option<Matcher> {
    match matcher {
        Matcher::DiskLightGlue | Matcher::AlikedLightGlue | Matcher::XFeatStar => {
            Some(Matcher::XFeatMnn)
        }
        _ => None,
    }
}

/// Matches a dense matcher draws when `max_matches` is not set. DKM draws 10 000; each costs a
/// shape-network evaluation and a refinement, so fewer by default.
pub const DENSE_MATCHES: usize = 2000;

/// Whether the network's ACs are refined against the images by affine Lucas–Kanade.
pub const REFINE_AFFINE: bool = true;

/// Whether image files are matched as their EXIF orientation shows them (upright), with every
/// coordinate still in their stored pixels (`affcorr_image::orientation`): a photograph taken
/// in portrait beside one in landscape is then matched without a turn.
pub const EXIF_ORIENTATION: bool = true;

/// The view cascade: synthetic views only when the plain pair fails verification.
pub const VIEWS: ViewMode = ViewMode::Auto;

/// The view cascade's verification: at least this many matches whose point and A agree with
/// one fundamental matrix...
pub const VIEW_MIN_INLIERS: usize = 12;

/// ... making up at least this share of the matches.
pub const VIEW_MIN_INLIER_RATIO: f64 = 0.1;

/// The view cascade starts no new view after this many times the plain pass's work (counted,
/// not timed: `views::WorkMeter`): what a pair that no view solves costs at most (about
/// ASIFT's cost over SIFT; the counted work runs 1–2× short of the time it takes, column
/// "max cost" against "max work" of benches/results/views.md). Every pair a view solved in
/// benches/results/views.md and benches/results/eval/extreme.md needed less.
pub const VIEW_RELATIVE_BUDGET: Option<f64> = Some(30.0);

/// Guided re-matching (more matches around the verified ones, `crate::grow`) of every pair. Off,
/// the view cascade still grows a pass it keeps with a weak yield (`crate::views`).
pub const GUIDED_MATCHING: bool = false;

/// The seed of a dense matcher's balanced sampling and of the robust estimators.
pub const SEED: u64 = 0;

/// Inlier threshold of [`crate::Pipeline::homography`]: transfer error, pixels.
pub const HOMOGRAPHY_THRESHOLD: f64 = 1.0;

/// Inlier threshold of [`crate::Pipeline::fundamental`]: Sampson distance, pixels.
pub const FUNDAMENTAL_THRESHOLD: f64 = 1.0;

/// Inlier threshold of [`crate::Pipeline::relative_pose`]: Sampson distance, pixels.
pub const POSE_THRESHOLD: f64 = 1.0;

/// What the pipeline estimates.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Geometry {
    /// A homography p2 ~ H p1.
    Homography,
    /// A fundamental matrix p2ᵀ F p1 = 0.
    Fundamental,
    /// A calibrated relative pose X2 = R X1 + t.
    RelativePose,
}

impl Geometry {
    /// The pipeline's default inlier threshold for this geometry, pixels.
    pub fn default_threshold(self) -> f64 {
        match self {
            Self::Homography => HOMOGRAPHY_THRESHOLD,
            Self::Fundamental => FUNDAMENTAL_THRESHOLD,
            Self::RelativePose => POSE_THRESHOLD,
        }
    }

    /// The estimator options the pipeline uses by default: [`EstimatorOptions::default`] with
    /// this geometry's threshold and [`SEED`].
    pub fn default_options(self) -> EstimatorOptions {
        let mut o = EstimatorOptions::default();
        o.ransac.threshold = self.default_threshold();
        o.ransac.seed = SEED;
        o
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_options_carry_the_thresholds_and_nothing_else() {
        for g in [
            Geometry::Homography,
            Geometry::Fundamental,
            Geometry::RelativePose,
        ] {
            let mut o = g.default_options();
            assert_eq!(o.ransac.threshold, g.default_threshold());
            o.ransac.threshold = EstimatorOptions::default().ransac.threshold;
            assert_eq!(
                format!("{o:?}"),
                format!("{:?}", EstimatorOptions::default())
            );
        }
    }
}
