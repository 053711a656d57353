//! [`Pipeline`]: the stages in order (see the crate docs), one pair or many. The view
//! cascade's driver is in the `cascade` submodule (pipeline/cascade.rs).

mod cascade;

use std::sync::OnceLock;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use affcorr_geom::Mat3;
use affcorr_geom::camera::Intrinsics;
use affcorr_image::affine_confidence;
use affcorr_image::{
    AffineRefineOptions, AffineWarp, GrayImage, ac_from_views, ac_to_original, extract_named,
    limit_side, refine_affine,
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
use crate::views::{ViewMode, ViewOptions, verified_fundamental, verify_affine_weight, weak_yield};

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
