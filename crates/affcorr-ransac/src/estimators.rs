//! The entry points: `estimate_homography`, `estimate_fundamental`, `estimate_relative_pose`,
//! and their `_batch` forms, which run many image pairs in parallel with rayon.
//!
//! They validate the input, pick the sample kind (ACs when the data carry them, unless told
//! otherwise), build the sampler and scoring from [`EstimatorOptions`], and run
//! [`crate::engine::estimate`].

use crate::engine::{Estimate, estimate, polish};
use crate::error::{RansacError, Result};
use crate::local_opt::LO_SCHEDULE;
use crate::options::{AffineRefinement, RansacOptions};
use crate::problem::Problem;
use crate::problems::fundamental::FundamentalProblem;
use crate::problems::homography::HomographyProblem;
use crate::problems::relpose::{PoseModel, RelativePoseProblem};
use crate::problems::{Correspondences, SampleKind, check_affine_weight, check_kind, epipolar_lm};
use crate::sampler::{ProsacSampler, UniformSampler};
use crate::score::{MagsacPlusPlus, Msac, Scoring};
use affcorr_geom::Mat3;
use affcorr_geom::camera::Intrinsics;
use affcorr_geom::epipolar::pose_from_essential;
use rayon::prelude::*;

/// How minimal samples are drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SamplerKind {
    /// Uniformly at random (default).
    #[default]
    Uniform,
    /// PROSAC, by decreasing [`EstimatorOptions::quality`].
    Prosac,
}

/// How models are scored.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ScoringKind {
    /// The measured best per problem (default): MSAC for every problem. On the scene families
    /// of benches/results/scene_families.md (pixel noise 0.25–2 px, affine noise 0–10%,
    /// 20–80% outliers, 1–8 planes, narrow and wide baselines) MSAC with the default affine
    /// terms is never far from the best candidate for F and the relative pose, where MAGSAC++
    /// (the default before) lost by up to 17× (relative pose) and 41× (F) and was no better on
    /// points; for H MSAC is within 1.07× of the best everywhere, MAGSAC++ up to 1.7× off.
    #[default]
    Auto,
    /// MSAC, the truncated quadratic.
    Msac,
    /// MAGSAC++ ([`MagsacPlusPlus`]): the σ-consensus++ loss marginalised over noise scales up
    /// to threshold/k; also the loss of local optimisation and of the final refinement.
    Magsac,
}

/// Options of every estimator. Defaults are documented at each field.
#[derive(Debug, Clone, Default)]
pub struct EstimatorOptions {
    /// The loop's options (threshold in pixels, confidence, iterations, seed, LO, refinement).
    pub ransac: RansacOptions,
    /// Minimal samples as points or ACs; `None` (default): ACs when the data carry them.
    pub sample: Option<SampleKind>,
    /// Uniform (default) or PROSAC sampling.
    pub sampler: SamplerKind,
    /// Per-correspondence quality for PROSAC (higher is better), e.g. matcher certainty.
    pub quality: Option<Vec<f64>>,
    /// Scoring function. Default [`ScoringKind::Auto`].
    pub scoring: ScoringKind,
    /// Weight λ (px²) of the affine residual in scoring; `Some(0.0)`: points only. `None`
    /// (default), for the fundamental matrix and the relative pose when the data carry A:
    /// [`DEFAULT_AFFINE_WEIGHT`], falling back to 0 when that shows A too poor
    /// ([`DEFAULT_AFFINE_FALLBACK`]), else the lower weight that the data show A's noise to
    /// allow (measured on the inliers of the first run, whose model is then polished at it); 0
    /// otherwise (H, points). The weight used is [`Estimate::affine_weight`]. See each
    /// problem's module for its units.
    pub affine_weight: Option<f64>,
    /// Per-AC confidence in [0, 1] of the affine part ((N, 8) data only): it scales each AC's
    /// affine term in scoring (with `affine_weight`) and in the refinements (with
    /// [`RansacOptions::affine_refinement`]); 0 makes an AC a point. `None` (default): all 1.
    pub affine_confidence: Option<Vec<f64>>,
}

/// The default weight λ (px²) of the affine residual in scoring F and relative poses from ACs:
/// the weight of "the affine part is accurate too" of the stopping rule (a circle of radius 10
/// px mapped by A, problems::SEED_AFFINE_WEIGHT). On the scene families
/// (benches/results/scene_families.md) it makes E on one plane and on narrow baselines, where
/// points fix it poorly, several times more accurate, at a small cost where A is noisy (10%);
/// H gains nothing from it. It cannot choose between a plane's two motions, which fit every AC
/// exactly ([`crate::planar`]).
pub const DEFAULT_AFFINE_WEIGHT: f64 = 50.0;

/// The default affine term gives way to points when it costs too many inliers. The
/// affine-scored model must explain, by its points alone, at least this share of the data that
/// the best points-scored model explains, and its own (affine) inliers must be at least this
/// share of what it explains by points. Either failure means that A is too poor to score with:
/// learned ACs can be off by 30%, where λ·SD_A alone is ~4 threshold² (tests/synthetic.rs), and
/// on repetitive texture (a chessboard) wrong A of a consistent subset let a model with half the
/// true inliers win the affine score (benches/results/scene_families.real.md). The estimate is
/// then the estimate of the points alone (points-only scoring and refinements). An uncapped
/// term is what gives the one-plane and narrow-baseline gains (a cap at threshold²/4 lost
/// them: benches/results/scene_families.md), and there both models explain about as many
/// points, so the affine one is kept.
pub const DEFAULT_AFFINE_FALLBACK: f64 = 0.8;

/// The affine scoring weight of an epipolar problem (F, relative pose) under `opts` on `data`,
/// and whether it is the default (which may fall back to points).
fn epipolar_affine_weight(data: &Correspondences, opts: &EstimatorOptions) -> (f64, bool) {
    match opts.affine_weight {
        Some(w) => (w, false),
        None if data.has_affine() => (DEFAULT_AFFINE_WEIGHT, true),
        None => (0.0, false),
    }
}

/// The default affine weight measured on the data: λ̂, the ratio of the point to the affine
/// noise variance ([`epipolar_lm::affine_scale`], what the final refinement weighs A by), on the
/// inliers of `first` (the estimate scored with [`DEFAULT_AFFINE_WEIGHT`]) under its pixel F,
/// when it is below that weight; `None` otherwise (or when too few ACs carry a confidence).
///
/// Why: λ = σ_P²/σ_A², so the fixed weight assumes that A's noise, carried over √50 ≈ 7 px,
/// is no larger than the points' (A to about 12% at 0.5 px; docs/estimation.md). ACs noisier
/// than that (learned A on blurred, texture-poor walls) make λ·SD_A exceed the
/// threshold for true inliers, and the affine-scored model drops 3–10% of the point inliers.
/// Scoring at λ̂ weighs each AC's affine part as much as its noise allows, like the final
/// refinement does; where A is as accurate as assumed or better (λ̂ ≥ the default), nothing
/// changes, so the gains of the uncapped term on one plane and narrow baselines stay
/// (benches/results/scene_families.md, docs/estimation.md).
fn measured_affine_weight(
    data: &Correspondences,
    f: &Mat3,
    first: &[bool],
    opts: &EstimatorOptions,
) -> Option<f64> {
    let inliers: Vec<usize> = (0..data.len()).filter(|&i| first[i]).collect();
    let confidence = opts.affine_confidence.as_deref();
    let (lambda, _) = epipolar_lm::affine_scale(data, f, &inliers, confidence)?;
    (lambda < DEFAULT_AFFINE_WEIGHT).then_some(lambda)
}

/// The default affine weight's second look at `first`, the estimate scored at
/// [`DEFAULT_AFFINE_WEIGHT`] (pixel F `f`, samples of `kind`) of the problem that
/// `at(weight, kind)` builds:
/// - the points-scored estimate, when A proves too poor to score with ([`points_fallback`]);
///   judged on `first`, since a lower weight keeps the inliers of such A;
/// - else `first` polished at the weight measured on its inliers ([`measured_affine_weight`])
///   when that is lower: scored at it, locally optimised and refined ([`polish`]), not sampled
///   again; it reports the work of both passes;
/// - else `first`.
fn settle_default_weight<P: Problem>(
    first: Estimate<P::Model>,
    f: &Mat3,
    data: &Correspondences,
    kind: SampleKind,
    at: impl Fn(f64, SampleKind) -> P,
    opts: &EstimatorOptions,
) -> Estimate<P::Model> {
    if let Some(p) = points_fallback(&at(0.0, SampleKind::Points), &first, opts) {
        return p;
    }
    let Some(w) = measured_affine_weight(data, f, &first.inliers, opts) else {
        return first;
    };
    let (problem, start, threshold) = (at(w, kind), first.model.clone(), opts.ransac.threshold);
    let polished = match scoring_of(opts, ScoringKind::Msac) {
        ScoringKind::Magsac => polish(
            &problem,
            &MagsacPlusPlus::new(threshold),
            start,
            &opts.ransac,
        ),
        _ => polish(&problem, &Msac::new(threshold), start, &opts.ransac),
    };
    match polished {
        Ok(mut e) => {
            e.iterations += first.iterations;
            e.lo_runs += first.lo_runs;
            e.refinements += first.refinements;
            e.residual_evaluations += first.residual_evaluations;
            e.sprt_rejections += first.sprt_rejections;
            e
        }
        Err(_) => first,
    }
}

/// The number of data whose residual under `model` in `problem` is below `threshold`.
fn explained<P: Problem>(problem: &P, model: &P::Model, threshold: f64) -> usize {
    let mut r = vec![0.0; problem.len()];
    problem.residuals(model, 0, &mut r);
    let t2 = threshold * threshold;
    r.iter().filter(|&&v| v < t2).count()
}

/// Most iterations of the probe of [`points_fallback`].
const PROBE_ITERATIONS: usize = 200;

/// Confidence with which the probe of [`points_fallback`] draws an all-inlier minimal sample
/// of a points model that would make the affine estimate lose.
const PROBE_CONFIDENCE: f64 = 0.99;

/// The points-scored estimate to return instead of the default affine-scored one `affine`
/// ([`DEFAULT_AFFINE_FALLBACK`]), or `None` to keep it. `points` is the same problem sampled and
/// scored by points only.
///
/// Whether a points model explains far more is asked of a probe: minimal point samples, no
/// local optimisation, no refinement (its count is a lower bound of a full run's). It only looks
/// for a model that beats the affine one by 1/[`DEFAULT_AFFINE_FALLBACK`], i.e. with an inlier
/// ratio w ≥ (explained by the affine model's points) / (0.8 N): k = log(1 − 0.99) / log(1 − wᵐ)
/// draws find one with 99% confidence (46 for E at w = 0.625; at most [`PROBE_ITERATIONS`]).
/// Only when the affine estimate loses is the full run made, with point samples, points-only
/// scoring and points-only refinements: exactly what the same data as points give.
///
/// The probe samples points because poor A is the case in question: 2-AC hypotheses of poor A
/// find a consistent decoy instead (tests/synthetic.rs), or half the true inliers on repetitive
/// texture unless local optimisation, which costs as much as the run, repairs them. A points run
/// that finds nothing keeps the affine estimate.
fn points_fallback<P: Problem>(
    points: &P,
    affine: &Estimate<P::Model>,
    opts: &EstimatorOptions,
) -> Option<Estimate<P::Model>> {
    let threshold = opts.ransac.threshold;
    let by_points = explained(points, &affine.model, threshold) as f64;
    let too_poor = (affine.num_inliers as f64) < DEFAULT_AFFINE_FALLBACK * by_points || {
        let mut probe = opts.clone();
        probe.ransac.final_refinement = false;
        probe.ransac.local_optimization = false;
        let w = (by_points / (DEFAULT_AFFINE_FALLBACK * points.len() as f64)).min(1.0);
        let p_good = w.powi(points.sample_size() as i32);
        let draws = if p_good >= 1.0 {
            1
        } else if p_good > 0.0 {
            ((1.0 - PROBE_CONFIDENCE).ln() / (1.0 - p_good).ln()).ceil() as usize
        } else {
            PROBE_ITERATIONS
        };
        probe.ransac.max_iterations = probe.ransac.max_iterations.min(PROBE_ITERATIONS).min(draws);
        probe.ransac.min_iterations = probe.ransac.min_iterations.min(probe.ransac.max_iterations);
        run(points, &probe, ScoringKind::Msac)
            .is_ok_and(|p| by_points < DEFAULT_AFFINE_FALLBACK * p.num_inliers as f64)
    };
    if too_poor {
        // A judged too poor to score with stays out of the refinements too: weighed by its
        // own estimated noise there, it still moved poses on repetitive texture away from
        // the points' (docs/estimation.md, "Poor A stays out").
        let mut points_only = opts.clone();
        points_only.ransac.affine_refinement = AffineRefinement::Off;
        run(points, &points_only, ScoringKind::Msac).ok()
    } else {
        None
    }
}

fn sample_kind(data: &Correspondences, opts: &EstimatorOptions) -> Result<SampleKind> {
    data.validate()?;
    let kind = opts.sample.unwrap_or(if data.has_affine() {
        SampleKind::Affine
    } else {
        SampleKind::Points
    });
    check_kind(data, kind)?;
    if let Some(w) = opts.affine_weight {
        check_affine_weight(w, data)?;
    }
    check_affine_confidence(opts.affine_confidence.as_deref(), data)?;
    Ok(kind)
}

/// Validates per-AC confidences: one per datum, each in [0, 1], only with affine data.
fn check_affine_confidence(c: Option<&[f64]>, data: &Correspondences) -> Result<()> {
    let Some(c) = c else {
        return Ok(());
    };
    let bad = |value: String, reason| {
        Err(RansacError::InvalidOption {
            name: "affine_confidence",
            value,
            reason,
        })
    };
    if !data.has_affine() {
        return bad(
            format!("{} values", c.len()),
            "needs (N, 8) correspondences with their A",
        );
    }
    if c.len() != data.len() {
        return bad(
            format!("{} values for {} correspondences", c.len(), data.len()),
            "needs one value per correspondence",
        );
    }
    if let Some(i) = c.iter().position(|v| !(0.0..=1.0).contains(v)) {
        return bad(format!("{} at index {i}", c[i]), "must be in [0, 1]");
    }
    Ok(())
}

/// The scoring that `opts` ask for, `auto` standing for [`ScoringKind::Auto`].
fn scoring_of(opts: &EstimatorOptions, auto: ScoringKind) -> ScoringKind {
    if opts.scoring == ScoringKind::Auto {
        auto
    } else {
        opts.scoring
    }
}

fn run<P: Problem>(
    problem: &P,
    opts: &EstimatorOptions,
    auto: ScoringKind,
) -> Result<Estimate<P::Model>> {
    match scoring_of(opts, auto) {
        ScoringKind::Auto | ScoringKind::Msac => {
            run_with(problem, &Msac::new(opts.ransac.threshold), opts)
        }
        ScoringKind::Magsac => run_with(problem, &MagsacPlusPlus::new(opts.ransac.threshold), opts),
    }
}

fn run_with<P: Problem, S: Scoring>(
    problem: &P,
    scoring: &S,
    opts: &EstimatorOptions,
) -> Result<Estimate<P::Model>> {
    match opts.sampler {
        SamplerKind::Uniform => estimate(problem, &mut UniformSampler, scoring, &opts.ransac),
        SamplerKind::Prosac => {
            let quality = opts.quality.as_deref().ok_or(RansacError::InvalidOption {
                name: "quality",
                value: "None".into(),
                reason: "PROSAC needs a per-correspondence quality",
            })?;
            if quality.len() != problem.len() {
                return Err(RansacError::InvalidOption {
                    name: "quality",
                    value: format!("{} values", quality.len()),
                    reason: "needs one value per correspondence",
                });
            }
            if let Some(i) = quality.iter().position(|q| !q.is_finite()) {
                return Err(RansacError::InvalidOption {
                    name: "quality",
                    value: format!("{} at index {i}", quality[i]),
                    reason: "must be finite",
                });
            }
            let mut sampler = ProsacSampler::new(quality, problem.sample_size());
            estimate(problem, &mut sampler, scoring, &opts.ransac)
        }
    }
}

/// Robust homography (pixels): p2 ~ H p1, ‖H‖_F = 1.
pub fn estimate_homography(
    data: &Correspondences,
    opts: &EstimatorOptions,
) -> Result<Estimate<Mat3>> {
    let kind = sample_kind(data, opts)?;
    run(
        &HomographyProblem::new(data, kind, opts.affine_weight.unwrap_or(0.0))
            .with_affine_confidence(opts.affine_confidence.as_deref()),
        opts,
        ScoringKind::Msac,
    )
}

/// Robust fundamental matrix (pixels): p2ᵀ F p1 = 0, ‖F‖_F = 1.
pub fn estimate_fundamental(
    data: &Correspondences,
    opts: &EstimatorOptions,
) -> Result<Estimate<Mat3>> {
    let kind = sample_kind(data, opts)?;
    let (weight, default) = epipolar_affine_weight(data, opts);
    let problem = |w, kind| {
        FundamentalProblem::new(data, kind, w, opts.ransac.threshold)
            .with_affine_confidence(opts.affine_confidence.as_deref())
    };
    let est = run(&problem(weight, kind), opts, ScoringKind::Msac)?;
    if !default {
        return Ok(est);
    }
    let f = est.model;
    Ok(settle_default_weight(est, &f, data, kind, problem, opts))
}

/// Robust relative pose X2 = R X1 + t (|t| = 1) from pixel correspondences and intrinsics.
/// The final pose is the factorisation of the final E with the most inliers in front of both
/// cameras.
pub fn estimate_relative_pose(
    data: &Correspondences,
    k1: &Intrinsics,
    k2: &Intrinsics,
    opts: &EstimatorOptions,
) -> Result<Estimate<PoseModel>> {
    let kind = sample_kind(data, opts)?;
    let (weight, default) = epipolar_affine_weight(data, opts);
    // Cheirality is checked wherever a datum can count as an inlier: below the widest threshold
    // of local optimisation's schedule.
    let make = |w, kind| {
        RelativePoseProblem::new(
            data,
            *k1,
            *k2,
            kind,
            w,
            LO_SCHEDULE[0] * opts.ransac.threshold,
        )
        .with_affine_confidence(opts.affine_confidence.as_deref())
    };
    // Every problem below shares the normalised data and the intrinsics; only the scoring
    // weight and the sample kind differ.
    let problem = make(weight, kind);
    let mut est = run(&problem, opts, ScoringKind::Msac)?;
    if default {
        let f = est.model.fundamental;
        est = settle_default_weight(est, &f, data, kind, make, opts);
    }
    let idx: Vec<usize> = (0..data.len()).filter(|&i| est.inliers[i]).collect();
    let (x1, x2): (Vec<_>, Vec<_>) = idx
        .iter()
        .map(|&i| (problem.normalized().x1[i], problem.normalized().x2[i]))
        .unzip();
    if let Ok((pose, n)) = pose_from_essential(&est.model.essential, &x1, &x2)
        && n > 0
    {
        est.model = problem.model(pose);
    }
    Ok(est)
}

/// The options of a batch: one set for every pair, or one per pair.
#[derive(Debug, Clone, Copy)]
pub enum BatchOptions<'a> {
    /// The same options for every pair.
    Shared(&'a EstimatorOptions),
    /// `options[i]` for pair i (as many as there are pairs).
    PerPair(&'a [EstimatorOptions]),
}

impl<'a> From<&'a EstimatorOptions> for BatchOptions<'a> {
    fn from(o: &'a EstimatorOptions) -> Self {
        BatchOptions::Shared(o)
    }
}

impl<'a> From<&'a [EstimatorOptions]> for BatchOptions<'a> {
    fn from(o: &'a [EstimatorOptions]) -> Self {
        BatchOptions::PerPair(o)
    }
}

impl<'a> From<&'a Vec<EstimatorOptions>> for BatchOptions<'a> {
    fn from(o: &'a Vec<EstimatorOptions>) -> Self {
        BatchOptions::PerPair(o)
    }
}

impl<'a, const K: usize> From<&'a [EstimatorOptions; K]> for BatchOptions<'a> {
    fn from(o: &'a [EstimatorOptions; K]) -> Self {
        BatchOptions::PerPair(o)
    }
}

impl BatchOptions<'_> {
    /// Pair i's options; an error for every pair when a per-pair list has the wrong length.
    fn get(&self, i: usize, pairs: usize) -> Result<&EstimatorOptions> {
        match *self {
            BatchOptions::Shared(o) => Ok(o),
            BatchOptions::PerPair(list) if list.len() == pairs => Ok(&list[i]),
            BatchOptions::PerPair(list) => Err(RansacError::InvalidOption {
                name: "options",
                value: format!("{} option sets for {pairs} pairs", list.len()),
                reason: "needs one option set per pair, or one for all",
            }),
        }
    }
}

/// [`estimate_homography`] over many image pairs in parallel; `opts` is one
/// [`EstimatorOptions`] for all pairs or a slice with one per pair.
pub fn estimate_homography_batch<'a>(
    data: &[Correspondences],
    opts: impl Into<BatchOptions<'a>>,
) -> Vec<Result<Estimate<Mat3>>> {
    let opts = opts.into();
    data.par_iter()
        .enumerate()
        .map(|(i, d)| estimate_homography(d, opts.get(i, data.len())?))
        .collect()
}

/// [`estimate_fundamental`] over many image pairs in parallel (options as in
/// [`estimate_homography_batch`]).
pub fn estimate_fundamental_batch<'a>(
    data: &[Correspondences],
    opts: impl Into<BatchOptions<'a>>,
) -> Vec<Result<Estimate<Mat3>>> {
    let opts = opts.into();
    data.par_iter()
        .enumerate()
        .map(|(i, d)| estimate_fundamental(d, opts.get(i, data.len())?))
        .collect()
}

/// [`estimate_relative_pose`] over many image pairs (each with its intrinsics) in parallel
/// (options as in [`estimate_homography_batch`]).
pub fn estimate_relative_pose_batch<'a>(
    pairs: &[(Correspondences, Intrinsics, Intrinsics)],
    opts: impl Into<BatchOptions<'a>>,
) -> Vec<Result<Estimate<PoseModel>>> {
    let opts = opts.into();
    pairs
        .par_iter()
        .enumerate()
        .map(|(i, (d, k1, k2))| estimate_relative_pose(d, k1, k2, opts.get(i, pairs.len())?))
        .collect()
}
