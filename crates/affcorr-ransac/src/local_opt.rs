//! Local optimisation (LO-RANSAC): iterated least squares on a promising hypothesis's inliers
//! along a threshold schedule (the shrinking [`LO_SCHEDULE`], the threshold alone, or both from
//! the same hypothesis: [`crate::LoSchedule`]), each step's candidates (the linear fit and,
//! where the problem wants it, the nonlinear refinement) scored at the true threshold. The
//! inliers of a step are either the data below its threshold or, with
//! [`crate::LoKind::GraphCut`], the graph-cut labelling of [`LoGraph`] (GC-RANSAC).

use crate::graph_cut::GraphCut;
use crate::options::{AffineRefinement, LoSchedule, RansacOptions};
use crate::problem::Problem;
use crate::refine::LmOptions;
use crate::score::Scoring;
use crate::verify::{Scored, Scratch, collect_inliers, score_model};
use affcorr_geom::Vec2;

/// Threshold multipliers of the local optimisation's least-squares steps: from a wide basin to
/// the true threshold (LO-RANSAC's iterative scheme, Lebeda et al., BMVC 2012). The wide first
/// steps pull in true inliers that a noisy minimal model (e.g. from 2 ACs) misses.
pub(crate) const LO_SCHEDULE: [f64; 5] = [8.0, 4.0, 2.0, 1.4, 1.0];

/// The threshold track's schedule: the true threshold from the first step.
const THRESHOLD_SCHEDULE: [f64; 1] = [1.0];

/// Least relative score gain of a local-optimisation step past [`LO_SCHEDULE`] to go on.
const LO_MIN_GAIN: f64 = 0.005;

/// Levenberg–Marquardt steps per refinement inside local optimisation: each schedule step starts
/// where the last one ended, so a few steps per threshold suffice to leave a rough minimal
/// model's basin (5 instead of 3 changed no median error over the profile example's scenes and
/// cost more: benches/results/ransac.md).
pub(crate) const LO_LM_ITERATIONS: usize = 3;
/// Local optimisation refines with Levenberg–Marquardt only at steps whose threshold is at most
/// this multiple of the true one; the wider first steps take the linear fit alone.
const LO_LM_MAX_SCALE: f64 = 2.0;

/// Local optimisation fits on at most this many inliers (an even stride through them): enough
/// to pin a model with ≤ 9 degrees of freedom (LO only has to find the basin and the inlier
/// set; 512 gave the same median errors at a higher cost, benches/results/ransac.md), and it
/// keeps LO's cost
/// independent of N. The score is still computed on all data, and the final refinement uses
/// all inliers.
const LO_MAX_FIT: usize = 256;

/// Keeps an even stride of at most `max` entries of `indices` (and their weights).
fn thin_out(indices: &mut Vec<usize>, weights: &mut Vec<f64>, max: usize) {
    let n = indices.len();
    if n <= max {
        return;
    }
    for k in 0..max {
        let src = k * n / max;
        indices[k] = indices[src];
        weights[k] = weights[src];
    }
    indices.truncate(max);
    weights.truncate(max);
}

/// Local optimisation of `start` along the tracks of `schedule` (resolved: never
/// [`LoSchedule::Auto`]): the widening [`LO_SCHEDULE`], the threshold alone, or both from
/// `start`, keeping the better score.
///
/// A track is iterated least squares on the inliers at its thresholds (multiples of the true
/// one), then at the true threshold while the score improves by more than [`LO_MIN_GAIN`].
/// Each step starts from the track's best model so far, collects its inliers at the step's
/// threshold, and tries two candidates: the linear fit on them and, where the problem wants it
/// ([`Problem::lo_refines`]), the nonlinear refinement of the best model on them (robust to the
/// outliers a wide threshold lets in). Every candidate is scored at the true threshold.
#[allow(clippy::too_many_arguments)]
pub(crate) fn local_optimization<P: Problem, S: Scoring>(
    problem: &P,
    scoring: &S,
    start: Scored<P::Model>,
    schedule: LoSchedule,
    options: &RansacOptions,
    scratch: &mut Scratch<P::Model>,
    mut graph: Option<&mut LoGraph>,
    indices: &mut Vec<usize>,
    weights: &mut Vec<f64>,
) -> Scored<P::Model> {
    let tracks: &[&[f64]] = match schedule {
        LoSchedule::Threshold => &[&THRESHOLD_SCHEDULE],
        LoSchedule::Both => &[&LO_SCHEDULE, &THRESHOLD_SCHEDULE],
        LoSchedule::Auto | LoSchedule::Widening => &[&LO_SCHEDULE],
    };
    let mut result: Option<Scored<P::Model>> = None;
    for &schedule in tracks {
        let mut best = start.clone();
        for step in 0..options.lo_iterations {
            let scale = schedule.get(step).copied().unwrap_or(1.0);
            match graph.as_deref_mut() {
                Some(g) => g.collect(problem, scoring, &best.model, scale, indices, weights),
                None => collect_inliers(
                    problem,
                    scoring,
                    &best.model,
                    scale,
                    scratch,
                    indices,
                    weights,
                ),
            }
            if indices.len() <= problem.sample_size() {
                break;
            }
            thin_out(indices, weights, LO_MAX_FIT);
            let threshold_sq = scoring.inlier_threshold_sq() * scale * scale;
            let refined = (scale <= LO_LM_MAX_SCALE && problem.lo_refines())
                .then(|| {
                    problem.refine(
                        &best.model,
                        indices,
                        &scoring.lo_loss(threshold_sq),
                        &LmOptions {
                            max_iterations: LO_LM_ITERATIONS,
                            affine: options.affine_refinement == AffineRefinement::All,
                            ..Default::default()
                        },
                    )
                })
                .flatten();
            // The linear fit at every step, beside LM: LM's few steps from a rough 2-AC model
            // can stall in a wrong basin on real data (graffiti 1→3 with learned ACs, with the
            // linear fit on the first step only: tests/test_pipeline.py; the errors with and
            // without it are in benches/results/ransac.md).
            let linear = problem.fit_nonminimal(indices, Some(weights));
            let start_score = best.score;
            for model in refined.into_iter().chain(linear) {
                if let Some(e) =
                    score_model(problem, scoring, &model, best.score, usize::MAX, scratch)
                    && e.score > best.score
                {
                    scratch.keep(&model);
                    best = Scored {
                        model,
                        score: e.score,
                        inliers: e.inliers,
                        wide_support: e.wide_support,
                    };
                }
            }
            // Past the schedule, stop at the first step that does not improve the score by
            // LO_MIN_GAIN: a model crawling up a long valley (typically a wrong one) is not
            // worth more refits.
            if step + 1 >= schedule.len() && best.score <= start_score * (1.0 + LO_MIN_GAIN) {
                break;
            }
        }
        if result.as_ref().is_none_or(|r| best.score > r.score) {
            result = Some(best);
        }
    }
    result.unwrap_or(start)
}

/// Graph-cut local optimisation's state: the neighbourhood graph and a buffer for the
/// residuals of all data.
pub(crate) struct LoGraph {
    cut: GraphCut,
    residuals: Vec<f64>,
}

impl LoGraph {
    /// The graph of the data at positions (`x1`, `x2`) and a residual buffer for `n` data.
    pub(crate) fn new(x1: &[Vec2], x2: &[Vec2], n: usize) -> Self {
        Self {
            cut: GraphCut::new(x1, x2),
            residuals: vec![0.0; n],
        }
    }

    /// [`collect_inliers`]'s counterpart: the inliers at `scale` × the threshold are the
    /// minimum-energy labelling of the graph cut, with the same weights.
    fn collect<P: Problem, S: Scoring>(
        &mut self,
        problem: &P,
        scoring: &S,
        model: &P::Model,
        scale: f64,
        indices: &mut Vec<usize>,
        weights: &mut Vec<f64>,
    ) {
        problem.residuals(model, 0, &mut self.residuals);
        let thr = scoring.inlier_threshold_sq() * scale * scale;
        self.cut.label(&self.residuals, thr, indices);
        weights.clear();
        weights.extend(indices.iter().map(|&i| {
            if scale > 1.0 {
                1.0
            } else {
                scoring.weight(self.residuals[i])
            }
        }));
    }
}
