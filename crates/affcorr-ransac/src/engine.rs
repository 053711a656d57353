//! The hypothesise-and-verify loop, generic over [`Problem`], [`Sampler`] and [`Scoring`].
//!
//! Per iteration: draw a minimal sample, fit its models, score each against all data (in blocks,
//! with an exact bail-out), and on a new best model run local optimisation and tighten the
//! adaptive iteration bound k = log(1 − confidence) / log(1 − ρ wᵐ) (m: sample size; w: the
//! fraction of data that can seed a good sample — the inliers, and for AC samples only those
//! whose affine part is accurate too; ρ: [`RansacOptions::sample_reliability`]). Finally the
//! best model is refined on its inliers. Buffers are allocated once, before the loop; the same
//! seed and data always give the same result.
//!
//! This module holds the loop, the adaptive iteration bound, the option checks and the final
//! refinement. The steps it calls live beside it: the verification pass and its residual cache
//! (`verify`), the SPRT (`sprt`) and local optimisation with its threshold schedule and the
//! graph-cut glue (`local_opt`).

use crate::error::{RansacError, Result};
use crate::local_opt::{LoGraph, local_optimization};
use crate::options::{AffineRefinement, Cancel, LoKind, LoSchedule, RansacOptions};
use crate::problem::Problem;
use crate::refine::LmOptions;
use crate::sampler::Sampler;
use crate::score::Scoring;
use crate::sprt::{Sprt, Verdict};
use crate::verify::{LO_TRIGGER_SCALE, Scored, Scratch, collect_inliers, inlier_mask, score_model};
use rand::SeedableRng;
use rand_pcg::Pcg64;

/// The result of a robust estimation.
#[derive(Debug, Clone)]
pub struct Estimate<M> {
    /// The best model.
    pub model: M,
    /// Per-datum inlier flags under the final model.
    pub inliers: Vec<bool>,
    /// Number of inliers.
    pub num_inliers: usize,
    /// Score of the final model (sum of qualities, higher is better).
    pub score: f64,
    /// Iterations run (minimal samples drawn).
    pub iterations: usize,
    /// Local optimisations run.
    pub lo_runs: usize,
    /// Rounds of the final refinement that improved the model (0 to 4: each round refits on the
    /// inliers of the previous one while they change).
    pub refinements: usize,
    /// Squared residuals computed (scoring, local optimisation, refinement excluded): the
    /// verification cost that the SPRT cuts.
    pub residual_evaluations: u64,
    /// Hypotheses rejected by the SPRT (0 without it).
    pub sprt_rejections: usize,
    /// The weight λ (px²) of the affine residual in scoring (0: points only); by default
    /// measured on the data ([`crate::estimators::EstimatorOptions::affine_weight`]).
    pub affine_weight: f64,
}

/// Adaptive bound on the number of iterations for `inliers` of `n` at `confidence`, when an
/// all-inlier sample's model survives verification with probability `pass`.
fn iterations_needed(inliers: usize, n: usize, m: usize, confidence: f64, pass: f64) -> usize {
    let w = inliers as f64 / n as f64;
    let p_good = w.powi(m as i32) * pass;
    if p_good >= 1.0 {
        return 1;
    }
    if p_good <= f64::MIN_POSITIVE {
        return usize::MAX;
    }
    let k = (1.0 - confidence).ln() / (1.0 - p_good).ln();
    if k.is_finite() {
        k.ceil().max(1.0) as usize
    } else {
        usize::MAX
    }
}

/// Validates the options shared by every problem.
pub fn check_options(o: &RansacOptions) -> Result<()> {
    let bad = |name, value: f64, reason| {
        Err(RansacError::InvalidOption {
            name,
            value: value.to_string(),
            reason,
        })
    };
    if !(o.threshold > 0.0 && o.threshold.is_finite()) {
        return bad("threshold", o.threshold, "must be positive and finite");
    }
    if !(o.confidence > 0.0 && o.confidence < 1.0) {
        return bad("confidence", o.confidence, "must be in (0, 1)");
    }
    if !(o.sample_reliability > 0.0 && o.sample_reliability <= 1.0) {
        return bad(
            "sample_reliability",
            o.sample_reliability,
            "must be in (0, 1]",
        );
    }
    if o.max_iterations == 0 {
        return bad("max_iterations", 0.0, "must be at least 1");
    }
    if o.min_iterations > o.max_iterations {
        return bad(
            "min_iterations",
            o.min_iterations as f64,
            "must not exceed max_iterations",
        );
    }
    Ok(())
}

/// The problem's size and sample size, when it has enough data for one sample.
fn check_size<P: Problem>(problem: &P) -> Result<(usize, usize)> {
    let (n, m) = (problem.len(), problem.sample_size());
    if n < m {
        return Err(RansacError::NotEnoughData {
            what: "corrs",
            needed: m,
            got: n,
        });
    }
    Ok((n, m))
}

/// Robustly fits `problem`'s model with `sampler` and `scoring`.
pub fn estimate<P, Sa, Sc>(
    problem: &P,
    sampler: &mut Sa,
    scoring: &Sc,
    options: &RansacOptions,
) -> Result<Estimate<P::Model>>
where
    P: Problem,
    Sa: Sampler,
    Sc: Scoring,
{
    check_options(options)?;
    let (n, m) = check_size(problem)?;
    let mut rng = Pcg64::seed_from_u64(options.seed);
    let mut sample = vec![0usize; m];
    let mut models: Vec<P::Model> = Vec::with_capacity(16);
    let mut scratch = Scratch::new(n);
    let (mut lo_indices, mut lo_weights) = (Vec::with_capacity(n), Vec::with_capacity(n));
    let lo = options.local_optimization;
    let mut graph = lo_graph(problem, options)?;
    // With local optimisation, a hypothesis is worth verifying if it explains data at the
    // LO trigger's wide threshold (see `promising` below); the SPRT tests consistency there.
    let mut sprt = options.sprt.then(|| {
        let scale = if lo { LO_TRIGGER_SCALE } else { 1.0 };
        let mut order_rng = Pcg64::seed_from_u64(options.seed ^ 0x5350_5254);
        Sprt::new(
            n,
            scoring.inlier_threshold_sq() * scale * scale,
            problem.model_cost(),
            &mut order_rng,
        )
    });

    let schedule = options.lo_schedule.resolve(problem);
    // With the threshold track, every raw record earns a local optimisation; see `record`.
    let records = lo && schedule.has_threshold_track();

    let mut best: Option<Scored<P::Model>> = None;
    let mut best_wide_support = 0usize;
    // The best score of a raw hypothesis (before local optimisation) so far; see `record`.
    let mut best_raw_score = 0.0f64;
    let mut bound = options.max_iterations;
    let (mut iterations, mut lo_runs) = (0, 0);
    while iterations
        < bound
            .max(options.min_iterations)
            .min(options.max_iterations)
    {
        if options.cancel.as_ref().is_some_and(Cancel::is_cancelled) {
            break;
        }
        iterations += 1;
        sampler.sample(&mut rng, n, &mut sample);
        models.clear();
        problem.fit_minimal(&sample, &mut models);
        if let Some(s) = sprt.as_mut() {
            s.samples += 1;
            s.models += models.len() as u64;
        }
        for model in models.drain(..) {
            let to_beat = best.as_ref().map_or(0.0, |b| b.score);
            let wide_to_beat = if lo { best_wide_support } else { usize::MAX };
            // A raw hypothesis is scored in full if it may out-score every earlier raw one
            // (`record`), not only the optimised best.
            let raw_to_beat = if records {
                to_beat.min(best_raw_score)
            } else {
                to_beat
            };
            let e = match sprt.as_mut() {
                None => score_model(
                    problem,
                    scoring,
                    &model,
                    raw_to_beat,
                    wide_to_beat,
                    &mut scratch,
                ),
                Some(s) => match s.verify(
                    problem,
                    scoring,
                    &model,
                    raw_to_beat,
                    wide_to_beat,
                    &mut scratch,
                ) {
                    Verdict::Complete(e) => Some(e),
                    Verdict::Rejected | Verdict::Beaten => None,
                },
            };
            let Some(e) = e else {
                continue;
            };
            // A hypothesis that is not the best at the threshold but has the widest support so
            // far is probably a noisy model of the right structure (e.g. from 2 noisy ACs): give
            // it a local optimisation too.
            let promising = lo && e.wide_support > best_wide_support && e.wide_support > m;
            best_wide_support = best_wide_support.max(e.wide_support);
            // The best raw hypothesis so far earns a local optimisation even when an optimised
            // model out-scores it (LO-RANSAC's so-far-the-best rule compares raw with raw, as
            // PoseLib does): optimisation lifts a score above any raw one's, and a model
            // optimised into a compromise between two structures (a plane and a cluster a few
            // pixels off it) would otherwise never be challenged by the raw samples of the
            // better one. Only with the threshold track: the widening track takes a raw
            // hypothesis of either structure into the compromise (docs/estimation.md).
            let record = records && e.score > best_raw_score;
            best_raw_score = best_raw_score.max(e.score);
            let only_record = e.score <= to_beat && !promising;
            if only_record && !record {
                continue;
            }
            // A record that is neither a new best nor promising gets the threshold track
            // alone: its widening track goes where the best's went (on the scene families and
            // the cluster scenes it never won; 10% of a homography's instructions).
            let track = if only_record {
                LoSchedule::Threshold
            } else {
                schedule
            };
            let mut candidate = Scored {
                model,
                score: e.score,
                inliers: e.inliers,
                wide_support: e.wide_support,
            };
            if lo && e.wide_support > m {
                lo_runs += 1;
                candidate = local_optimization(
                    problem,
                    scoring,
                    candidate,
                    track,
                    options,
                    &mut scratch,
                    graph.as_mut(),
                    &mut lo_indices,
                    &mut lo_weights,
                );
            }
            if candidate.score > to_beat {
                if let Some(s) = sprt.as_mut() {
                    s.new_best(
                        if lo {
                            candidate.wide_support
                        } else {
                            candidate.inliers
                        },
                        n,
                    );
                }
                let pass = sprt.as_ref().map_or(1.0, Sprt::pass_probability);
                // An AC sample needs accurate affine parts too: count the data that can seed
                // a good minimal sample (`Problem::sample_support`), not just the inliers.
                let seeds = problem
                    .sample_support(&candidate.model, scoring.inlier_threshold_sq())
                    .unwrap_or(candidate.inliers);
                bound = iterations_needed(
                    seeds,
                    n,
                    m,
                    options.confidence,
                    pass * options.sample_reliability,
                );
                // The best model's inliers bound its wide support from below: a raw hypothesis
                // must out-support the optimised best, not just earlier raw ones, to earn an LO.
                best_wide_support = best_wide_support.max(candidate.inliers);
                best = Some(candidate);
            }
        }
    }

    let best = best.ok_or(RansacError::NoModel { iterations })?;
    let rejections = sprt.map_or(0, |s| s.rejections);
    let counts = Counts(iterations, lo_runs, rejections);
    Ok(finish(
        problem,
        scoring,
        options,
        best,
        &mut scratch,
        counts,
    ))
}

/// Polishes a known model of `problem` without drawing samples: scores `start`, runs local
/// optimisation from it (when `options` ask for it) and the final refinement, as [`estimate`]
/// does with its best sample's model.
///
/// For a second look at the same data under a changed score (the measured affine weight of
/// [`crate::estimators::EstimatorOptions::affine_weight`]): the first run's model is already in
/// the right basin, and local optimisation's widening threshold schedule re-collects the data
/// that the new score admits, where a second run would draw every sample again.
pub fn polish<P, Sc>(
    problem: &P,
    scoring: &Sc,
    start: P::Model,
    options: &RansacOptions,
) -> Result<Estimate<P::Model>>
where
    P: Problem,
    Sc: Scoring,
{
    check_options(options)?;
    let (n, m) = check_size(problem)?;
    let mut scratch = Scratch::new(n);
    let (mut lo_indices, mut lo_weights) = (Vec::with_capacity(n), Vec::with_capacity(n));
    let mut graph = lo_graph(problem, options)?;
    let e = score_model(problem, scoring, &start, 0.0, usize::MAX, &mut scratch)
        .ok_or(RansacError::NoModel { iterations: 0 })?;
    let mut best = Scored {
        model: start,
        score: e.score,
        inliers: e.inliers,
        wide_support: e.wide_support,
    };
    let mut lo_runs = 0;
    if options.local_optimization && best.wide_support > m {
        lo_runs = 1;
        best = local_optimization(
            problem,
            scoring,
            best,
            options.lo_schedule.resolve(problem),
            options,
            &mut scratch,
            graph.as_mut(),
            &mut lo_indices,
            &mut lo_weights,
        );
    }
    Ok(finish(
        problem,
        scoring,
        options,
        best,
        &mut scratch,
        Counts(0, lo_runs, 0),
    ))
}

/// The graph of graph-cut local optimisation, when `options` ask for it (it needs positions).
fn lo_graph<P: Problem>(problem: &P, options: &RansacOptions) -> Result<Option<LoGraph>> {
    if !(options.local_optimization && options.lo == LoKind::GraphCut) {
        return Ok(None);
    }
    let (x1, x2) = problem.positions().ok_or(RansacError::InvalidOption {
        name: "lo",
        value: "graph_cut".into(),
        reason: "graph-cut local optimisation needs data with positions",
    })?;
    Ok(Some(LoGraph::new(x1, x2, problem.len())))
}

/// What a search counted, for its [`Estimate`]: iterations, local optimisations, SPRT
/// rejections.
struct Counts(usize, usize, usize);

/// The final refinement of `best` (when `options` ask for it) and the estimate it gives.
fn finish<P: Problem, Sc: Scoring>(
    problem: &P,
    scoring: &Sc,
    options: &RansacOptions,
    mut best: Scored<P::Model>,
    scratch: &mut Scratch<P::Model>,
    Counts(iterations, lo_runs, sprt_rejections): Counts,
) -> Estimate<P::Model> {
    let m = problem.sample_size();
    let (lo_indices, lo_weights) = (&mut Vec::new(), &mut Vec::new());
    let mut refinements = 0;
    if options.final_refinement {
        // Refine on the inliers, then again on the refined model's inliers while that set
        // changes (at most FINAL_ROUNDS): data that the polished model brings within the
        // threshold join the fit, as in a refinement over all data with the truncated loss.
        let mut previous: Vec<usize> = Vec::new();
        // With the affine terms the refinement no longer minimises the point residuals alone,
        // so its model may score a little lower on them while fitting the data better: it is
        // kept if it loses less than AFFINE_SCORE_SLACK of the score the refinement started
        // from (a wrong basin loses far more).
        let affine = options.affine_refinement != AffineRefinement::Off && problem.refines_affine();
        let floor = if affine {
            best.score * (1.0 - AFFINE_SCORE_SLACK)
        } else {
            best.score
        };
        for _ in 0..FINAL_ROUNDS {
            collect_inliers(
                problem,
                scoring,
                &best.model,
                1.0,
                scratch,
                lo_indices,
                lo_weights,
            );
            if lo_indices.len() < m || *lo_indices == previous {
                break;
            }
            // The affine refinement first; if its model scores too low on the point
            // residuals (the ACs pull it away from what the points support), the points-only
            // refinement, which must beat the score outright.
            let attempts: &[bool] = if affine { &[true, false] } else { &[false] };
            let mut improved = false;
            for &with_affine in attempts {
                let Some(refined) = problem.refine(
                    &best.model,
                    lo_indices,
                    // The scoring's own cost: the refined model optimises what the score
                    // measures.
                    &scoring.refinement_loss(),
                    &LmOptions {
                        max_iterations: FINAL_LM_ITERATIONS,
                        noise_fraction: FINAL_NOISE_FRACTION,
                        affine: with_affine,
                        ..Default::default()
                    },
                ) else {
                    continue;
                };
                let to_beat = if with_affine { floor } else { best.score };
                if let Some(e) =
                    score_model(problem, scoring, &refined, to_beat, usize::MAX, scratch)
                        .filter(|e| e.score > to_beat)
                {
                    scratch.keep(&refined);
                    best = Scored {
                        model: refined,
                        score: e.score,
                        inliers: e.inliers,
                        wide_support: e.wide_support,
                    };
                    refinements += 1;
                    improved = true;
                    break;
                }
            }
            if !improved {
                break;
            }
            std::mem::swap(&mut previous, lo_indices);
        }
    }
    let inliers = inlier_mask(problem, scoring, &best.model, scratch);
    Estimate {
        num_inliers: inliers.iter().filter(|&&b| b).count(),
        model: best.model,
        inliers,
        score: best.score,
        iterations,
        lo_runs,
        refinements,
        residual_evaluations: scratch.evaluations,
        sprt_rejections,
        affine_weight: problem.scoring_affine_weight(),
    }
}

/// Levenberg–Marquardt steps of the final refinement.
const FINAL_LM_ITERATIONS: usize = 100;
/// The final refinement's [`LmOptions::noise_fraction`]: it stops once a step would move the
/// model by less than √0.001 ≈ 0.03 standard errors. From a linear fit (H: no LM inside LO)
/// the default 0.01 stopped early enough to raise the median H error over the profile scenes
/// (benches/results/ransac.md); 0.001 costs one more normal-equation pass on the inliers.
const FINAL_NOISE_FRACTION: f64 = 0.001;
/// The share of its starting score that the final refinement with affine terms may lose on the
/// point residuals (see the engine's final refinement). The point-optimal model overfits the
/// point noise by about dof·σ² in Σr², a fraction ~dof/N of the score; 1% covers it for N ≥ 10³
/// inliers-per-dof ratios well above any real set while rejecting a model that drops inliers.
const AFFINE_SCORE_SLACK: f64 = 0.01;
/// Most refine-and-recollect rounds of the final refinement.
const FINAL_ROUNDS: usize = 4;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::local_opt::LO_LM_ITERATIONS;
    use crate::loss::Loss;
    use crate::sampler::UniformSampler;
    use crate::score::Msac;
    use rand::Rng;

    /// 2-D line fitting y = a x + b: the smallest problem that exercises every path.
    struct Line {
        x: Vec<f64>,
        y: Vec<f64>,
        lo_refines: bool,
        /// `None`: `refine` fails. `Some(offset)`: it returns the least-squares line, moved up
        /// by `offset` when asked for the affine terms (an affine refinement that pulls the
        /// model away from what the points support), and the problem refines affine terms.
        refinement: Option<f64>,
        /// The options of every `refine` call.
        refine_calls: std::sync::Mutex<Vec<LmOptions>>,
    }

    impl Problem for Line {
        type Model = (f64, f64);
        fn len(&self) -> usize {
            self.x.len()
        }
        fn sample_size(&self) -> usize {
            2
        }
        fn fit_minimal(&self, s: &[usize], out: &mut Vec<(f64, f64)>) {
            let dx = self.x[s[1]] - self.x[s[0]];
            if dx.abs() > 1e-12 {
                let a = (self.y[s[1]] - self.y[s[0]]) / dx;
                out.push((a, self.y[s[0]] - a * self.x[s[0]]));
            }
        }
        fn fit_nonminimal(&self, idx: &[usize], w: Option<&[f64]>) -> Option<(f64, f64)> {
            let (mut sw, mut sx, mut sy, mut sxx, mut sxy) = (0.0, 0.0, 0.0, 0.0, 0.0);
            for (k, &i) in idx.iter().enumerate() {
                let wi = w.map_or(1.0, |w| w[k]);
                let (x, y) = (self.x[i], self.y[i]);
                sw += wi;
                sx += wi * x;
                sy += wi * y;
                sxx += wi * x * x;
                sxy += wi * x * y;
            }
            let det = sw * sxx - sx * sx;
            (det.abs() > 1e-12).then(|| ((sw * sxy - sx * sy) / det, (sxx * sy - sx * sxy) / det))
        }
        fn residuals(&self, m: &(f64, f64), start: usize, out: &mut [f64]) {
            for (k, o) in out.iter_mut().enumerate() {
                let r = self.y[start + k] - (m.0 * self.x[start + k] + m.1);
                *o = r * r;
            }
        }
        fn refine(
            &self,
            _: &(f64, f64),
            inliers: &[usize],
            _: &Loss,
            options: &LmOptions,
        ) -> Option<(f64, f64)> {
            self.refine_calls.lock().unwrap().push(*options);
            let offset = self.refinement?;
            let (a, b) = self.fit_nonminimal(inliers, None)?;
            Some((a, if options.affine { b + offset } else { b }))
        }
        fn refines_affine(&self) -> bool {
            self.refinement.is_some()
        }
        fn lo_refines(&self) -> bool {
            self.lo_refines
        }
    }

    fn noisy_line(n: usize, outlier_ratio: f64, seed: u64) -> (Line, Vec<bool>) {
        let mut rng = Pcg64::seed_from_u64(seed);
        let (mut x, mut y, mut truth) = (vec![], vec![], vec![]);
        for _ in 0..n {
            let xi = rng.random_range(-10.0..10.0);
            let outlier = rng.random::<f64>() < outlier_ratio;
            let yi = if outlier {
                rng.random_range(-50.0..50.0)
            } else {
                2.0 * xi - 1.0 + rng.random_range(-0.1..0.1)
            };
            x.push(xi);
            y.push(yi);
            truth.push(!outlier);
        }
        let line = Line {
            x,
            y,
            lo_refines: true,
            refinement: None,
            refine_calls: Default::default(),
        };
        (line, truth)
    }

    #[test]
    fn a_set_cancel_flag_stops_the_loop_before_the_next_iteration() {
        let (line, _) = noisy_line(500, 0.7, 3);
        let cancel = Cancel::new();
        let opts = RansacOptions {
            threshold: 0.3,
            cancel: Some(cancel.clone()),
            ..Default::default()
        };
        assert!(estimate(&line, &mut UniformSampler, &Msac::new(0.3), &opts).is_ok());
        cancel.cancel();
        let r = estimate(&line, &mut UniformSampler, &Msac::new(0.3), &opts);
        assert!(
            matches!(r, Err(RansacError::NoModel { iterations: 0 })),
            "{r:?}"
        );
    }

    #[test]
    fn recovers_the_line_and_its_inliers_at_70_percent_outliers() {
        let (line, truth) = noisy_line(2000, 0.7, 3);
        let opts = RansacOptions {
            threshold: 0.3,
            ..Default::default()
        };
        let est = estimate(&line, &mut UniformSampler, &Msac::new(0.3), &opts).unwrap();
        assert!(
            (est.model.0 - 2.0).abs() < 0.01 && (est.model.1 + 1.0).abs() < 0.02,
            "{:?}",
            est.model
        );
        let recall = truth
            .iter()
            .zip(&est.inliers)
            .filter(|(t, e)| **t && **e)
            .count() as f64
            / truth.iter().filter(|t| **t).count() as f64;
        assert!(recall > 0.99, "{recall}");
        assert!(est.lo_runs >= 1);
        // The adaptive bound stopped the loop long before max_iterations.
        assert!(est.iterations < 500, "{}", est.iterations);
    }

    #[test]
    fn polishing_a_rough_model_reaches_the_sampled_estimate_without_samples() {
        let (line, truth) = noisy_line(2000, 0.7, 3);
        let opts = RansacOptions {
            threshold: 0.3,
            ..Default::default()
        };
        let scoring = Msac::new(0.3);
        let sampled = estimate(&line, &mut UniformSampler, &scoring, &opts).unwrap();
        // Off by 0.05 in slope (0.5 at the ends of the data): a third of the inliers at the
        // threshold, and LO's widening schedule brings in the rest.
        let polished = polish(&line, &scoring, (2.05, -1.0), &opts).unwrap();
        assert_eq!(polished.iterations, 0);
        assert_eq!(polished.lo_runs, 1);
        assert!(
            (polished.model.0 - sampled.model.0).abs() < 1e-3
                && (polished.model.1 - sampled.model.1).abs() < 1e-3,
            "{:?} against {:?}",
            polished.model,
            sampled.model
        );
        let recall = |inliers: &[bool]| {
            truth
                .iter()
                .zip(inliers)
                .filter(|(t, e)| **t && **e)
                .count()
        };
        assert!(recall(&polished.inliers) + 5 >= recall(&sampled.inliers));
        // Nothing explained: no model, and the options are checked as `estimate` checks them.
        let r = polish(&line, &scoring, (0.0, 1e6), &opts);
        assert!(
            matches!(r, Err(RansacError::NoModel { iterations: 0 })),
            "{r:?}"
        );
        let bad = RansacOptions {
            threshold: -1.0,
            ..Default::default()
        };
        assert!(matches!(
            polish(&line, &scoring, (2.0, -1.0), &bad),
            Err(RansacError::InvalidOption {
                name: "threshold",
                ..
            })
        ));
    }

    #[test]
    fn local_optimisation_refines_only_if_the_problem_wants_it() {
        let opts = RansacOptions {
            threshold: 0.3,
            ..Default::default()
        };
        for lo_refines in [true, false] {
            let (mut line, _) = noisy_line(500, 0.5, 3);
            line.lo_refines = lo_refines;
            let est = estimate(&line, &mut UniformSampler, &Msac::new(0.3), &opts).unwrap();
            assert!(est.lo_runs >= 1);
            let calls = line.refine_calls.into_inner().unwrap();
            let lo = calls
                .iter()
                .filter(|o| o.max_iterations == LO_LM_ITERATIONS)
                .count();
            let last = calls.last().unwrap();
            // The final refinement always runs, with its own options.
            assert_eq!(last.max_iterations, FINAL_LM_ITERATIONS);
            assert_eq!(last.noise_fraction, FINAL_NOISE_FRACTION);
            assert_eq!(lo > 0, lo_refines, "{lo} LO refinements");
        }
    }

    #[test]
    fn a_rejected_affine_refinement_falls_back_to_the_points_only_one() {
        let opts = RansacOptions {
            threshold: 0.3,
            affine_refinement: AffineRefinement::Final,
            ..Default::default()
        };
        let final_calls = |line: Line| {
            let calls = line.refine_calls.into_inner().unwrap();
            calls
                .iter()
                .filter(|o| o.max_iterations == FINAL_LM_ITERATIONS)
                .map(|o| o.affine)
                .collect::<Vec<_>>()
        };
        // Half the threshold off: the affine model loses far more than the slack and is
        // rejected, and the points-only refinement replaces it (not the unrefined model).
        let (mut line, truth) = noisy_line(500, 0.5, 3);
        line.refinement = Some(0.15);
        let est = estimate(&line, &mut UniformSampler, &Msac::new(0.3), &opts).unwrap();
        let inliers: Vec<usize> = (0..500).filter(|&i| est.inliers[i]).collect();
        let found = inliers.iter().filter(|&&i| truth[i]).count();
        assert!(found * 100 >= 99 * truth.iter().filter(|&&t| t).count());
        assert_eq!(Some(est.model), line.fit_nonminimal(&inliers, None));
        assert_eq!(final_calls(line)[..2], [true, false]);
        // A negligible pull is within the slack: the affine model is kept, no fallback.
        let (mut line, _) = noisy_line(500, 0.5, 3);
        line.refinement = Some(1e-6);
        let est = estimate(&line, &mut UniformSampler, &Msac::new(0.3), &opts).unwrap();
        assert!(est.refinements >= 1);
        assert!(final_calls(line).iter().all(|&affine| affine));
    }

    #[test]
    fn same_seed_same_result_other_seed_may_differ() {
        let (line, _) = noisy_line(500, 0.5, 4);
        let opts = RansacOptions {
            threshold: 0.3,
            seed: 9,
            ..Default::default()
        };
        let a = estimate(&line, &mut UniformSampler, &Msac::new(0.3), &opts).unwrap();
        let b = estimate(&line, &mut UniformSampler, &Msac::new(0.3), &opts).unwrap();
        assert_eq!(a.model, b.model);
        assert_eq!(a.inliers, b.inliers);
        assert_eq!(a.iterations, b.iterations);
    }

    #[test]
    fn errors_are_typed() {
        let (line, _) = noisy_line(1, 0.0, 5);
        let e = estimate(
            &line,
            &mut UniformSampler,
            &Msac::new(1.0),
            &RansacOptions::default(),
        )
        .unwrap_err();
        assert_eq!(
            e,
            RansacError::NotEnoughData {
                what: "corrs",
                needed: 2,
                got: 1
            }
        );
        let (line, _) = noisy_line(10, 0.0, 5);
        for o in [
            RansacOptions {
                threshold: 0.0,
                ..Default::default()
            },
            RansacOptions {
                threshold: f64::NAN,
                ..Default::default()
            },
            RansacOptions {
                confidence: 1.0,
                ..Default::default()
            },
            RansacOptions {
                max_iterations: 0,
                ..Default::default()
            },
        ] {
            assert!(matches!(
                estimate(&line, &mut UniformSampler, &Msac::new(1.0), &o),
                Err(RansacError::InvalidOption { .. })
            ));
        }
        // All x equal: every sample is degenerate.
        let flat = Line {
            x: vec![1.0; 10],
            y: (0..10).map(f64::from).collect(),
            lo_refines: true,
            refinement: None,
            refine_calls: Default::default(),
        };
        let e = estimate(
            &flat,
            &mut UniformSampler,
            &Msac::new(1.0),
            &RansacOptions {
                max_iterations: 50,
                ..Default::default()
            },
        );
        assert_eq!(e.unwrap_err(), RansacError::NoModel { iterations: 50 });
    }

    #[test]
    fn graph_cut_lo_needs_positions() {
        let (line, _) = noisy_line(50, 0.2, 6);
        let o = RansacOptions {
            threshold: 0.3,
            lo: LoKind::GraphCut,
            ..Default::default()
        };
        let e = estimate(&line, &mut UniformSampler, &Msac::new(0.3), &o).unwrap_err();
        assert!(
            matches!(e, RansacError::InvalidOption { name: "lo", .. }),
            "{e:?}"
        );
    }

    #[test]
    fn iteration_bound_follows_the_formula() {
        // w = 0.5, m = 2, confidence 0.99: log(0.01)/log(0.75) = 16.0
        assert_eq!(iterations_needed(50, 100, 2, 0.99, 1.0), 17);
        assert_eq!(iterations_needed(100, 100, 5, 0.99, 1.0), 1);
        assert_eq!(iterations_needed(0, 100, 5, 0.99, 1.0), usize::MAX);
        // A test that passes good models with probability 1/2 doubles the odds against.
        // log(0.01)/log(1 − 0.125) = 34.5
        assert_eq!(iterations_needed(50, 100, 2, 0.99, 0.5), 35);
    }
}
