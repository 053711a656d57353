//! View synthesis as a cascade, for pairs that the plain matcher cannot solve: large in-plane
//! rotation, zoom and tilt (the idea of ASIFT and MODS; Morel & Yu 2009, Mishkin et al. 2015).
//!
//! 1. The plain pair is matched and **verified**: a fundamental matrix from 3-AC samples
//!    (`affcorr_ransac::estimate_fundamental` at [`VERIFY_THRESHOLD`]) scored with the
//!    affine Sampson error too ([`VERIFY_AFFINE_WEIGHT`]; [`VERIFY_AFFINE_WEIGHT_NETWORK`] for
//!    the shape network's unrefined ACs), so that a match counts only when
//!    its point *and* its A agree with F, must have at least [`ViewOptions::min_inliers`]
//!    such inliers making up at least [`ViewOptions::min_inlier_ratio`] of the matches. F
//!    rather than H, so that non-planar scenes verify. Points alone are not enough: a few
//!    dozen wrong matches of a rotated pair often fit some F within 2 px, while their ACs
//!    rarely fit it (benches/results/views.md has the measurement).
//!    A pass that verifies only weakly (under [`WEAK_RATIO`] of its matches agree, the
//!    matcher's share of [`crate::defaults::weak_ratio`], or fewer
//!    inliers than [`WEAK_YIELD`] of the keypoint budget: a repetitive pattern matched at
//!    the wrong rotation looks like this; or whose matches' median certainty is low: a
//!    repetitive pattern matched a quarter turn off can agree almost wholly with one F, and
//!    only its matcher is unsure of it) is rivalled by B rotated in 45° steps
//!    ([`rival_views`], screened; those that do not stand out are not matched); a rival with
//!    [`RIVAL_MARGIN`] times its inliers replaces it, or one with more inliers and
//!    [`RIVAL_MARGIN`] times its support by one homography (`planar_rival`). Verified by fewer than
//!    [`CONFIDENT_VIEW`] × min_inliers (too few to end the cascade on a synthetic view), it is
//!    rivalled by every view of step 2, the one its inliers guide right after the rotations
//!    (a steep tilt verifies with a dozen or two matches); verified by more, by the rotations
//!    and then the view its inliers guide (a 70° tilt verifies with a few dozen matches in a
//!    band of the overlap).
//! 2. If it fails (and [`ViewMode::Auto`]), synthetic views of one image are matched against
//!    the other, in order, until one verifies ([`ViewMode::Full`] tries them all and keeps
//!    the best), within [`ViewOptions::relative_budget`]:
//!    - **AC-guided** first: when the plain pass has a few F-inliers, their median affine map
//!      D says the dominant rotation, zoom and tilt; the view undoes it (B by D⁻¹, or A by D
//!      when that shrinks instead of enlarging). Later, any view whose ACs partly agree (more
//!      than every guide so far, but too few to verify) puts the view that undoes *their*
//!      dominant map at the front of the queue (up to three guided views a pair): a tilt view
//!      that finds the right tilt but not the rotation leads to the view with both.
//!    - in-plane **rotations** of B in 45° steps ([`ROTATIONS_DEG`], one screened group: the
//!      matchers hold about ±45°, but a view 45° off gives fewer and worse matches than the
//!      one that undoes the rotation), **zooms** of A or B by ½, then by ¼ (the matcher's
//!      keypoint budget lands on the overlap);
//!    - then **screened groups** ([`Step::Screened`], [`screen`]): tilts t = 2 (4 directions)
//!      of A and of B, each against the other image as it is and rotated by 270°, 90° and
//!      180° (a steep tilt of a rotated pair needs both undone); tilts t = 4 (8 directions)
//!      of A and of B against the rotations, in one group with the same tilts zoomed by ½
//!      (a steep tilt seen from farther away); **tiles** of B and of A: half-size tiles
//!      magnified by 2 against the other image shrunk by ½ (3–6× zooms), one group ranked by
//!      the screen but matched whole ([`Step::Ranked`]), then third-size tiles magnified by 3
//!      against the other image as it is (6×), ranked the same. A group extracts each of
//!      its warped images once, ranks its views by XFeat's mutual nearest neighbours and a
//!      homography's inliers (milliseconds, where LighterGlue and the ACs take hundreds),
//!      matches those clearly above the group's noise ([`screen_run`]) and defers the rest
//!      until every step has run. The screen is XFeat's for every matcher: DISK's and
//!      ALIKED's groups (whose extractions cost 10–30× XFeat's) and XFeat*'s (whose cells have
//!      no keypoint descriptors) are screened with XFeat's keypoints, and the matcher
//!      extracts only the views that run ([`crate::defaults::view_screen`]).
//!    - a view that verifies with fewer than [`REFINE_BELOW`] × min_inliers, or fewer than
//!      [`WEAK_YIELD`] of the keypoint budget, is followed by its refinement
//!      ([`refinement_view`], the view its inliers' map guides); the one with
//!      more inliers is kept. If that has fewer than [`CONFIDENT_VIEW`] × min_inliers, the
//!      cascade goes on, and a view with [`RIVAL_MARGIN`] times its inliers replaces it.
//! 3. Every AC of a view is mapped back to the original images with its A composed with the
//!    synthetic warp ([`affcorr_image::ac_from_views`]), so the ACs are correct in the
//!    original pixels whichever view produced them.
//! 4. A kept pass (plain or synthetic) verified with a [`WEAK_YIELD`] is grown by guided
//!    re-matching ([`crate::grow`]) in the original images: a steep tilt's or a zoom's few
//!    matches cluster in part of the overlap, and a model fitted to them extrapolates badly
//!    elsewhere (benches/results/eval/extreme_varied.md).
//!
//! [`crate::Matches::views`] reports each view tried: its warp, matches, inliers and time.

use std::fmt;
use std::str::FromStr;
use std::time::Duration;

use affcorr_geom::Mat3;
use affcorr_image::AffineWarp;
use affcorr_ransac::{
    Correspondences, EstimatorOptions, LoSchedule, RansacError, estimate_fundamental,
    estimate_homography,
};
use affcorr_runner::{FeatureData, ImageFeatures, mutual_nearest_neighbours};

use crate::defaults;
use crate::error::{PipelineError, Result};

/// The weight λ (px² per unit of affine Sampson error) of the affine residual in
/// verification: the estimators' own weight for "the affine part is accurate too"
/// (`affine_weight` of `affcorr_ransac::EstimatorOptions`, docs/design.md §5).
pub const VERIFY_AFFINE_WEIGHT: f64 = 50.0;

/// [`VERIFY_AFFINE_WEIGHT`]'s counterpart for the shape network's own ACs, when the pipeline
/// does not refine them (`refine_affine` off).
///
/// The network's A is an order of magnitude less accurate than the refined one
/// (benches/results/eval/affine.md). At the refined ACs' weight about half of a correct
/// pass's network ACs fail the affine check, so an easy pair verified only weakly
/// ([`WEAK_RATIO`]) and paid for the rotated rivals. A tenth of the weight keeps most correct
/// ACs and still rejects most ACs whose shape is wrong (the unit test
/// `the_network_weight_keeps_the_networks_acs_and_still_rejects_random_shapes`). The price:
/// the network's A tells a chessboard matched a quarter turn off from the right turn less well,
/// and rotated chessboards lose a few pairs; judging weak passes by refined copies of their
/// ACs instead lost as many at a higher cost (docs/pipeline.md, "Without the refinement").
pub const VERIFY_AFFINE_WEIGHT_NETWORK: f64 = 5.0;

/// The verification's affine weight for a pipeline's ACs: [`VERIFY_AFFINE_WEIGHT`] when they
/// are refined against the images, [`VERIFY_AFFINE_WEIGHT_NETWORK`] when they are the shape
/// network's.
pub(crate) fn verify_affine_weight(refined: bool) -> f64 {
    if refined {
        VERIFY_AFFINE_WEIGHT
    } else {
        VERIFY_AFFINE_WEIGHT_NETWORK
    }
}

/// The Sampson threshold (px) of verification: looser than an estimate's, since a verified
/// pair only has to be right, not precise (the thresholds of the numbers in
/// benches/results/views.md and benches/results/eval/extreme.md).
pub const VERIFY_THRESHOLD: f64 = 2.0;

/// A plain pair verified by fewer than this share of its matches is verified only weakly: on
/// a repetitive pattern (a chessboard, a facade) a rotated pair's wrong matches often agree
/// with some F, and in auto mode the rotated views ([`rival_views`]) are tried as rivals. On
/// the chessboard stereo pairs with B rotated (benches/results/views_pose.md) the wrong
/// rotation's share was 0.16–0.55, the right one's 0.37–0.93. XFeat's mutual nearest
/// neighbours, whose correct passes keep many outliers, have their own
/// ([`crate::defaults::weak_ratio`]).
pub const WEAK_RATIO: f64 = 0.6;

/// A rival view replaces a weakly verified plain pair only with this many times its inliers
/// (the right rotation of those pairs had 2–10× the wrong one's).
pub const RIVAL_MARGIN: f64 = 1.5;

/// A plain pair verified by fewer inliers than this share of the keypoint budget is verified
/// only weakly too: a repetitive pattern matched at a wrong rotation can agree almost
/// wholly with one F (the chessboard pairs of benches/results/views_pose.md rotated by 135°
/// agreed 48 of 53, 81 of 123 and 96 of 157 at a wrong rotation; upright they had 138–222
/// inliers at 1024 keypoints) and only the number of inliers tells them from the right one.
pub const WEAK_YIELD: f64 = 0.1;

/// The transfer threshold (px) of the homography that measures a pass's support by one plane
/// (`planar_support`, which breaks near-ties between rivals).
pub const PLANAR_THRESHOLD: f64 = 3.0;

/// A view that outnumbers the kept pass's verified inliers but falls short of
/// [`RIVAL_MARGIN`] replaces it when its [`planar_support`] is [`RIVAL_MARGIN`] times the
/// kept pass's. A repetitive pattern registered at a wrong rotation (a chessboard a quarter
/// turn off) fits some F with most of its matches, since an epipolar line leaves a match one
/// degree of freedom, but fits a homography poorly; the right registration's dominant plane
/// does (the board views of benches/results/views_pose_board.md: docs/pipeline.md, "Rotated
/// pairs").
pub(crate) fn planar_rival(view: usize, kept: usize) -> bool {
    view as f64 >= RIVAL_MARGIN * kept.max(1) as f64
}

/// The inliers of the best homography of the matches' points at [`PLANAR_THRESHOLD`]: how much
/// of a pass one plane explains (0 without a model).
pub(crate) fn planar_support(corrs: &[[f64; 8]]) -> Result<usize> {
    if corrs.len() < 8 {
        return Ok(0);
    }
    let rows: Vec<[f64; 4]> = corrs.iter().map(|r| [r[0], r[1], r[2], r[3]]).collect();
    let max_iterations = EstimatorOptions::default().ransac.max_iterations;
    homography_inliers(&rows, PLANAR_THRESHOLD, max_iterations)
}

/// The inliers of affcorr's homography RANSAC on point `rows` (x1, y1, x2, y2) at `threshold`
/// px within `max_iterations`; 0 without a model.
///
/// A count of support, not a model: local optimisation follows the widening schedule alone,
/// whose model takes in every match within the threshold of one homography (as when the
/// margins that compare these counts were measured). The homography's default two tracks
/// prefer the better-scoring, tighter model and can count fewer: with them a zoomed 80° pair
/// of benches/results/eval/extreme_zoom.md lost its rival view.
fn homography_inliers(rows: &[[f64; 4]], threshold: f64, max_iterations: usize) -> Result<usize> {
    let data = Correspondences::from_point_rows(rows)?;
    let mut o = EstimatorOptions::default();
    o.ransac.threshold = threshold;
    o.ransac.max_iterations = max_iterations;
    o.ransac.lo_schedule = LoSchedule::Widening;
    match estimate_homography(&data, &o) {
        Ok(e) => Ok(e.num_inliers),
        Err(RansacError::NoModel { .. }) => Ok(0),
        Err(e) => Err(e.into()),
    }
}

/// Whether `inliers` are fewer than [`WEAK_YIELD`] of the keypoint budget: the yardstick of the
/// plain pass (rivals) and of a synthetic view (its refinement).
pub(crate) fn weak_yield(inliers: usize, keypoint_budget: usize) -> bool {
    (inliers as f64) < WEAK_YIELD * keypoint_budget as f64
}

/// Whether the plain pass's matches are uncertain enough to be rivalled however well they
/// verify: their median `certainty` is below `floor`, the matcher's
/// ([`crate::defaults::rival_certainty`]; `None`: never). A repetitive pattern matched a
/// quarter turn off can agree with one F by most of its matches and more than
/// [`WEAK_YIELD`] of the keypoint budget, so neither [`WEAK_RATIO`] nor [`WEAK_YIELD`] sees
/// it; its matcher does, as a low median certainty (the measurements: docs/pipeline.md,
/// "Rotated pairs").
pub(crate) fn uncertain(certainty: &[f64], floor: Option<f64>) -> bool {
    let Some(floor) = floor else {
        return false;
    };
    !certainty.is_empty() && median(certainty.to_vec()) < floor
}

/// The element at `values.len() / 2` in sorted order (the upper of the two middle ones for an
/// even count); `values` must not be empty.
fn median(mut values: Vec<f64>) -> f64 {
    let k = values.len() / 2;
    *values.select_nth_unstable_by(k, f64::total_cmp).1
}

/// A synthetic view (with its refinement) that verifies with fewer than this many times
/// [`ViewOptions::min_inliers`] does not end an auto cascade: it is kept, and a later view
/// replaces it with [`RIVAL_MARGIN`] times its inliers. A dozen matches that agree with
/// some F are a weak proof on a zoom pair, where little of the other image is seen.
pub const CONFIDENT_VIEW: usize = 2;

/// Whether and how the pipeline synthesises views.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ViewMode {
    /// The plain pair only (`"off"`).
    Off,
    /// Views only when the plain pair fails verification, stopping at the first that verifies
    /// (`"auto"`).
    Auto,
    /// Every view, keeping the one with the most verified inliers (`"full"`).
    Full,
}

impl ViewMode {
    /// The name in APIs.
    pub fn name(self) -> &'static str {
        match self {
            Self::Off => "off",
            Self::Auto => "auto",
            Self::Full => "full",
        }
    }
}

impl fmt::Display for ViewMode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for ViewMode {
    type Err = PipelineError;

    fn from_str(s: &str) -> Result<Self> {
        match s.to_ascii_lowercase().as_str() {
            "off" => Ok(Self::Off),
            "auto" => Ok(Self::Auto),
            "full" => Ok(Self::Full),
            _ => Err(PipelineError::invalid(
                "views",
                format!("unknown mode {s:?}; expected \"off\", \"auto\" or \"full\""),
            )),
        }
    }
}

/// Options of the view cascade.
#[derive(Debug, Clone, PartialEq)]
pub struct ViewOptions {
    /// The mode (default [`defaults::VIEWS`]).
    pub mode: ViewMode,
    /// Stop starting views after this much time in the cascade (`None`: no limit).
    pub time_budget: Option<Duration>,
    /// Stop starting views once the cascade has done this many times the plain pass's work
    /// (`None`: no limit), nor a screened group's screen (or its extractions) that would
    /// reach it, since no view could follow. Unlike [`Self::time_budget`] it scales with the
    /// image size and the keypoint budget, bounds what a pair that no view solves costs, and
    /// is counted, not timed (nominal costs of each extraction, matching, screen,
    /// verification and AC): which views run does not depend on the machine or its load.
    pub relative_budget: Option<f64>,
    /// At most this many synthetic views.
    pub max_views: usize,
    /// Verification: at least this many F-inliers (point and affine residual).
    pub min_inliers: usize,
    /// Verification: F-inliers / matches at least this.
    pub min_inlier_ratio: f64,
}

impl Default for ViewOptions {
    fn default() -> Self {
        Self {
            mode: defaults::VIEWS,
            time_budget: None,
            relative_budget: defaults::VIEW_RELATIVE_BUDGET,
            max_views: 256,
            min_inliers: defaults::VIEW_MIN_INLIERS,
            min_inlier_ratio: defaults::VIEW_MIN_INLIER_RATIO,
        }
    }
}

impl ViewOptions {
    /// Whether the cascade, `elapsed` into its views, having spent the work in `meter`, may
    /// start another view.
    pub(crate) fn within_budget(&self, elapsed: Duration, meter: &WorkMeter) -> bool {
        self.time_budget.is_none_or(|b| elapsed < b)
            && self
                .relative_budget
                .is_none_or(|k| meter.spent < k * meter.plain)
    }

    pub(crate) fn validate(&self) -> Result<()> {
        if let Some(k) = self.relative_budget
            && !(k > 0.0 && k.is_finite())
        {
            return Err(PipelineError::invalid(
                "relative_budget",
                format!("must be a positive number, got {k}"),
            ));
        }
        if !(0.0..=1.0).contains(&self.min_inlier_ratio) {
            return Err(PipelineError::invalid(
                "min_inlier_ratio",
                format!("must be in [0, 1], got {}", self.min_inlier_ratio),
            ));
        }
        if self.min_inliers < 8 {
            return Err(PipelineError::invalid(
                "min_inliers",
                format!(
                    "must be at least 8 (a fundamental matrix), got {}",
                    self.min_inliers
                ),
            ));
        }
        Ok(())
    }
}

/// The work of the cascade, counted in nominal milliseconds of the default matcher (XFeat +
/// LighterGlue at 1024 keypoints, 2 threads: benches/results/pipeline_timing.md), so that the
/// relative budget ([`ViewOptions::relative_budget`]) does not depend on the machine or its
/// load: the same pair runs the same views anywhere. Each stage is charged by what its time
/// grows with: an extraction by its pixels, a matching (and a screen) by the product of the two
/// sides' keypoints, the ACs (patches, shape network, refinement) by their number; a
/// verification is a fixed cost.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct WorkMeter {
    /// The plain pass's work: both extractions, their matching and its ACs.
    pub(crate) plain: f64,
    /// The cascade's work so far.
    pub(crate) spent: f64,
}

/// Nominal cost of extracting features from a megapixel (a VGA image in about 100 ms).
const EXTRACTION_PER_MEGAPIXEL: f64 = 330.0;
/// Nominal cost of matching per million keypoint pairs (1024 × 1024 in about 230 ms).
const MATCHING_PER_MEGAPAIR: f64 = 220.0;
/// Nominal cost of one AC: its patches, the shape network and the affine refinement.
const PER_AC: f64 = 0.6;
/// A screen (mutual nearest neighbours and a homography) costs this share of a matching.
const SCREEN_SHARE: f64 = 0.05;
/// Nominal cost of a verification (a fundamental matrix by RANSAC on the ACs): the
/// pipeline's `views` stage of an easy pair (benches/results/pipeline_timing.md).
const VERIFICATION: f64 = 2.0;

impl WorkMeter {
    /// The meter of a cascade after a plain pass on images of `pixels` (both together) with
    /// `keypoints` on each side, which gave `acs` ACs.
    pub(crate) fn new(pixels: usize, keypoints: (usize, usize), acs: usize) -> Self {
        Self {
            plain: Self::extraction_cost(pixels)
                + Self::matching_cost(keypoints)
                + acs as f64 * PER_AC,
            spent: 0.0,
        }
    }

    fn extraction_cost(pixels: usize) -> f64 {
        EXTRACTION_PER_MEGAPIXEL * pixels as f64 * 1e-6
    }

    fn matching_cost((a, b): (usize, usize)) -> f64 {
        MATCHING_PER_MEGAPAIR * (a * b) as f64 * 1e-6
    }

    /// Charges the extraction of a warped image of `pixels`.
    pub(crate) fn extraction(&mut self, pixels: usize) {
        self.spent += Self::extraction_cost(pixels);
    }

    /// Charges the screen of a view with `keypoints` on each side.
    pub(crate) fn screen(&mut self, keypoints: (usize, usize)) {
        self.spent += SCREEN_SHARE * Self::matching_cost(keypoints);
    }

    /// Charges a verification (the plain pass's is the cascade's first work).
    pub(crate) fn verification(&mut self) {
        self.spent += VERIFICATION;
    }

    /// Charges the matching of a view with `keypoints` on each side, and its `acs` ACs.
    pub(crate) fn matching(&mut self, keypoints: (usize, usize), acs: usize) {
        self.spent += Self::matching_cost(keypoints) + acs as f64 * PER_AC;
    }

    /// The work so far in plain passes.
    pub(crate) fn passes(&self) -> f64 {
        self.in_passes(self.spent)
    }

    /// `work` (nominal units, as `spent`) in plain passes.
    pub(crate) fn in_passes(&self, work: f64) -> f64 {
        work / self.plain.max(f64::MIN_POSITIVE)
    }
}

/// One image's warp in a view, with the size of the view it makes (`None`: the image as it
/// is).
pub type ImageWarp = Option<(AffineWarp, usize, usize)>;

/// The warps of a view's images A and B ([`ViewSpec::warps`]).
pub type ViewWarps = [ImageWarp; 2];

/// Which image a view warps.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ViewImage {
    /// Neither: the plain pair.
    None,
    /// Image A.
    A,
    /// Image B.
    B,
}

/// A synthetic view: which image, and the ASIFT parameters of its warp.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ViewSpec {
    /// The warped image.
    pub image: ViewImage,
    /// In-plane rotation ψ, radians.
    pub rotation: f64,
    /// Zoom s.
    pub scale: f64,
    /// Tilt t ≥ 1 (compression by t along `tilt_angle`).
    pub tilt: f64,
    /// Direction φ of the tilt, radians.
    pub tilt_angle: f64,
    /// The linear part, when the view was guided by ACs rather than parametrised.
    pub guided: Option<[f64; 4]>,
    /// The part of the warped image that is matched, `[x0, y0, x1, y1]` as fractions of its
    /// width and height (`None`: all of it). A magnified tile spends the keypoint budget on
    /// a small part of the image: where the other image is a strong zoom into it.
    pub window: Option<[f64; 4]>,
    /// The zoom of the *other* image (1: as it is). A tile magnified by s meets the other
    /// image shrunk, so that the scales meet without magnifying the tile past the matcher's
    /// useful resolution.
    pub other_scale: f64,
    /// The in-plane rotation of the *other* image, radians (0: as it is). A steep tilt of
    /// one image against the other rotated by 90°, 180° or 270° needs no extraction of its
    /// own: both views' features are the cascade's already (the tilt views' and the rotated
    /// views'), and only the matching runs. It reaches what the tilt of the rotated image
    /// would: the matcher needs the local map between the views near a similarity with a
    /// small rotation, and R D T⁻¹ and D T⁻¹ R share it once T undoes D's tilt.
    pub other_rotation: f64,
}

impl ViewSpec {
    /// The plain pair.
    pub const PLAIN: Self = Self {
        image: ViewImage::None,
        rotation: 0.0,
        scale: 1.0,
        tilt: 1.0,
        tilt_angle: 0.0,
        guided: None,
        window: None,
        other_scale: 1.0,
        other_rotation: 0.0,
    };

    fn param(image: ViewImage, rotation_deg: f64, scale: f64, tilt: f64, tilt_deg: f64) -> Self {
        Self {
            image,
            rotation: rotation_deg.to_radians(),
            scale,
            tilt,
            tilt_angle: tilt_deg.to_radians(),
            ..Self::PLAIN
        }
    }

    /// This view against the other image rotated by `degrees`.
    fn with_other_rotation(self, degrees: f64) -> Self {
        Self {
            other_rotation: degrees.to_radians(),
            ..self
        }
    }

    /// A tile of `image` magnified by `scale`: the window `[x0, y0, x0 + size, y0 + size]`
    /// (fractions), with the other image zoomed by `other_scale`.
    fn tile(image: ViewImage, scale: f64, x0: f64, y0: f64, size: f64, other_scale: f64) -> Self {
        Self {
            image,
            scale,
            window: Some([x0, y0, x0 + size, y0 + size]),
            other_scale,
            ..Self::PLAIN
        }
    }

    /// The warps of images A and B (`width` × `height` each) that make this view, each with
    /// the size of its view, `None` for an image matched as it is.
    pub fn warps(&self, a: (usize, usize), b: (usize, usize)) -> ViewWarps {
        let (main, other) = match self.image {
            ViewImage::None => return [None, None],
            ViewImage::A => (a, b),
            ViewImage::B => (b, a),
        };
        let (w, vw, vh) = self.linear().fitted(main.0, main.1);
        let main_view = Some(match self.window {
            Some(window) => w.windowed(vw, vh, window),
            None => (w, vw, vh),
        });
        let other_view = (self.other_scale != 1.0 || self.other_rotation != 0.0).then(|| {
            AffineWarp::linear(self.other_rotation, self.other_scale, 1.0, 0.0)
                .fitted(other.0, other.1)
        });
        match self.image {
            ViewImage::A => [main_view, other_view],
            _ => [other_view, main_view],
        }
    }

    /// The warp's linear part.
    pub fn linear(&self) -> AffineWarp {
        match self.guided {
            Some(m) => AffineWarp { m, c: [0.0, 0.0] },
            None => AffineWarp::linear(self.rotation, self.scale, self.tilt, self.tilt_angle),
        }
    }

    /// A short label, e.g. `"B rot 90°"`, `"A zoom 0.5"`, `"A tilt 2 @45°"`, `"guided"`.
    pub fn label(&self) -> String {
        let image = match self.image {
            ViewImage::None => return "plain".to_string(),
            ViewImage::A => "A",
            ViewImage::B => "B",
        };
        if self.guided.is_some() {
            return format!("{image} guided");
        }
        let mut parts = vec![image.to_string()];
        if self.rotation != 0.0 {
            parts.push(format!("rot {:.0}°", self.rotation.to_degrees()));
        }
        if self.scale != 1.0 {
            parts.push(format!("zoom {}", self.scale));
        }
        if self.tilt != 1.0 {
            parts.push(format!(
                "tilt {} @{:.1}°",
                self.tilt,
                self.tilt_angle.to_degrees()
            ));
        }
        if let Some(w) = self.window {
            let [x0, y0, x1, y1] = w.map(short);
            parts.push(format!("tile [{x0}, {y0}; {x1}, {y1}]"));
        }
        let other = if self.image == ViewImage::A { "B" } else { "A" };
        if self.other_rotation != 0.0 {
            let r = self.other_rotation.to_degrees();
            parts.push(format!("+ {other} rot {r:.0}°"));
        }
        if self.other_scale != 1.0 {
            parts.push(format!("+ {other} zoom {}", self.other_scale));
        }
        parts.join(" ")
    }
}

/// `v` to at most two decimals, without trailing zeros: 0.5, 0.33, 1.
fn short(v: f64) -> String {
    let text = format!("{v:.2}");
    text.trim_end_matches('0').trim_end_matches('.').to_string()
}

/// What one view of the cascade gave.
#[derive(Debug, Clone, PartialEq)]
pub struct ViewReport {
    /// The view.
    pub view: ViewSpec,
    /// Its matches.
    pub matches: usize,
    /// Their inliers to the verifying F (0 when none was found).
    pub inliers: usize,
    /// Whether it passed verification.
    pub verified: bool,
    /// Its [`screen`], when it was ranked in a screened group.
    pub screen: Option<usize>,
    /// Wall time: warping, matching, ACs and verification.
    pub time: Duration,
    /// The work it took from [`ViewOptions::relative_budget`], in plain passes (the plain
    /// pass: 1): its extractions, its group's screen when it is the first of the group to run,
    /// its matching and its ACs; counted, not timed. The last view (the plain pass when no
    /// view ran) also carries what was spent after it (a group's extractions whose screens
    /// would have reached the budget, or a screen the time budget cut short), so that the
    /// views' work sums to the pair's.
    pub work: f64,
    /// The work spent when it started, in plain passes (the plain pass: 0), its group's
    /// screen included: what [`ViewOptions::relative_budget`] was compared with. The view runs
    /// under any budget above it, so one cascade run tells which views a smaller budget runs.
    pub started: f64,
    /// The part of `started` (and of `work`) that its group's screen spent on extractions, in
    /// plain passes: 0 for a view with no screen before it. Under a budget at or below
    /// `started` the cascade stops before this screen, or, when the work before the screen
    /// plus its extractions is below the budget, after the extractions (its screens would
    /// reach the budget): no screen is paid for without a view after it.
    pub screen_extraction: f64,
    /// Whether its ACs are the result's (one view of a cascade; a verified view with the most
    /// inliers is not used when it fell short of a rival's margin, [`RIVAL_MARGIN`]).
    pub used: bool,
}

/// The in-plane rotations of B (degrees) that the cascade tries: 45° steps, so that no
/// rotation is more than 22.5° from one (the matchers hold about ±45°, but a pair matched
/// 45° off gives fewer and less accurate matches than the upright pair: on the rotated
/// non-planar pairs of benches/results/views_pose.md, 135° lost a fifth of what 90° and
/// 180° solved while only the 90° steps were tried first).
pub const ROTATIONS_DEG: [f64; 7] = [90.0, 270.0, 180.0, 45.0, 315.0, 135.0, 225.0];

/// The rotated views of B ([`ROTATIONS_DEG`]): the cascade's first step, screened as one
/// group (seven extractions of B, then the views matched best-screened first), and the
/// rivals of a weakly verified plain pair.
pub fn rival_views() -> Vec<ViewSpec> {
    ROTATIONS_DEG
        .map(|r| ViewSpec::param(ViewImage::B, r, 1.0, 1.0, 0.0))
        .to_vec()
}

/// A step of the cascade: one view, or a group of views ranked by a cheap screen before any
/// is matched ([`screen`]).
#[derive(Debug, Clone, PartialEq)]
pub enum Step {
    /// One view, matched as it comes.
    View(ViewSpec),
    /// Views whose warped images are few and shared (tilts of one image against rotations of
    /// the other; tiles against one zoom of the other): every warped image is extracted once,
    /// each view is screened by XFeat's mutual nearest neighbours, and the views are matched
    /// best-screened first; after [`screen_run`] of them the rest waits until every step has
    /// run, best over its group's noise first.
    Screened(Vec<ViewSpec>),
    /// Views screened and matched like [`Step::Screened`]'s, best-screened first, but all of
    /// them before the next step: for tiles, whose screen hardly tells the right one (the
    /// zoomed image's content fills a ninth of a tile: on the 6× zoom pairs of
    /// benches/results/views.md the right tile screened 10–17 against 8–13 for the others),
    /// while a tile with nothing in it costs only its matching (a few dozen milliseconds).
    Ranked(Vec<ViewSpec>),
}

/// The steps of the cascade in order (after the AC-guided view).
pub fn cascade_steps() -> Vec<Step> {
    use ViewImage::{A, B};
    let zoom = |image, s| ViewSpec::param(image, 0.0, s, 1.0, 0.0);
    let single = |v: Vec<ViewSpec>| v.into_iter().map(Step::View).collect::<Vec<_>>();
    let mut steps = vec![Step::Screened(rival_views())];
    steps.extend(single(vec![zoom(A, 0.5), zoom(B, 0.5)]));
    steps.extend(single(vec![zoom(A, 0.25), zoom(B, 0.25)]));
    // Tilts t of `image` in n directions (zoomed by s) against the other image as it is and
    // rotated by 270°, 90° and 180°: a steep tilt of a rotated pair needs both undone at once,
    // and the rotated images are the rivals' (B) or shared by the group (A). A's tilt 4 meets
    // B's 45° rotations too: what tilt 4 leaves of an 80° tilt and up to 45° of roll together
    // were beyond the matcher (docs/pipeline.md, "Extreme viewpoints beyond experiment 4").
    // B's rotated images are extracted for the rivals already, so the extra views cost their
    // screens; B's tilts would need four more extractions of A, and solved nothing more.
    let rotated_tilts = |image, s: f64, t: f64, n: usize| {
        let rotations: &'static [f64] = if t >= 4.0 && image == A {
            &[0.0, 270.0, 90.0, 180.0, 45.0, 315.0, 135.0, 225.0]
        } else {
            &[0.0, 270.0, 90.0, 180.0]
        };
        rotations.iter().copied().flat_map(move |r| {
            (0..n).map(move |k| {
                ViewSpec::param(image, 0.0, s, t, 180.0 * k as f64 / n as f64)
                    .with_other_rotation(r)
            })
        })
    };
    // Tiles of `image` magnified by `scale` (each 1/`scale` of its side), at every pair of
    // `starts` (fractions; x and y), against the other image zoomed by `other_scale`.
    let tile_grid = |image, scale: f64, starts: [f64; 3], other_scale| {
        starts.into_iter().flat_map(move |y0| {
            starts
                .into_iter()
                .map(move |x0| ViewSpec::tile(image, scale, x0, y0, 1.0 / scale, other_scale))
        })
    };
    // Strong zooms (4–8×): the zoomed image's content is a small part of the other, where
    // the other's keypoint budget barely lands. Half-size tiles of that image, magnified by 2
    // and overlapping by half (so that any part up to a quarter of the image's side lies
    // inside one), meet the zoomed image shrunk by ½.
    let tiles = |image| tile_grid(image, 2.0, [0.25, 0.0, 0.5], 0.5);
    // Tilt 2 first (with the other image rotated it solved every 80° tilt of experiment 4
    // outright or through its refinement), then tilt 4, then the tiles. A tilt group's warped
    // images are foreshortened (a quarter of the pixels at tilt 4) and its screen tells the
    // right view, where the tiles are full-size images run whole: with the tiles first, the
    // tiles took 20 of the 30 plain passes of budget, and 80° tilts of other textures and
    // cameras (benches/results/eval/extreme_varied.md) never reached tilt 4. Tilt 4 first
    // costs a 4–6× zoom pair about 4 more plain passes of work (views.md).
    steps.push(Step::Screened(
        rotated_tilts(A, 1.0, 2.0, 4)
            .chain(rotated_tilts(B, 1.0, 2.0, 4))
            .collect(),
    ));
    // Stronger zooms (6×): the zoomed image's content is a sixth of the other's side, a third
    // of a half-size tile, where about a ninth of the tile's keypoints land: too few. Third-
    // size tiles magnified by 3 give it a quarter of them (and more where it sits inside one)
    // and meet the zoomed image as it is (its features are the plain pass's): 2× apart,
    // within the matcher's range.
    let third_tiles = |image| tile_grid(image, 3.0, [1.0 / 3.0, 0.0, 2.0 / 3.0], 1.0);
    // The tiles of both images in one group each: which image is the zoomed one is not
    // known, and the screen ranks the 18 views together, so that the right tile of either
    // image runs before the other image's tiles are reached. The half-size tiles first: with
    // the third-size tiles first, a 6× zoom that only a half-size tile solves
    // (tests/views.rs) reached it near the budget, and failed on a loaded machine.
    // Tilt 4 of an image at its size and zoomed by ½, in one group per image: a steep tilt
    // seen from farther away (EVD's pairs; the tilt and zoom set of
    // benches/results/eval/extreme_zoom.md) shrinks the plane across the tilt too, beyond
    // the matcher's scale range, and the screen tells the zoomed view from the plain one as
    // it tells the directions apart. The zoomed views are small: 1/16 of the pixels.
    for image in [A, B] {
        steps.push(Step::Screened(
            rotated_tilts(image, 1.0, 4.0, 8)
                .chain(rotated_tilts(image, 0.5, 4.0, 8))
                .collect(),
        ));
    }
    steps.push(Step::Ranked(tiles(B).chain(tiles(A)).collect()));
    steps.push(Step::Ranked(third_tiles(B).chain(third_tiles(A)).collect()));
    steps
}

/// Every view of the cascade's steps, in their order before screening.
pub fn candidate_views() -> Vec<ViewSpec> {
    cascade_steps()
        .into_iter()
        .flat_map(|s| match s {
            Step::View(v) => vec![v],
            Step::Screened(v) | Step::Ranked(v) => v,
        })
        .collect()
}

/// Whether a view kept as verified by `inliers` (at least [`CONFIDENT_VIEW`] × min_inliers)
/// is still rivalled by the rotated views, the cascade's `next` step, instead of ending the
/// cascade: it verified before the rotations ran (the view guided by a failed plain pass's
/// agreeing ACs, or its refinement) and with a [`weak_yield`]. A pattern matched at the wrong
/// rotation can agree in part and guide to a wrong registration that verifies; the rotations
/// rival it as they rival a weak plain pass, and nothing after them runs. On views_pose this
/// took one stereo pair turned by 135° from the wrong guided view to B turned by 135°, and
/// with XFeat* two (docs/pipeline.md, "Rotated pairs").
pub(crate) fn rivalled_by_rotations(
    next: Option<&Step>,
    inliers: usize,
    keypoint_budget: usize,
) -> bool {
    next == Some(&Step::Screened(rival_views())) && weak_yield(inliers, keypoint_budget)
}

/// The inlier threshold (px, in the views' pixels) of the screen's homography.
pub const SCREEN_THRESHOLD: f64 = 5.0;

/// A screened group's best-screened views matched before the rest of it waits for the end:
/// at most this many...
pub const SCREEN_RUN: usize = 4;

/// ... of those screened at least this many times the group's median (its noise: most views
/// of a group see nothing), and at least the best one.
pub const SCREEN_MARGIN: usize = 2;

/// How many of a screened group's views, sorted by `scores` (best first), run before the rest
/// waits ([`SCREEN_RUN`], [`SCREEN_MARGIN`]).
pub fn screen_run(scores: &[usize]) -> usize {
    if scores.is_empty() {
        return 0;
    }
    let noise = scores[scores.len() / 2];
    let above = scores
        .iter()
        .take_while(|&&s| s > 0 && s >= SCREEN_MARGIN * noise)
        .count();
    above.clamp(1, SCREEN_RUN)
}

/// The largest part of its source image's pixels that a screened view's warped image keeps:
/// a group's screen extracts every warped image of it, most of a hard pair's work, and ranks
/// its views about as well on images of half the side (benches/results/views_budget.md).
pub const SCREEN_PIXELS: f64 = 0.25;

/// The strongest compression of its source image, along any direction, that a view's screen
/// may shrink it to (it never shrinks an image already compressed beyond this): a tilt of 4
/// halved again (1/8 across the tilt) screened the steep tilts' views as noise and lost 80°
/// tilts, where the isotropic shrinks (rotations, zooms, tiles) and tilt 2 solved as many as
/// at full size (docs/pipeline.md, "Views", has the figures).
pub const SCREEN_MIN_SCALE: f64 = 0.25;

/// The warps (A's, B's; `None`: the image as it is, of size `a` or `b`) on which a view with
/// `warps` is screened: both shrunk by one factor, so that the view's geometry is unchanged,
/// the largest at which neither keeps more than [`SCREEN_PIXELS`] of its source's pixels
/// (in its content: the warped source, or the window of it that the view keeps),
/// raised so that neither is compressed beyond [`SCREEN_MIN_SCALE`] in any direction; `warps`
/// themselves when that factor is above 0.9 (a tenth of the side is not worth another
/// extraction, nor a pixel of rounding).
pub fn screen_warps(warps: &ViewWarps, a: (usize, usize), b: (usize, usize)) -> ViewWarps {
    let sides = [(warps[0], a), (warps[1], b)]
        .map(|(w, (sw, sh))| (w.unwrap_or((AffineWarp::IDENTITY, sw, sh)), sw * sh));
    let mut scale = 1.0f64;
    let mut floor = 0.0f64;
    for ((w, vw, vh), source) in sides {
        // The image's content, not its view's box: a 45° rotation's box is twice its pixels,
        // and its screen must compare with the other rotations'.
        let [m11, m12, m21, m22] = w.m;
        let content = ((vw * vh) as f64).min((m11 * m22 - m12 * m21).abs() * source as f64);
        scale = scale.min((SCREEN_PIXELS * source as f64 / content).sqrt());
        floor = floor.max(SCREEN_MIN_SCALE / w.min_singular_value());
    }
    let scale = scale.max(floor);
    if scale > 0.9 {
        return *warps;
    }
    sides.map(|((w, vw, vh), _)| {
        let shrunk = |n: usize| ((n - 1) as f64 * scale).floor() as usize + 1;
        Some((
            AffineWarp {
                m: w.m.map(|v| v * scale),
                c: w.c.map(|v| v * scale),
            },
            shrunk(vw),
            shrunk(vh),
        ))
    })
}

/// The screen of a view: the inliers of a homography (points only, [`SCREEN_THRESHOLD`])
/// among the mutual nearest neighbours of the two views' XFeat descriptors. Matching costs
/// a few milliseconds where LighterGlue and the ACs cost a few hundred, and on experiment 4's
/// steep tilts the views that verify scored 19–129 against 5–17 for the others; 0 for
/// features without descriptors (XFeat*, dense).
pub fn screen(a: &ImageFeatures, b: &ImageFeatures) -> Result<usize> {
    let (FeatureData::Sparse(a), FeatureData::Sparse(b)) = (&a.data, &b.data) else {
        return Ok(0);
    };
    let m = mutual_nearest_neighbours(&a.descriptors, &b.descriptors, a.dim);
    if m.len() < 8 {
        return Ok(0);
    }
    let rows: Vec<[f64; 4]> = m
        .idx1
        .iter()
        .zip(&m.idx2)
        .map(|(&i, &j)| {
            let (p, q) = (a.keypoints[i], b.keypoints[j]);
            [p[0].into(), p[1].into(), q[0].into(), q[1].into()]
        })
        .collect();
    homography_inliers(&rows, SCREEN_THRESHOLD, 1000)
}

/// The view that undoes the dominant affine map D of `inlier_acs` (their elementwise median):
/// B warped by D⁻¹, or A by D when D shrinks (so that the view shrinks rather than enlarges).
/// `None` with fewer than 8 ACs, a D close to the identity, or a degenerate D.
pub fn guided_view(inlier_acs: &[[f64; 8]]) -> Option<ViewSpec> {
    let d = dominant_map(inlier_acs)?;
    let det = d[0] * d[3] - d[1] * d[2];
    if !(det > 1e-3) || !det.is_finite() || off_identity(&d) < 0.3 {
        return None;
    }
    let inv = [d[3] / det, -d[1] / det, -d[2] / det, d[0] / det];
    let (image, m) = if det < 1.0 {
        (ViewImage::A, d)
    } else {
        (ViewImage::B, inv)
    };
    Some(ViewSpec {
        guided: Some(m),
        ..ViewSpec {
            image,
            ..ViewSpec::PLAIN
        }
    })
}

/// The elementwise median of the ACs' A; `None` for fewer than 8.
fn dominant_map(acs: &[[f64; 8]]) -> Option<[f64; 4]> {
    if acs.len() < 8 {
        return None;
    }
    let entry = |k: usize| median(acs.iter().map(|r| r[k]).collect());
    Some([entry(4), entry(5), entry(6), entry(7)])
}

/// |M − I| summed over the entries.
fn off_identity(m: &[f64; 4]) -> f64 {
    (m[0] - 1.0).abs() + m[1].abs() + m[2].abs() + (m[3] - 1.0).abs()
}

/// A synthetic view verified by fewer than this many times
/// [`ViewOptions::min_inliers`] (or fewer than [`WEAK_YIELD`] of the keypoint budget) is
/// refined ([`refinement_view`]) before the cascade stops: with accurate ACs a tilt view of
/// the grid verifies with several dozen inliers, where the view that undoes the map exactly
/// finds hundreds (the steep tilt of a rotated graffiti pair in tests/test_views.py: 67
/// inliers of 154 matches, then 428 of 484).
pub const REFINE_BELOW: usize = 4;

/// The refinement of a view that verified with few inliers (`inlier_acs`, in the original
/// images): the view that undoes their dominant map exactly ([`guided_view`]), when what the
/// view left of it (W_b D W_a⁻¹) is far from the identity. A view of the cascade's grid
/// (tilts 2 and 4 in 4–8 directions) verifies with a few dozen matches where the exact map
/// gives hundreds, enough for any estimator. `None` for tiles (the exact map would give up
/// the tile's magnification) and for views that already undo it.
pub fn refinement_view(view: &ViewSpec, inlier_acs: &[[f64; 8]]) -> Option<ViewSpec> {
    if view.window.is_some() {
        return None;
    }
    let d = dominant_map(inlier_acs)?;
    let main = view.linear().m;
    let other = AffineWarp::linear(view.other_rotation, view.other_scale, 1.0, 0.0).m;
    let (wa, wb) = match view.image {
        ViewImage::A => (main, other),
        ViewImage::B => (other, main),
        ViewImage::None => ([1.0, 0.0, 0.0, 1.0], [1.0, 0.0, 0.0, 1.0]),
    };
    let det = wa[0] * wa[3] - wa[1] * wa[2];
    let wa_inv = [wa[3] / det, -wa[1] / det, -wa[2] / det, wa[0] / det];
    let mul = |a: [f64; 4], b: [f64; 4]| {
        [
            a[0] * b[0] + a[1] * b[2],
            a[0] * b[1] + a[1] * b[3],
            a[2] * b[0] + a[3] * b[2],
            a[2] * b[1] + a[3] * b[3],
        ]
    };
    let left = mul(mul(wb, d), wa_inv);
    if off_identity(&left) < 0.3 {
        return None;
    }
    guided_view(inlier_acs)
}

/// The F-inliers of ACs (in any pixels) under the point and affine residual: 0 without a
/// model; the inlier mask.
pub(crate) fn verify(corrs: &[[f64; 8]], affine_weight: f64) -> Result<(usize, Vec<bool>)> {
    Ok(match verified_fundamental(corrs, affine_weight)? {
        Some((_, mask)) => (mask.iter().filter(|m| **m).count(), mask),
        None => (0, vec![false; corrs.len()]),
    })
}

/// The verifying fundamental matrix of ACs and its inlier mask ([`verify`]); `None` without a
/// model.
pub(crate) fn verified_fundamental(
    corrs: &[[f64; 8]],
    affine_weight: f64,
) -> Result<Option<(Mat3, Vec<bool>)>> {
    if corrs.len() < 8 {
        return Ok(None);
    }
    let data = Correspondences::from_ac_rows(corrs)?;
    let mut o = EstimatorOptions::default();
    o.ransac.threshold = VERIFY_THRESHOLD;
    o.affine_weight = Some(affine_weight);
    match estimate_fundamental(&data, &o) {
        Ok(e) => Ok(Some((e.model, e.inliers))),
        Err(RansacError::NoModel { .. }) => Ok(None),
        Err(e) => Err(e.into()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uncertain_compares_the_median_certainty_with_the_matchers_floor() {
        // Median 0.3 (one very sure match does not lift it).
        let c = [0.2, 0.99, 0.3, 0.25, 0.9];
        assert!(uncertain(&c, Some(0.35)));
        assert!(!uncertain(&c, Some(0.3)));
        // A matcher without a floor, or no matches, is never uncertain.
        assert!(!uncertain(&c, None));
        assert!(!uncertain(&[], Some(0.35)));
        // Only the LightGlue matchers' certainties are match probabilities with a floor
        // (measured on solved and wrongly registered pairs).
        use affcorr_runner::Matcher;
        assert_eq!(
            crate::defaults::rival_certainty(Matcher::XFeatLighterGlue),
            Some(0.35)
        );
        assert_eq!(
            crate::defaults::rival_certainty(Matcher::AlikedLightGlue),
            Some(0.3)
        );
        assert_eq!(
            crate::defaults::rival_certainty(Matcher::DiskLightGlue),
            Some(0.35)
        );
        for m in [Matcher::XFeatMnn, Matcher::XFeatStar, Matcher::Dense] {
            assert_eq!(crate::defaults::rival_certainty(m), None, "{m:?}");
        }
    }

    #[test]
    fn planar_support_tells_one_plane_from_parallax_that_fits_an_f() {
        use affcorr_geom::Vec2;
        use affcorr_geom::homography::ac_from_homography;
        let plane = Mat3::new(0.9, 0.08, 25.0, -0.05, 1.1, 12.0, 1e-4, -6e-5, 1.0);
        // A grid of 200 points of image A; a deterministic spread of depths for the parallax.
        let grid: Vec<(f64, f64)> = (0..200)
            .map(|i| (20.0 + 30.0 * (i % 20) as f64, 20.0 + 45.0 * (i / 20) as f64))
            .collect();
        let planar: Vec<[f64; 8]> = grid
            .iter()
            .map(|&(x, y)| {
                ac_from_homography(&plane, &Vec2::new(x, y), 0)
                    .unwrap()
                    .to_row()
            })
            .collect();
        // A sideways camera motion: every match on its (horizontal) epipolar line, shifted by
        // its own depth's disparity of 10-100 px. One F explains them all, one H few.
        let parallax: Vec<[f64; 8]> = grid
            .iter()
            .enumerate()
            .map(|(i, &(x, y))| {
                let d = 10.0 + 90.0 * ((i as f64 * 12.9898).sin() * 43_758.545).fract().abs();
                [x, y, x + d, y, 1.0, 0.0, 0.0, 1.0]
            })
            .collect();
        let (kept_planar, kept_parallax) = (
            planar_support(&planar).unwrap(),
            planar_support(&parallax).unwrap(),
        );
        assert_eq!(kept_planar, 200);
        assert!(kept_parallax < 40, "{kept_parallax}");
        assert_eq!(
            verify(&parallax, VERIFY_AFFINE_WEIGHT).unwrap().0,
            200,
            "the parallax fits one F"
        );
        assert!(planar_rival(kept_planar, kept_parallax));
        assert!(!planar_rival(kept_parallax, kept_planar));
        // The margin is RIVAL_MARGIN; a kept pass without a plane needs a rival of 2.
        assert!(planar_rival(3, 2) && !planar_rival(2, 2));
        assert!(planar_rival(2, 0) && !planar_rival(1, 0));
        assert_eq!(planar_support(&planar[..7]).unwrap(), 0);
    }

    /// ACs of a three-plane scene (0.5 px noise): `shape_noise` relative noise on A, and the
    /// ACs from `random_from` on with a random similarity for A (their points still exact).
    fn scene_acs(shape_noise: f64, random_from: usize, seed: u64) -> Vec<[f64; 8]> {
        use affcorr_geom::synthetic::{NoiseModel, PlaneScene, noisy_correspondences};
        use rand::{Rng, SeedableRng, rngs::StdRng};
        let mut rng = StdRng::seed_from_u64(seed);
        let scene = PlaneScene::random(&mut rng);
        let noise = NoiseModel {
            planes: 3,
            outlier_ratio: 0.0,
            pixel_noise: 0.5,
            affine_noise: shape_noise,
        };
        let (acs, _) = noisy_correspondences(&mut rng, &scene, 300, &noise);
        let mut rows: Vec<[f64; 8]> = acs.iter().map(|ac| ac.to_row()).collect();
        for row in &mut rows[random_from..] {
            let a = affcorr_geom::affine::rotation(rng.random_range(-3.0..3.0))
                * rng.random_range(0.5..2.0);
            row[4..].copy_from_slice(&[a[(0, 0)], a[(0, 1)], a[(1, 0)], a[(1, 1)]]);
        }
        rows
    }

    #[test]
    fn the_network_weight_keeps_the_networks_acs_and_still_rejects_random_shapes() {
        // Relative noise on A at which the refined ACs' weight keeps under WEAK_RATIO of a
        // correct pass, as it kept of the shape network's ACs on graffiti (0.53).
        let net = verify_affine_weight(false);
        assert_eq!(verify_affine_weight(true), VERIFY_AFFINE_WEIGHT);
        assert!(net < VERIFY_AFFINE_WEIGHT);
        for seed in 0..4 {
            // A correct pass of network ACs verifies strongly at the network's weight, and
            // looked weak (under WEAK_RATIO) at the refined ACs' weight.
            let correct = scene_acs(0.3, 300, seed);
            let share = |w| verify(&correct, w).unwrap().0 as f64 / correct.len() as f64;
            let (at_net, at_refined) = (share(net), share(VERIFY_AFFINE_WEIGHT));
            assert!(at_net > 0.9, "seed {seed}: {at_net}");
            assert!(at_refined < WEAK_RATIO, "seed {seed}: {at_refined}");
            // Matches whose points fit F but whose shapes are random: two thirds and more are
            // still rejected (eleven twelfths and more at the refined weight).
            let mixed = scene_acs(0.3, 180, seed);
            let kept = |w| {
                let (_, mask) = verify(&mixed, w).unwrap();
                let count = |m: &[bool]| m.iter().filter(|m| **m).count();
                (count(&mask[..180]), count(&mask[180..]))
            };
            let (kept_correct, kept_random) = kept(net);
            assert!(kept_random < 120 / 3, "seed {seed}: {kept_random} of 120");
            assert!(kept_correct > 160, "seed {seed}: {kept_correct} of 180");
            let (_, kept_random_refined) = kept(VERIFY_AFFINE_WEIGHT);
            assert!(
                kept_random_refined <= 120 / 12,
                "seed {seed}: {kept_random_refined}"
            );
        }
    }

    #[test]
    fn modes_parse_and_bad_options_are_named() {
        for m in [ViewMode::Off, ViewMode::Auto, ViewMode::Full] {
            assert_eq!(m.name().parse::<ViewMode>().unwrap(), m);
        }
        let e = "some".parse::<ViewMode>().unwrap_err().to_string();
        assert!(e.starts_with("views: unknown mode"), "{e}");
        let o = ViewOptions {
            min_inlier_ratio: 1.5,
            ..Default::default()
        };
        assert!(
            o.validate()
                .unwrap_err()
                .to_string()
                .contains("min_inlier_ratio")
        );
        let o = ViewOptions {
            min_inliers: 3,
            ..Default::default()
        };
        assert!(
            o.validate()
                .unwrap_err()
                .to_string()
                .contains("min_inliers")
        );
    }

    #[test]
    fn candidates_cover_rotation_zoom_and_tilt_without_repeats() {
        let v = candidate_views();
        // Rotations, zooms, tilt 2 of A and of B (4 directions × 4 rotations), tilt 4 of A
        // at its size and zoomed by ½ against B's 8 rotations (8 directions × 8 rotations) and
        // of B against A's 4 (8 × 4), the tiles.
        assert_eq!(v.len(), 7 + 4 + 32 + 128 + 64 + 18 + 18);
        let labels: std::collections::BTreeSet<String> = v.iter().map(|s| s.label()).collect();
        assert_eq!(labels.len(), v.len());
        assert!(labels.contains("B rot 90°") && labels.contains("A zoom 0.25"));
        assert!(labels.contains("B rot 135°") && labels.contains("B rot 315°"));
        assert!(
            labels.contains("B tilt 4 @157.5°") && labels.contains("A tilt 4 @22.5° + B rot 90°")
        );
        assert!(labels.contains("B tilt 2 @45.0° + A rot 180°"));
        // A's tilt 4 meets B's 45° rotations too (B's rotated images are the rivals'); B's
        // tilts and tilt 2 do not.
        assert!(labels.contains("A tilt 4 @112.5° + B rot 315°"));
        assert!(labels.contains("A zoom 0.5 tilt 4 @0.0° + B rot 45°"));
        assert!(!labels.contains("B tilt 4 @0.0° + A rot 45°"));
        assert!(!labels.contains("A tilt 2 @0.0° + B rot 45°"));
        assert!(labels.contains("A zoom 0.5 tilt 4 @112.5° + B rot 270°"));
        assert!(labels.contains("B zoom 0.5 tilt 4 @0.0°"));
        assert!(labels.contains("B zoom 2 tile [0.5, 0.25; 1, 0.75] + A zoom 0.5"));
        assert!(labels.contains("A zoom 3 tile [0.33, 0; 0.67, 0.33]"));
        assert!(labels.contains("B zoom 3 tile [0, 0.67; 0.33, 1]"));
    }

    #[test]
    fn every_view_maps_plane_acs_back_exactly_and_magnified_tiles_show_their_window() {
        use affcorr_geom::homography::ac_from_homography;
        use affcorr_geom::{AffineCorrespondence, Mat2, Vec2};
        use affcorr_image::{GrayImage, ac_from_views, warp_image};
        let (w, h) = (640usize, 480usize);
        // A smooth texture (periods of 60-90 px), so that bilinear sampling is near exact.
        let texture = |x: f64, y: f64| ((x / 13.0).sin() * (y / 11.0).cos() + 1.0) as f32 * 0.5;
        let data = (0..w * h)
            .map(|i| texture((i % w) as f64, (i / w) as f64))
            .collect();
        let img = GrayImage::new(w, h, data).unwrap();
        // A perspective plane between A and B (both w × h).
        let plane = Mat3::new(0.9, 0.08, 25.0, -0.05, 1.1, 12.0, 1e-4, -6e-5, 1.0);
        let linear = |w: &AffineWarp| Mat2::new(w.m[0], w.m[1], w.m[2], w.m[3]);
        let mut tiles = 0;
        for view in candidate_views() {
            let label = view.label();
            let [a_warp, b_warp] = view.warps((w, h), (w, h));
            let wa = a_warp.map_or(AffineWarp::IDENTITY, |v| v.0);
            let wb = b_warp.map_or(AffineWarp::IDENTITY, |v| v.0);
            // An AC found between the views is the plane's AC seen through both warps:
            // x1' = Wa x1, x2' = Wb x2, A' = Wb A Wa⁻¹. Mapped back, it is the plane's.
            let ia = wa.inverse().unwrap();
            for (gx, gy) in [(40.0, 30.0), (320.0, 240.0), (600.0, 400.0), (150.0, 420.0)] {
                let ac = ac_from_homography(&plane, &Vec2::new(gx, gy), 0).unwrap();
                let truth = ac.to_row();
                let (p, q) = (wa.apply([gx, gy]), wb.apply([ac.x2.x, ac.x2.y]));
                let seen = AffineCorrespondence {
                    x1: Vec2::new(p[0], p[1]),
                    x2: Vec2::new(q[0], q[1]),
                    a: linear(&wb) * ac.a * linear(&ia),
                };
                let back = ac_from_views(&seen.to_row(), &wa, &wb).unwrap();
                for (got, want) in back.iter().zip(&truth) {
                    assert!(
                        (got - want).abs() < 1e-9,
                        "{label}: {back:?} against {truth:?}"
                    );
                }
            }
            // A magnified tile shows its window of the image: its pixels are the image's at
            // the warp's preimage, and they span the window's fraction of the image.
            let (Some(window), ViewImage::A) = (view.window, view.image) else {
                continue;
            };
            tiles += 1;
            let (warp, vw, vh) = a_warp.unwrap();
            let tile = warp_image(&img, &warp, vw, vh).unwrap();
            let [x0, y0, x1, y1] = window;
            let side = |lo: f64, hi: f64, n: usize| (hi - lo) * view.scale * n as f64;
            assert!(
                (vw as f64 - side(x0, x1, w)).abs() <= view.scale + 1.0,
                "{label}: {vw}"
            );
            assert!(
                (vh as f64 - side(y0, y1, h)).abs() <= view.scale + 1.0,
                "{label}: {vh}"
            );
            let inv = warp.inverse().unwrap();
            let corner = inv.apply([0.0, 0.0]);
            assert!(
                (corner[0] - x0 * w as f64).abs() <= 1.0
                    && (corner[1] - y0 * h as f64).abs() <= 1.0,
                "{label}: the tile starts at {corner:?}"
            );
            for (tx, ty) in [(5, 5), (vw / 2, vh / 3), (vw - 6, vh - 6)] {
                let [u, v] = inv.apply([tx as f64, ty as f64]);
                let (got, want) = (tile.get(tx, ty), texture(u, v));
                assert!(
                    (got - want).abs() < 0.01,
                    "{label} at ({tx}, {ty}): {got} against {want}"
                );
            }
        }
        // The half-size tiles (9) and the third-size tiles (9) of A.
        assert_eq!(tiles, 18);
    }

    #[test]
    fn the_relative_budget_counts_work_not_time() {
        // A VGA pair at 1024 keypoints with 300 ACs: about the default matcher's plain pass.
        let mut meter = WorkMeter::new(2 * 640 * 480, (1024, 1024), 300);
        let plain = meter.plain;
        assert!((500.0..800.0).contains(&plain), "{plain}");
        // A rotated view of B: its extraction (a VGA image), its screen, its matching and ACs.
        meter.extraction(640 * 480);
        meter.screen((1024, 1024));
        meter.matching((1024, 1024), 300);
        meter.verification();
        let view = meter.spent;
        assert!(view < plain && view > 0.6 * plain, "{view} of {plain}");
        assert!((meter.passes() - view / plain).abs() < 1e-12);
        // Fewer keypoints and ACs cost less; a quarter of the pixels a quarter of the work.
        let mut small = WorkMeter::new(2 * 640 * 480, (1024, 1024), 300);
        small.extraction(320 * 240);
        small.matching((512, 1024), 30);
        assert!(small.spent < 0.5 * view);
        // The budget: k plain passes of work, whatever the time taken; an absolute time
        // budget on top of it.
        let o = ViewOptions {
            relative_budget: Some(2.0),
            ..Default::default()
        };
        let long = Duration::from_secs(3600);
        assert!(o.within_budget(long, &meter));
        meter.spent = 2.0 * plain;
        assert!(!o.within_budget(Duration::ZERO, &meter));
        let unbounded = ViewOptions {
            relative_budget: None,
            ..Default::default()
        };
        assert!(unbounded.within_budget(long, &meter));
        let timed = ViewOptions {
            time_budget: Some(Duration::from_secs(1)),
            ..unbounded
        };
        assert!(!timed.within_budget(long, &meter));
    }

    #[test]
    fn a_weak_view_verified_before_the_rotations_is_rivalled_by_them() {
        let rotations = Step::Screened(rival_views());
        // 30 inliers of a 1024-keypoint budget: weak (under a tenth).
        assert!(rivalled_by_rotations(Some(&rotations), 30, 1024));
        // A strong yield ends the cascade.
        assert!(!rivalled_by_rotations(Some(&rotations), 150, 1024));
        // After the rotations ran (or for any other next step), nothing rivals it.
        let zoom = Step::View(ViewSpec::param(ViewImage::A, 0.0, 0.5, 1.0, 0.0));
        assert!(!rivalled_by_rotations(Some(&zoom), 30, 1024));
        assert!(!rivalled_by_rotations(None, 30, 1024));
        // Only the whole group of rotations counts as the rotations.
        let part = Step::Screened(rival_views()[..3].to_vec());
        assert!(!rivalled_by_rotations(Some(&part), 30, 1024));
    }

    #[test]
    fn a_screened_group_runs_the_views_above_its_noise() {
        // Experiment 4's steep tilt group of x-leuvenA-80 (scores sorted): three views above
        // twice the median.
        let mut s = vec![
            129, 98, 55, 13, 13, 12, 12, 11, 10, 10, 9, 9, 9, 8, 8, 8, 7, 7, 6, 5,
        ];
        assert_eq!(screen_run(&s), 3);
        // Nothing stands out: only the best runs; more than SCREEN_RUN stand out: SCREEN_RUN.
        s = vec![15, 14, 13, 12, 11, 10, 10];
        assert_eq!(screen_run(&s), 1);
        s = vec![90, 80, 70, 60, 50, 9, 9, 8, 8, 7, 7];
        assert_eq!(screen_run(&s), SCREEN_RUN);
        assert_eq!(screen_run(&[]), 0);
    }

    #[test]
    fn a_view_is_screened_shrunk_to_its_pixel_share_with_its_geometry_kept() {
        let (a, b) = ((640, 480), (600, 400));
        let share = |w: &ImageWarp, (sw, sh): (usize, usize)| {
            w.map_or(1.0, |(_, vw, vh)| (vw * vh) as f64 / (sw * sh) as f64)
        };
        // B turned by 90° against A as it is: both halved, A's side gaining a warp.
        let turned = ViewSpec::param(ViewImage::B, 90.0, 1.0, 1.0, 0.0);
        let full = turned.warps(a, b);
        let shrunk = screen_warps(&full, a, b);
        let (wa, aw, ah) = shrunk[0].unwrap();
        assert_eq!((aw, ah), (320, 240));
        assert_eq!(wa.m, [0.5, 0.0, 0.0, 0.5]);
        let (wb, bw, bh) = shrunk[1].unwrap();
        let (fb, ..) = full[1].unwrap();
        assert_eq!((bw, bh), (200, 300));
        // The same map, shrunk: a pixel of B lands where the full view puts it, halved.
        for p in [[0.0, 0.0], [599.0, 0.0], [123.0, 321.0]] {
            let (s, f) = (wb.apply(p), fb.apply(p));
            assert!((s[0] - 0.5 * f[0]).abs() < 1e-12 && (s[1] - 0.5 * f[1]).abs() < 1e-12);
        }
        // A turn by 45° (its view's box twice its pixels) is halved as the quarter turns are.
        let oblique = ViewSpec::param(ViewImage::B, 45.0, 1.0, 1.0, 0.0).warps(a, b);
        let (w45, ..) = screen_warps(&oblique, a, b)[1].unwrap();
        assert!((w45.min_singular_value() - 0.5).abs() < 1e-12);
        // A tilt 2 of A (half its pixels) against B as it is: B's share decides, and the tilt
        // shrinks by the same factor (else the screen would test another view): 1/4 across
        // the tilt, the most the screen may compress.
        let tilted = |t| ViewSpec::param(ViewImage::A, 0.0, 1.0, t, 0.0);
        let full = tilted(2.0).warps(a, b);
        let shrunk = screen_warps(&full, a, b);
        assert!((share(&shrunk[1], b) - SCREEN_PIXELS).abs() < 0.01);
        let (wa, ..) = shrunk[0].unwrap();
        assert!((wa.m[0] / full[0].unwrap().0.m[0] - 0.5).abs() < 1e-3);
        assert!((wa.min_singular_value() - SCREEN_MIN_SCALE).abs() < 1e-3);
        // A tilt of 4 is compressed by 1/4 already: screened as it runs.
        let full = tilted(4.0).warps(a, b);
        assert_eq!(screen_warps(&full, a, b), full);
        // Views whose images keep no more than their share already are screened as they run.
        let small = ViewSpec {
            other_scale: 0.5,
            ..ViewSpec::param(ViewImage::A, 0.0, 0.5, 1.0, 0.0)
        };
        let full = small.warps(a, b);
        assert_eq!(screen_warps(&full, a, b), full);
    }

    #[test]
    fn the_guided_view_undoes_the_dominant_map() {
        // B is A rotated by 120° and zoomed by 2: D = 2 R(120°); B is warped by D⁻¹.
        let (c, s) = (120f64.to_radians().cos(), 120f64.to_radians().sin());
        let row = [0.0, 0.0, 0.0, 0.0, 2.0 * c, -2.0 * s, 2.0 * s, 2.0 * c];
        let v = guided_view(&[row; 9]).unwrap();
        assert_eq!(v.image, ViewImage::B);
        let m = v.linear().m;
        let d = [row[4], row[5], row[6], row[7]];
        let prod = [
            m[0] * d[0] + m[1] * d[2],
            m[0] * d[1] + m[1] * d[3],
            m[2] * d[0] + m[3] * d[2],
            m[2] * d[1] + m[3] * d[3],
        ];
        for (p, want) in prod.iter().zip([1.0, 0.0, 0.0, 1.0]) {
            assert!((p - want).abs() < 1e-12);
        }
        // A shrinking map warps A instead; near-identity and too few ACs give no view.
        let half = [0.0, 0.0, 0.0, 0.0, 0.5, 0.0, 0.0, 0.5];
        assert_eq!(guided_view(&[half; 9]).unwrap().image, ViewImage::A);
        let id = [0.0, 0.0, 0.0, 0.0, 1.05, 0.0, 0.0, 0.98];
        assert!(guided_view(&[id; 9]).is_none() && guided_view(&[row; 7]).is_none());
    }
}
