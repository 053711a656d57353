//! [`Pipeline`]: the stages in order (see the crate docs), one pair or many.

use std::collections::{HashMap, HashSet, VecDeque};
use std::rc::Rc;
use std::sync::OnceLock;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use affcorr_geom::Mat3;
use affcorr_geom::camera::Intrinsics;
use affcorr_image::affine_confidence;
use affcorr_image::{
    AffineRefineOptions, AffineWarp, GrayImage, ac_from_views, ac_to_original, extract_named,
    limit_side, refine_affine, warp_image,
};
use affcorr_ransac::options::Cancel;
use affcorr_ransac::problems::relpose::PoseModel;
use affcorr_ransac::{
    Correspondences, Estimate, EstimatorOptions, SamplerKind, estimate_fundamental,
    estimate_homography, estimate_relative_pose,
};
use affcorr_runner::{
    AlikedBackbone, Backbone, DenseMatcher, DiskBackbone, ImageFeatures, Matcher, PointMatcher,
    PointMatches, ShapeEstimator,
};

use crate::builder::PipelineBuilder;
use crate::error::{PipelineError, Result};
use crate::features::Features;
use crate::grow::{GrowOptions, grow};
use crate::result::{Estimated, Matches, Timings};
use crate::source::ImageSource;
use crate::views::{
    CONFIDENT_VIEW, REFINE_BELOW, RIVAL_MARGIN, Step, ViewMode, ViewOptions, ViewReport, ViewSpec,
    WorkMeter, cascade_steps, guided_view, planar_rival, planar_support, refinement_view,
    rival_views, rivalled_by_rotations, screen, screen_run, uncertain, verified_fundamental,
    verify, verify_affine_weight, weak_yield,
};

/// The most pixels the XFeat matchers take at the working resolution. Their memory grows with
/// the pixels, ≈160 MB per megapixel (benches/results/bad_input_scale.md: 12 MP 2.0 GB, 48 MP
/// 7.9 GB), so 64 MP is ≈10 GB; larger images would end in an out-of-memory abort instead of
/// an error.
pub const MAX_WORKING_PIXELS: usize = 64_000_000;

/// The smallest side the XFeat matchers take at the working resolution (their input multiple).
const MIN_WORKING_SIDE: usize = 32;

/// Refuses working images the matcher cannot take, naming the user's image size (and the
/// working one when `max_side` downscaled it).
fn check_working_size(original: &GrayImage, work: &GrayImage, what: &'static str) -> Result<()> {
    let (w, h) = (work.width(), work.height());
    let size = if (w, h) == (original.width(), original.height()) {
        format!("{w}×{h} pixels")
    } else {
        format!(
            "{}×{} pixels ({w}×{h} at the working resolution after max_side)",
            original.width(),
            original.height()
        )
    };
    if w.saturating_mul(h) > MAX_WORKING_PIXELS {
        return Err(PipelineError::invalid(
            what,
            format!(
                "{size} is over the matcher's limit of {} MP at the working resolution \
                 (≈160 MB per megapixel): set max_side (e.g. 4096)",
                MAX_WORKING_PIXELS / 1_000_000
            ),
        ));
    }
    if w.min(h) < MIN_WORKING_SIDE {
        return Err(PipelineError::invalid(
            what,
            format!(
                "{size} is too small: both sides must be at least {MIN_WORKING_SIDE} pixels \
                 at the working resolution"
            ),
        ));
    }
    Ok(())
}

/// Matcher, shape network and estimators in one object; `Send` and `Sync` (inference runs
/// under each model's mutex).
#[derive(Debug)]
pub struct Pipeline {
    pub(crate) matcher: PointMatcher,
    /// The matcher whose features screen the view cascade's groups, when not `matcher`
    /// ([`crate::defaults::view_screen`]).
    pub(crate) screener: Option<PointMatcher>,
    pub(crate) shape: ShapeEstimator,
    pub(crate) affine_refinement: Option<AffineRefineOptions>,
    pub(crate) drop_unreliable: bool,
    pub(crate) exif_orientation: bool,
    pub(crate) views: ViewOptions,
    pub(crate) guided_matching: Option<GrowOptions>,
    pub(crate) max_matches: Option<usize>,
    pub(crate) max_side: Option<usize>,
    pub(crate) threads: usize,
    pub(crate) pool: rayon::ThreadPool,
    /// What the pipeline was built from (for the single-threaded workers of `match_pairs`).
    pub(crate) config: PipelineBuilder,
    /// `threads` single-threaded copies for `match_pairs`, built on its first call (or the
    /// error that prevented it, as text: then batches run one pair after the other).
    pub(crate) workers: OnceLock<std::result::Result<Vec<Pipeline>, String>>,
}

/// A warped image of the cascade: the image (0: A, 1: B), the warp's bits and the view's size.
type WarpKey = (usize, [u64; 6], usize, usize);

fn warp_key(image: usize, w: &Option<(AffineWarp, usize, usize)>) -> Option<WarpKey> {
    w.map(|(warp, vw, vh)| {
        let [a, b, c, d] = warp.m.map(f64::to_bits);
        let [e, f] = warp.c.map(f64::to_bits);
        (image, [a, b, c, d, e, f], vw, vh)
    })
}

/// Whether a view's warped image is too small for the matchers (under 32 px a side): such
/// a view is skipped, neither side extracted.
fn too_small(w: &Option<(AffineWarp, usize, usize)>) -> bool {
    w.is_some_and(|(_, vw, vh)| vw.min(vh) < 32)
}

/// At most this many views guided by the ACs of earlier views, per pair.
const MAX_GUIDED_VIEWS: usize = 3;

/// ACs of two (working or view) images, before the map back to the original pixels.
struct WorkMatches {
    corrs: Vec<[f64; 8]>,
    certainty: Vec<f64>,
    affine_confidence: Vec<f64>,
    reliable: Vec<bool>,
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
        self.matcher.kind()
    }

    /// Keypoints (or semi-dense cells) per image; for a dense matcher the matches it draws.
    pub fn max_keypoints(&self) -> usize {
        self.matcher.max_keypoints()
    }

    /// The score a keypoint needs in the matcher's detector map (`None`: the matcher keeps no
    /// keypoints by score); see [`crate::PipelineBuilder::detection_threshold`].
    pub fn detection_threshold(&self) -> Option<f32> {
        self.matcher.detection_threshold()
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
        self.matcher.backbone()
    }

    /// The DISK backbone (`Some` for [`Matcher::DiskLightGlue`]).
    pub fn disk_backbone(&self) -> Option<&DiskBackbone> {
        self.matcher.disk_backbone()
    }

    /// The ALIKED backbone (`Some` for [`Matcher::AlikedLightGlue`]).
    pub fn aliked_backbone(&self) -> Option<&AlikedBackbone> {
        self.matcher.aliked_backbone()
    }

    /// The dense matcher (`Some` for [`Matcher::Dense`]).
    pub fn dense_matcher(&self) -> Option<&DenseMatcher> {
        self.matcher.dense_matcher()
    }

    /// The seed of the dense matcher's sampling.
    pub fn seed(&self) -> u64 {
        self.matcher.seed()
    }

    /// The view cascade's options.
    pub fn views(&self) -> &ViewOptions {
        &self.views
    }

    /// The matcher whose features screen the view cascade's groups ([`crate::views::screen`]):
    /// XFeat's for DISK, ALIKED and XFeat* when its backbone was found
    /// ([`crate::defaults::view_screen`]), else the pipeline's own.
    pub fn view_screen(&self) -> Matcher {
        self.screener
            .as_ref()
            .map_or(self.matcher.kind(), PointMatcher::kind)
    }

    /// Whether unreliable ACs are dropped ([`PipelineBuilder::drop_unreliable`]).
    pub fn drop_unreliable(&self) -> bool {
        self.drop_unreliable
    }

    /// Whether image files are matched upright, as their EXIF orientation shows them
    /// ([`PipelineBuilder::exif_orientation`]).
    pub fn exif_orientation(&self) -> bool {
        self.exif_orientation
    }

    /// The affine refinement's options (`None` when it is off).
    pub fn affine_refinement(&self) -> Option<&AffineRefineOptions> {
        self.affine_refinement.as_ref()
    }

    /// The view cascade's affine weight in verification, for this pipeline's ACs
    /// (`views::verify_affine_weight`).
    fn verify_weight(&self) -> f64 {
        verify_affine_weight(self.affine_refinement.is_some())
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

    /// [`Self::match_pair`] over many pairs; one result per pair, in order. A pair that fails
    /// (an unreadable image, too small for the matcher, ...) gets its error; the other pairs
    /// are unaffected.
    ///
    /// With `threads` > 1 the pairs run in parallel, one per thread, each on a single-threaded
    /// copy of the pipeline (ONNX Runtime and rayon with one thread; the copies are loaded on
    /// the first call and kept; at most one per core). On 2 cores shared with other work this
    /// gave 12–20 % more pairs per second than pairs one after the other with every thread per
    /// pair (benches/results/pipeline_timing.md). The results equal [`Self::match_pair`]'s.
    ///
    /// An image in several pairs (the same path or the same buffer) is decoded and its
    /// features extracted once ([`Self::extract`]), kept until its last pair is matched
    /// ([`Self::match_features`]); each pair's timings still count the extraction of both its
    /// images.
    pub fn match_pairs<'a, A, B>(
        &self,
        pairs: impl IntoIterator<Item = (A, B)>,
    ) -> Vec<Result<Matches>>
    where
        A: Into<ImageSource<'a>>,
        B: Into<ImageSource<'a>>,
    {
        self.match_pairs_until(pairs, &Cancel::new())
            .into_iter()
            .map(|r| r.expect("nothing cancels this call"))
            .collect()
    }

    /// [`Self::match_pairs`] that stops starting pairs once `cancel` is set: each pair gets
    /// `Some(result)`, or `None` when it was not started because of the cancellation (the pairs
    /// already running finish).
    pub fn match_pairs_until<'a, A, B>(
        &self,
        pairs: impl IntoIterator<Item = (A, B)>,
        cancel: &Cancel,
    ) -> Vec<Option<Result<Matches>>>
    where
        A: Into<ImageSource<'a>>,
        B: Into<ImageSource<'a>>,
    {
        let pairs: Vec<(ImageSource<'a>, ImageSource<'a>)> = pairs
            .into_iter()
            .map(|(a, b)| (a.into(), b.into()))
            .collect();
        // More copies than cores only cost memory (each holds every model).
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        let copies = self.threads.min(cores);
        let workers = if copies > 1 && pairs.len() > 1 {
            match self.workers.get_or_init(|| {
                (0..copies)
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
        let cache = FeatureCache::new(&pairs);
        if workers.is_empty() {
            return (0..pairs.len())
                .map(|i| (!cancel.is_cancelled()).then(|| cache.match_pair(self, &pairs, i)))
                .collect();
        }
        let next = AtomicUsize::new(0);
        let mut results: Vec<Option<Result<Matches>>> = (0..pairs.len()).map(|_| None).collect();
        std::thread::scope(|scope| {
            let handles: Vec<_> = workers
                .iter()
                .take(pairs.len())
                .map(|w| {
                    let (next, pairs, cache) = (&next, &pairs, &cache);
                    scope.spawn(move || {
                        let mut done = Vec::new();
                        while !cancel.is_cancelled() {
                            let i = next.fetch_add(1, Ordering::Relaxed);
                            if i >= pairs.len() {
                                break;
                            }
                            done.push((i, cache.match_pair(w, pairs, i)));
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
    }

    /// The homography p2 ~ H p1 (original pixels) of an image pair: [`Self::match_pair`], then
    /// [`estimate_homography`] on the ACs with `options`.
    pub fn homography<'a>(
        &self,
        image_a: impl Into<ImageSource<'a>>,
        image_b: impl Into<ImageSource<'a>>,
        options: &EstimatorOptions,
    ) -> Result<Estimated<Mat3>> {
        self.estimate(
            self.match_pair(image_a, image_b)?,
            options,
            estimate_homography,
        )
    }

    /// The fundamental matrix p2ᵀ F p1 = 0 (original pixels) of an image pair:
    /// [`Self::match_pair`], then [`estimate_fundamental`] on the ACs with `options`.
    pub fn fundamental<'a>(
        &self,
        image_a: impl Into<ImageSource<'a>>,
        image_b: impl Into<ImageSource<'a>>,
        options: &EstimatorOptions,
    ) -> Result<Estimated<Mat3>> {
        self.estimate(
            self.match_pair(image_a, image_b)?,
            options,
            estimate_fundamental,
        )
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
    ) -> Result<Estimated<PoseModel>> {
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
    ) -> Result<Estimated<M>> {
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
        let fa = self.extract_inner(a, "image_a")?;
        let fb = self.extract_inner(b, "image_b")?;
        let mut m = self.match_features_inner(&fa, &fb)?;
        m.timings.total = start.elapsed();
        Ok(m)
    }

    /// The features of one image ([`Features`]): decoded, downscaled to `max_side`, and the
    /// matcher's keypoints and descriptors (a dense matcher keeps the colour image). Matching
    /// two with [`Self::match_features`] gives [`Self::match_pair`]'s result, bit for bit.
    pub fn extract<'a>(&self, image: impl Into<ImageSource<'a>>) -> Result<Features> {
        let image = image.into();
        self.pool.install(|| self.extract_inner(image, "image"))
    }

    /// The ACs of two images' features ([`Self::extract`] of this pipeline, or of one built
    /// with the same matcher, models and options): [`Self::match_pair`]'s result, bit for bit,
    /// but for the timings, which count each image's extraction as well (`decode`, `matcher`,
    /// `detection`).
    pub fn match_features(&self, a: &Features, b: &Features) -> Result<Matches> {
        self.pool.install(|| self.match_features_inner(a, b))
    }

    pub(crate) fn extract_inner(
        &self,
        src: ImageSource<'_>,
        what: &'static str,
    ) -> Result<Features> {
        let mut t = Instant::now();
        let dense = self.matcher() == Matcher::Dense;
        let upright = self.exif_orientation;
        let (img, colour, orientation) = if dense {
            let (g, c, o) = src
                .load_with_colour(upright)
                .map_err(|e| PipelineError::image(e, what))?;
            (g, Some(c), o)
        } else {
            let (g, o) = src
                .load(upright)
                .map_err(|e| PipelineError::image(e, what))?;
            (g, None, o)
        };
        let (work, scale) = limit_side(&img, self.max_side);
        if !dense {
            check_working_size(&img, &work, what)?;
        }
        // The size as stored: every coordinate is reported in the stored pixels.
        let original_size = if orientation.swaps_axes() {
            (img.height(), img.width())
        } else {
            (img.width(), img.height())
        };
        let work = match work {
            std::borrow::Cow::Owned(w) => w,
            std::borrow::Cow::Borrowed(_) => img.into_owned(),
        };
        let decode = elapsed(&mut t);
        let matcher = self.matcher.extract(&work, colour.as_ref())?;
        Ok(Features {
            work,
            scale,
            orientation,
            original_size,
            matcher,
            max_keypoints: self.max_keypoints(),
            detection_threshold: self.detection_threshold(),
            max_side: self.max_side,
            decode,
        })
    }

    pub(crate) fn match_features_inner(&self, fa: &Features, fb: &Features) -> Result<Matches> {
        let start = Instant::now();
        for (f, what) in [(fa, "features_a"), (fb, "features_b")] {
            if f.matcher() != self.matcher()
                || f.max_keypoints != self.max_keypoints()
                || f.detection_threshold != self.detection_threshold()
                || f.max_side != self.max_side
            {
                return Err(PipelineError::invalid(
                    what,
                    format!(
                        "extracted with matcher {}, max_keypoints {}, detection_threshold \
                         {:?}, max_side {:?}; this pipeline has {}, {}, {:?}, {:?}",
                        f.matcher(),
                        f.max_keypoints,
                        f.detection_threshold,
                        f.max_side,
                        self.matcher(),
                        self.max_keypoints(),
                        self.detection_threshold(),
                        self.max_side
                    ),
                ));
            }
        }
        let mut timings = Timings {
            decode: fa.decode + fb.decode,
            ..Timings::default()
        };
        let dense = self.matcher() == Matcher::Dense;
        let (work_a, work_b) = (&fa.work, &fb.work);
        let raw = self.matcher.match_features(&fa.matcher, &fb.matcher)?;
        let plain = self.match_working(work_a, work_b, raw, &mut timings)?;
        let (work, views) = if dense || self.views.mode == ViewMode::Off {
            (plain, Vec::new())
        } else {
            let t = Instant::now();
            let r = self.view_cascade(
                plain,
                [(work_a, &fa.matcher), (work_b, &fb.matcher)],
                &mut timings,
            )?;
            timings.views += t.elapsed();
            r
        };
        // Guided re-matching when asked for, and after the cascade when the pass it kept
        // verified with a weak yield (`views::weak_yield`): a steep tilt's few matches cluster
        // in a band of the overlap, and H extrapolates from them tens of pixels off
        // (benches/results/eval/extreme_varied.md); grown from them, the matches spread over
        // the plane.
        let weak_kept = views
            .iter()
            .any(|v| v.used && v.verified && weak_yield(v.inliers, self.max_keypoints()));
        let grow_options = self
            .guided_matching
            .clone()
            .or_else(|| weak_kept.then(GrowOptions::default));
        let work = match &grow_options {
            Some(o) if !dense => {
                let t = Instant::now();
                let w = self.guided(work, work_a, work_b, &fa.matcher, o)?;
                timings.guided += t.elapsed();
                w
            }
            _ => work,
        };
        // Working pixels to the upright originals, then back into the stored pixels of an
        // image that was turned upright (its EXIF orientation): exact, a signed permutation.
        let stored = match (fa.upright_warp(), fb.upright_warp()) {
            (None, None) => None,
            (wa, wb) => Some((
                wa.unwrap_or(AffineWarp::IDENTITY),
                wb.unwrap_or(AffineWarp::IDENTITY),
            )),
        };
        let corrs = work
            .corrs
            .iter()
            .map(|row| {
                let row = ac_to_original(row, fa.scale, fb.scale);
                stored.map_or(row, |(wa, wb)| {
                    ac_from_views(&row, &wa, &wb)
                        .expect("an orientation's warp is a signed permutation")
                })
            })
            .collect();
        timings.total = start.elapsed() + fa.extraction_time() + fb.extraction_time();
        tracing::debug!(
            matcher = %self.matcher(),
            acs = work.corrs.len(),
            views = views.len(),
            "matched a pair: {timings}"
        );
        let mut matches = Matches {
            corrs,
            certainty: work.certainty,
            affine_confidence: work.affine_confidence,
            reliable: work.reliable,
            num_keypoints: work.num_keypoints,
            timings,
            views,
        };
        if self.drop_unreliable {
            matches.retain_reliable();
        }
        Ok(matches)
    }

    /// Guided re-matching ([`crate::grow`]) of `work`: when its matches verify, the ACs grown
    /// from the verified ones to the unmatched keypoints of image A (`features_a`) are
    /// appended, with the certainty of the AC each grew from.
    fn guided(
        &self,
        mut work: WorkMatches,
        work_a: &GrayImage,
        work_b: &GrayImage,
        features_a: &ImageFeatures,
        options: &GrowOptions,
    ) -> Result<WorkMatches> {
        let Some((f, mask)) = verified_fundamental(&work.corrs, self.verify_weight())? else {
            return Ok(work);
        };
        let o = &self.views;
        let inliers = mask.iter().filter(|m| **m).count();
        if inliers < o.min_inliers || (inliers as f64) < o.min_inlier_ratio * mask.len() as f64 {
            return Ok(work);
        }
        let index: Vec<usize> = (0..mask.len()).filter(|&i| mask[i]).collect();
        let seeds: Vec<[f64; 8]> = index.iter().map(|&i| work.corrs[i]).collect();
        let grown = grow(
            work_a,
            work_b,
            &seeds,
            &work.corrs,
            features_a.keypoints(),
            &f,
            options,
        )?;
        tracing::debug!(
            seeds = seeds.len(),
            grown = grown.corrs.len(),
            "guided re-matching"
        );
        for (k, row) in grown.corrs.iter().enumerate() {
            work.corrs.push(*row);
            work.certainty.push(work.certainty[index[grown.seed[k]]]);
            work.affine_confidence.push(grown.affine_confidence[k]);
            work.reliable.push(true);
        }
        Ok(work)
    }

    /// The matcher's features of both sides of a view with `warps` (A's, B's): the plain
    /// pass's for a side the view leaves as it is, else those of its warp, extracted once per
    /// pair (`store`); `None` when a warp is too small for the matcher. An extraction here is
    /// timed into `timings`; the matching of a view subtracts its features' extraction times.
    fn view_features(
        &self,
        store: &mut ViewFeatures<'_>,
        warps: &[Option<(AffineWarp, usize, usize)>; 2],
        timings: &mut Timings,
    ) -> Result<Option<[Rc<ImageFeatures>; 2]>> {
        store.pair(&self.matcher, false, warps, timings)
    }

    /// The features that screen a view ([`crate::views::screen`]): the screener's where the
    /// pipeline has one, else the matcher's ([`Self::view_features`]).
    fn screen_features(
        &self,
        store: &mut ViewFeatures<'_>,
        warps: &[Option<(AffineWarp, usize, usize)>; 2],
        timings: &mut Timings,
    ) -> Result<Option<[Rc<ImageFeatures>; 2]>> {
        match &self.screener {
            Some(screener) => store.pair(screener, true, warps, timings),
            None => self.view_features(store, warps, timings),
        }
    }

    /// Patches, shape network and refinement on the matches `raw` of two images (the working
    /// images, or synthetic views of them): ACs in those images' pixels, most certain first.
    fn match_working(
        &self,
        work_a: &GrayImage,
        work_b: &GrayImage,
        raw: PointMatches,
        timings: &mut Timings,
    ) -> Result<WorkMatches> {
        timings.decode += raw.timings.preprocess;
        timings.matcher += raw.timings.network;
        timings.detection += raw.timings.detection;
        timings.matching += raw.timings.matching;
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

        let patch_a = extract_named(work_a, &x1, "x1")?;
        let patch_b = extract_named(work_b, &x2, "x2")?;
        timings.patches += elapsed(&mut t);

        let prediction = self.shape.model().predict(&patch_a, &patch_b)?;
        let mut corrs: Vec<[f64; 8]> = prediction
            .affine()?
            .iter()
            .zip(x1.iter().zip(&x2))
            .map(|(m, (p, q))| [p[0], p[1], q[0], q[1], m[0], m[1], m[2], m[3]])
            .collect();
        timings.shape_net += elapsed(&mut t);
        // Every AC is scored: a failed refinement returns the network's A, flagged unreliable.
        let spread = prediction.spread();
        let confidence = if let Some(options) = &self.affine_refinement {
            let r = refine_affine(work_a, work_b, &corrs, options)?;
            let c = affine_confidence(&r.corrs, Some(&spread), Some(&r))?;
            corrs = r.corrs;
            timings.affine_refine += elapsed(&mut t);
            c
        } else {
            affine_confidence(&corrs, Some(&spread), None)?
        };
        Ok(WorkMatches {
            corrs,
            certainty,
            affine_confidence: confidence.confidence,
            reliable: confidence.reliable,
            num_keypoints: raw.num_keypoints,
        })
    }

    /// The view cascade (see [`crate::views`]) after the plain pass `plain`: the matches of the
    /// first view that verifies (or, in full mode, of the view with the most inliers), in the
    /// working images' pixels, and a report per view. The stages of the synthetic views are
    /// timed into `timings` too.
    fn view_cascade(
        &self,
        plain: WorkMatches,
        [(work_a, features_a), (work_b, features_b)]: [(&GrayImage, &ImageFeatures); 2],
        timings: &mut Timings,
    ) -> Result<(WorkMatches, Vec<ViewReport>)> {
        let o = &self.views;
        let start = Instant::now();
        // The plain pass's work: both extractions, their matching and its ACs.
        let mut meter = WorkMeter::new(
            work_a.width() * work_a.height() + work_b.width() * work_b.height(),
            (features_a.len(), features_b.len()),
            plain.corrs.len(),
        );
        let passes = |inliers: usize, n: usize| {
            inliers >= o.min_inliers && inliers as f64 >= o.min_inlier_ratio * n as f64
        };
        let (inliers, mask) = verify(&plain.corrs, self.verify_weight())?;
        meter.verification();
        let verified = passes(inliers, plain.corrs.len());
        let mut reports = vec![ViewReport {
            view: ViewSpec::PLAIN,
            matches: plain.corrs.len(),
            inliers,
            verified,
            screen: None,
            time: start.elapsed(),
            work: 1.0,
            started: 0.0,
            screen_extraction: 0.0,
            used: false,
        }];
        // The meter's reading at the last report (the plain pass's verification is the plain
        // pass's): a view's work is what was spent since.
        let mut reported = meter.spent;
        // A weak verification (few of the matches agree) may be a repetitive pattern matched
        // at the wrong rotation: the rotated views are its rivals (see `defaults::weak_ratio`).
        // So may one verified by few inliers (`views::WEAK_YIELD`), or by matches the
        // matcher is unsure of (`views::uncertain`).
        let weak = verified
            && ((inliers as f64)
                < crate::defaults::weak_ratio(self.matcher()) * plain.corrs.len() as f64
                || weak_yield(inliers, self.max_keypoints())
                || uncertain(
                    &plain.certainty,
                    crate::defaults::rival_certainty(self.matcher()),
                ));
        if verified && !weak && o.mode == ViewMode::Auto {
            reports[0].used = true;
            return Ok((plain, reports));
        }
        let mut rival_floor = if weak && o.mode == ViewMode::Auto {
            (RIVAL_MARGIN * inliers as f64).ceil() as usize
        } else {
            0
        };
        tracing::info!(
            matches = plain.corrs.len(),
            inliers,
            weak,
            "the plain pair does not verify (or only weakly): trying synthetic views"
        );
        let inlier_acs: Vec<[f64; 8]> = plain
            .corrs
            .iter()
            .zip(&mask)
            .filter(|(_, m)| **m)
            .map(|(r, _)| *r)
            .collect();
        let mut queue: VecDeque<(ViewSpec, Option<usize>)> = VecDeque::new();
        // A weak plain pass verified by so few inliers that a synthetic view would not end the
        // cascade on them (`views::CONFIDENT_VIEW`) is judged as such a view: kept, and every
        // view rivals it, not only the rotations. A steep tilt verifies like this, with a
        // dozen or two matches in a corner of the overlap. Its AC-guided view comes right
        // after the rotations, which rival it first: a repetitive pattern matched at the
        // wrong rotation guides to a wrong view that verifies too (views_pose lost chessboard
        // and stereo pairs at 90–180° with the guide first). A failed plain pass's guide
        // comes first. A weak pass with more inliers is rivalled by the rotations and then
        // by its guide too: a tilt of 70° verifies the plain pass with a few dozen matches
        // in a band of the overlap, and the view that undoes their map finds the plane
        // (benches/results/eval/extreme_varied.md).
        let mut rivals_only = rival_floor > 0 && inliers >= CONFIDENT_VIEW * o.min_inliers;
        let mut steps: VecDeque<Step> = if rivals_only {
            VecDeque::from([Step::Screened(rival_views())])
        } else {
            cascade_steps().into()
        };
        if let Some(g) = guided_view(&inlier_acs) {
            steps.insert(usize::from(weak), Step::View(g));
        }
        // The views of screened groups past their best: tried once every step has run.
        let mut deferred: Vec<(f64, ViewSpec, Option<usize>)> = Vec::new();
        let (mut best, mut best_inliers) = (plain, if verified { inliers } else { 0 });
        // The kept pass's `views::planar_support`, once a rival needs it.
        let mut best_planar: Option<usize> = None;
        let mut best_index = 0;
        // A view whose matches partly agree (too few to verify) guides the next one: the
        // dominant map of its agreeing ACs, in the original images, is undone first.
        let (mut guide_inliers, mut guided) = (inlier_acs.len(), 0);
        let mut tried = 0;
        // A verified view's refinement is queued: the cascade stops after it.
        let mut refining = false;
        let sizes = (
            (work_a.width(), work_a.height()),
            (work_b.width(), work_b.height()),
        );
        // Views share warps (the tilts of A against B's rotations, the tiles against one zoom
        // of the other image): each warped image's features are extracted once per pair.
        let mut store = ViewFeatures {
            images: [work_a, work_b],
            matcher: FeatureStore {
                plain: [
                    Some(Rc::new(features_a.clone())),
                    Some(Rc::new(features_b.clone())),
                ],
                warped: HashMap::new(),
            },
            screen: FeatureStore::default(),
            charged: HashSet::new(),
            meter,
        };
        // The time a group's screen took, counted in the first view it runs.
        let mut screen_time = Duration::ZERO;
        // The extractions of the screens since the last view, reported with the next one.
        let mut screen_extraction = 0.0;
        loop {
            if tried >= o.max_views || !o.within_budget(start.elapsed(), &store.meter) {
                break;
            }
            let (view, screen_score) = if let Some(v) = queue.pop_front() {
                v
            } else if let Some(step) = steps.pop_front() {
                let ranked_only = matches!(step, Step::Ranked(_));
                match step {
                    Step::View(v) => (v, None),
                    Step::Screened(group) | Step::Ranked(group) => {
                        // A screen that no view could follow within the budget is not paid
                        // for: skipped when its extractions (most of a group's cost) would
                        // reach the budget, and its screens when they would. The cascade
                        // stops there, as it would after the screen: the same views run.
                        let extracted = store.after_extraction(&group, sizes);
                        if !o.within_budget(start.elapsed(), &extracted) {
                            break;
                        }
                        let (t, before) = (Instant::now(), store.meter.spent);
                        let mut features = Vec::with_capacity(group.len());
                        for v in group {
                            let warps = v.warps(sizes.0, sizes.1);
                            if let Some(f) = self.screen_features(&mut store, &warps, timings)? {
                                features.push((v, f));
                            }
                        }
                        debug_assert_eq!(store.meter, extracted);
                        screen_extraction += store.meter.in_passes(store.meter.spent - before);
                        let mut screened = store.meter.clone();
                        for (_, [fa, fb]) in &features {
                            screened.screen((fa.len(), fb.len()));
                        }
                        if !o.within_budget(start.elapsed(), &screened) {
                            break;
                        }
                        store.meter = screened;
                        let mut scored = Vec::with_capacity(features.len());
                        for (v, [fa, fb]) in features {
                            scored.push((v, Some(screen(&fa, &fb)?)));
                        }
                        // Best first (stable: ties keep the steps' order).
                        scored.sort_by_key(|(_, s)| std::cmp::Reverse(*s));
                        let scores: Vec<usize> = scored.iter().filter_map(|v| v.1).collect();
                        // A ranked group runs whole, best-screened first.
                        let run = if ranked_only {
                            scored.len()
                        } else {
                            screen_run(&scores)
                        };
                        let rest = scored.split_off(run);
                        queue.extend(scored);
                        // Deferred views wait ranked by their screen over their group's noise;
                        // a weakly verified pair's rivals that do not stand out are dropped:
                        // they only check the plain pass, which is kept.
                        let noise = scores.get(scores.len() / 2).map_or(1, |&n| n.max(1));
                        deferred.extend(
                            rest.into_iter()
                                .filter(|_| !rivals_only)
                                .map(|(v, s)| (s.unwrap_or(0) as f64 / noise as f64, v, s)),
                        );
                        screen_time += t.elapsed();
                        continue;
                    }
                }
            } else if !deferred.is_empty() {
                // Best first across the groups (stable: ties keep the steps' order).
                deferred.sort_by(|a, b| b.0.total_cmp(&a.0));
                queue.extend(deferred.drain(..).map(|(_, v, s)| (v, s)));
                continue;
            } else {
                break;
            };
            tried += 1;
            let started = store.meter.passes();
            let t = Instant::now();
            let warps = view.warps(sizes.0, sizes.1);
            let [a_warp, b_warp] = warps;
            let Some([fa, fb]) = self.view_features(&mut store, &warps, timings)? else {
                // A view too small for the matcher is skipped, not an error of the pair.
                continue;
            };
            let mut raw = self.matcher.match_features(&fa, &fb)?;
            // The features were timed where they were extracted (the plain pass, this view's
            // warp or an earlier view's): only the matching is this view's.
            for f in [&fa, &fb] {
                raw.timings.preprocess -= f.timings.preprocess;
                raw.timings.network -= f.timings.network;
                raw.timings.detection -= f.timings.detection;
            }
            let warped = |img: &GrayImage, w: &Option<(AffineWarp, usize, usize)>| {
                w.map(|(warp, vw, vh)| warp_image(img, &warp, vw, vh))
                    .transpose()
            };
            let (va, vb) = (warped(work_a, &a_warp)?, warped(work_b, &b_warp)?);
            let (va, vb) = (va.as_ref().unwrap_or(work_a), vb.as_ref().unwrap_or(work_b));
            let m = self.match_working(va, vb, raw, timings)?;
            store.meter.matching((fa.len(), fb.len()), m.corrs.len());
            let (wa, wb) = (
                a_warp.map_or(AffineWarp::IDENTITY, |w| w.0),
                b_warp.map_or(AffineWarp::IDENTITY, |w| w.0),
            );
            let corrs: Vec<[f64; 8]> = m
                .corrs
                .iter()
                .filter_map(|row| ac_from_views(row, &wa, &wb))
                .collect();
            let (inliers, mask) = verify(&corrs, self.verify_weight())?;
            store.meter.verification();
            let verified = passes(inliers, corrs.len());
            let agreeing: Vec<[f64; 8]> = corrs
                .iter()
                .zip(&mask)
                .filter(|(_, m)| **m)
                .map(|(r, _)| *r)
                .collect();
            if !verified
                && inliers > guide_inliers
                && guided < MAX_GUIDED_VIEWS
                && let Some(g) = guided_view(&agreeing)
            {
                queue.push_front((g, None));
                (guide_inliers, guided) = (inliers, guided + 1);
            }
            tracing::debug!(
                view = %view.label(),
                matches = corrs.len(),
                inliers,
                verified,
                "view cascade"
            );
            reports.push(ViewReport {
                view,
                matches: corrs.len(),
                inliers,
                verified,
                screen: screen_score,
                time: t.elapsed() + std::mem::take(&mut screen_time),
                work: store.meter.in_passes(store.meter.spent - reported),
                started,
                screen_extraction: std::mem::take(&mut screen_extraction),
                used: false,
            });
            reported = store.meter.spent;
            // Short of the rival margin, a view that outnumbers the kept pass wins by one plane's
            // support instead (`views::planar_rival`); the kept pass's is computed once.
            let outnumbers = verified && inliers > best_inliers;
            let better = outnumbers
                && (inliers >= rival_floor || {
                    let kept = match best_planar {
                        Some(k) => k,
                        None => *best_planar.insert(planar_support(&best.corrs)?),
                    };
                    planar_rival(planar_support(&corrs)?, kept)
                });
            if better {
                best_index = reports.len() - 1;
                best_inliers = inliers;
                best = WorkMatches { corrs, ..m };
                best_planar = None;
            }
            if o.mode == ViewMode::Auto && (better || refining) {
                // Few inliers (in number, or for the keypoint budget, as `views::WEAK_YIELD`
                // judges the plain pass): the view that undoes their map exactly may find many
                // more.
                let few = inliers < REFINE_BELOW * o.min_inliers
                    || weak_yield(inliers, self.max_keypoints());
                if better
                    && !refining
                    && few
                    && let Some(r) = refinement_view(&view, &agreeing)
                {
                    queue.push_front((r, None));
                    refining = true;
                    continue;
                }
                refining = false;
                if best_inliers >= CONFIDENT_VIEW * o.min_inliers {
                    if !rivalled_by_rotations(steps.front(), best_inliers, self.max_keypoints()) {
                        break;
                    }
                    // Verified weakly before the rotations ran: they rival it, and only they
                    // (their views that do not stand out dropped, as for a weak plain pass).
                    steps.truncate(1);
                    rivals_only = true;
                }
                // A weak proof (`views::CONFIDENT_VIEW`): kept, and rivalled by the views left.
                rival_floor = rival_floor.max((RIVAL_MARGIN * best_inliers as f64).ceil() as usize);
            }
        }
        // Work spent after the last view (a group's extractions whose screens would have
        // reached the budget; a screen the time budget cut short) is the last view's, the
        // plain pass's when no view ran: the views' work sums to the pair's.
        if let Some(last) = reports.last_mut() {
            last.work += store.meter.in_passes(store.meter.spent - reported);
        }
        reports[best_index].used = true;
        tracing::debug!(
            views = reports.len() - 1,
            plain_passes = store.meter.passes(),
            "view cascade's work"
        );
        Ok((best, reports))
    }
}

/// The features of a pair's synthetic views: the working images, the matcher's features and
/// the screener's (each image extracted once per pair by each), and the cascade's work meter
/// that the extractions are charged to.
struct ViewFeatures<'a> {
    images: [&'a GrayImage; 2],
    matcher: FeatureStore,
    /// The screener's, when the pipeline has one ([`Pipeline::screener`]).
    screen: FeatureStore,
    /// The warped images whose extraction the meter has counted. Each counts once, whichever
    /// extractor comes first: the meter counts the default matcher's work (see
    /// `views::WorkMeter`), and a screener's extraction is a small part of a slow matcher's.
    charged: HashSet<WarpKey>,
    meter: WorkMeter,
}

/// One extractor's features of a pair's images: of the working images (`None` until
/// extracted) and of their warps.
#[derive(Default)]
struct FeatureStore {
    plain: [Option<Rc<ImageFeatures>>; 2],
    warped: HashMap<WarpKey, Rc<ImageFeatures>>,
}

impl ViewFeatures<'_> {
    /// `extractor`'s features of both sides of a view with `warps` ([`Self::side`]).
    fn pair(
        &mut self,
        extractor: &PointMatcher,
        screen: bool,
        warps: &[Option<(AffineWarp, usize, usize)>; 2],
        timings: &mut Timings,
    ) -> Result<Option<[Rc<ImageFeatures>; 2]>> {
        if warps.iter().any(too_small) {
            return Ok(None);
        }
        let fa = self.side(extractor, screen, 0, &warps[0], timings)?;
        let fb = self.side(extractor, screen, 1, &warps[1], timings)?;
        Ok(Some([fa, fb]))
    }

    /// The meter as `group`'s screen (its views on images of `sizes`) will leave it once it
    /// has extracted the warped images that no extractor has yet: each charged in the order
    /// the screen extracts them, so that the reading is the one the screen leaves.
    fn after_extraction(
        &self,
        group: &[ViewSpec],
        sizes: ((usize, usize), (usize, usize)),
    ) -> WorkMeter {
        let mut meter = self.meter.clone();
        let mut new = HashSet::new();
        for v in group {
            let warps = v.warps(sizes.0, sizes.1);
            if warps.iter().any(too_small) {
                continue;
            }
            for (image, w) in warps.iter().enumerate() {
                if let (Some((_, vw, vh)), Some(key)) = (w, warp_key(image, w))
                    && !self.charged.contains(&key)
                    && new.insert(key)
                {
                    meter.extraction(vw * vh);
                }
            }
        }
        meter
    }

    /// `extractor`'s features (the screener's store when `screen`) of image `image` (0: A,
    /// 1: B) under `warp` (not [`too_small`]), extracted on first use. A warped image's first
    /// extraction is charged to the meter; the screener's features of a working image are
    /// not (the plain pass's extractions were).
    fn side(
        &mut self,
        extractor: &PointMatcher,
        screen: bool,
        image: usize,
        warp: &Option<(AffineWarp, usize, usize)>,
        timings: &mut Timings,
    ) -> Result<Rc<ImageFeatures>> {
        let store = if screen {
            &mut self.screen
        } else {
            &mut self.matcher
        };
        let (Some((w, vw, vh)), Some(key)) = (warp, warp_key(image, warp)) else {
            if let Some(f) = &store.plain[image] {
                return Ok(f.clone());
            }
            let f = Rc::new(extract_timed(extractor, self.images[image], timings)?);
            store.plain[image] = Some(f.clone());
            return Ok(f);
        };
        if let Some(hit) = store.warped.get(&key) {
            return Ok(hit.clone());
        }
        let view = warp_image(self.images[image], w, *vw, *vh)?;
        let f = Rc::new(extract_timed(extractor, &view, timings)?);
        if self.charged.insert(key) {
            self.meter.extraction(vw * vh);
        }
        store.warped.insert(key, f.clone());
        Ok(f)
    }
}

/// `extractor`'s features of `image`, their stages timed into `timings`.
fn extract_timed(
    extractor: &PointMatcher,
    image: &GrayImage,
    timings: &mut Timings,
) -> Result<ImageFeatures> {
    let f = extractor.extract(image, None)?;
    timings.decode += f.timings.preprocess;
    timings.matcher += f.timings.network;
    timings.detection += f.timings.detection;
    Ok(f)
}

/// The features of the images of a batch ([`Pipeline::match_pairs`]), each extracted once
/// (by the first pair that needs it) and dropped after the last pair that uses it: an image
/// shared by k pairs costs one extraction instead of k. Images are the same when they are the
/// same path or the same buffer.
struct FeatureCache {
    /// The image index of each pair's A and B.
    index: Vec<(usize, usize)>,
    slots: Vec<std::sync::Mutex<Slot>>,
}

struct Slot {
    features: Option<std::sync::Arc<Features>>,
    /// Pairs (sides) still to use it.
    remaining: usize,
}

impl FeatureCache {
    fn new<'a>(pairs: &[(ImageSource<'a>, ImageSource<'a>)]) -> Self {
        #[derive(PartialEq, Eq, Hash)]
        enum Key<'a> {
            Path(&'a std::path::Path),
            Buffer(usize),
        }
        let key = |s: &ImageSource<'a>| -> Key<'a> {
            match *s {
                ImageSource::Path(p) => Key::Path(p),
                ImageSource::Image(img) => Key::Buffer(std::ptr::from_ref(img) as usize),
                ImageSource::Rgb(img) => Key::Buffer(std::ptr::from_ref(img) as usize),
            }
        };
        let mut ids = std::collections::HashMap::new();
        let mut uses: Vec<usize> = Vec::new();
        let mut id = |s| {
            let n = ids.len();
            let i = *ids.entry(key(s)).or_insert(n);
            if i == uses.len() {
                uses.push(0);
            }
            uses[i] += 1;
            i
        };
        let index = pairs.iter().map(|(a, b)| (id(a), id(b))).collect();
        let slots = uses
            .into_iter()
            .map(|remaining| {
                std::sync::Mutex::new(Slot {
                    features: None,
                    remaining,
                })
            })
            .collect();
        Self { index, slots }
    }

    fn slot(&self, i: usize) -> std::sync::MutexGuard<'_, Slot> {
        // A poisoned slot (a panic elsewhere) still holds valid data.
        self.slots[i]
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// The features of image `i` (`src`), extracted by `w` unless cached; errors are not
    /// cached (each pair reports its own).
    fn features(
        &self,
        w: &Pipeline,
        i: usize,
        src: ImageSource<'_>,
        what: &'static str,
    ) -> Result<std::sync::Arc<Features>> {
        let mut slot = self.slot(i);
        if let Some(f) = &slot.features {
            return Ok(f.clone());
        }
        let f = std::sync::Arc::new(w.pool.install(|| w.extract_inner(src, what))?);
        if slot.remaining > 1 {
            slot.features = Some(f.clone());
        }
        Ok(f)
    }

    fn release(&self, i: usize) {
        let mut slot = self.slot(i);
        slot.remaining = slot.remaining.saturating_sub(1);
        if slot.remaining == 0 {
            slot.features = None;
        }
    }

    /// Pair `k` on the pipeline `w`: [`Pipeline::match_pair`]'s result.
    fn match_pair(
        &self,
        w: &Pipeline,
        pairs: &[(ImageSource<'_>, ImageSource<'_>)],
        k: usize,
    ) -> Result<Matches> {
        let start = Instant::now();
        let (ia, ib) = self.index[k];
        let (a, b) = pairs[k];
        let r = self.features(w, ia, a, "image_a").and_then(|fa| {
            let fb = self.features(w, ib, b, "image_b")?;
            w.pool.install(|| w.match_features_inner(&fa, &fb))
        });
        self.release(ia);
        self.release(ib);
        r.map(|mut m| {
            m.timings.total = m.timings.total.max(start.elapsed());
            m
        })
    }
}
