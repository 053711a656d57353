//! The hypothesise-and-verify loop, generic over [`Problem`], [`Sampler`] and [`Scoring`].
//!
//! Per iteration: draw a minimal sample, fit its models, score each against all data (in blocks,
//! with an exact bail-out), and on a new best model run local optimisation and tighten the
//! adaptive iteration bound k = log(1 − confidence) / log(1 − ρ wᵐ) (m: sample size; w: the
//! fraction of data that can seed a good sample — the inliers, and for AC samples only those
//! whose affine part is accurate too; ρ: [`RansacOptions::sample_reliability`]). Finally the
//! best model is refined on its inliers. Buffers are allocated once, before the loop; the same
//! seed and data always give the same result.

use crate::error::{RansacError, Result};
use crate::graph_cut::GraphCut;
use crate::options::{LoKind, RansacOptions};
use crate::problem::Problem;
use crate::refine::LmOptions;
use crate::sampler::Sampler;
use crate::score::Scoring;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

/// Residuals are scored in blocks of this many data, checking the bail-out between blocks.
const BLOCK: usize = 256;

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
}

/// A model with its score, inlier count and support at [`LO_TRIGGER_SCALE`] × the threshold.
#[derive(Clone)]
struct Scored<M> {
    model: M,
    score: f64,
    inliers: usize,
    wide_support: usize,
}

/// A model's score, its inliers, and its support at [`LO_TRIGGER_SCALE`] × the threshold.
struct Evaluation {
    score: f64,
    inliers: usize,
    wide_support: usize,
}

/// The residual buffers and the count of residuals computed.
///
/// Every complete [`for_each_block`] pass leaves all residuals in `latest`; [`Scratch::keep`]
/// moves them to `kept` when that model becomes the one local optimisation or the final
/// refinement goes on from, so that their next inlier collection (and the final inlier mask)
/// read them instead of recomputing: 8% of a homography run's instructions. `buf` is the SPRT's
/// block buffer.
struct Scratch<M> {
    buf: Vec<f64>,
    evaluations: u64,
    latest: Vec<f64>,
    latest_for: Option<M>,
    kept: Vec<f64>,
    kept_for: Option<M>,
}

impl<M: PartialEq> Scratch<M> {
    fn new(n: usize) -> Self {
        Self {
            buf: vec![0.0; BLOCK.min(n)],
            evaluations: 0,
            latest: vec![0.0; n],
            latest_for: None,
            kept: vec![0.0; n],
            kept_for: None,
        }
    }

    /// Keeps the residuals of the last complete pass (if it was of `model`).
    fn keep(&mut self, model: &M) {
        if self.latest_for.as_ref() == Some(model) {
            std::mem::swap(&mut self.latest, &mut self.kept);
            std::mem::swap(&mut self.latest_for, &mut self.kept_for);
        }
    }

    /// All residuals under `model`, if a complete pass left them.
    fn cached(&self, model: &M) -> Option<&[f64]> {
        if self.kept_for.as_ref() == Some(model) {
            Some(&self.kept)
        } else if self.latest_for.as_ref() == Some(model) {
            Some(&self.latest)
        } else {
            None
        }
    }
}

/// Scores `model` on all data; `None` as soon as it can beat neither `to_beat` (the best score)
/// nor `wide_to_beat` (the best wide support).
fn score_model<P: Problem, S: Scoring>(
    problem: &P,
    scoring: &S,
    model: &P::Model,
    to_beat: f64,
    wide_to_beat: usize,
    scratch: &mut Scratch<P::Model>,
) -> Option<Evaluation> {
    let n = problem.len();
    let thr = scoring.inlier_threshold_sq();
    let wide_thr = thr * LO_TRIGGER_SCALE * LO_TRIGGER_SCALE;
    let (mut score, mut inliers, mut wide_support) = (0.0, 0usize, 0usize);
    let complete = for_each_block(problem, model, scratch, |start, block| {
        for &r2 in block {
            score += scoring.quality(r2);
            inliers += usize::from(r2 < thr);
            wide_support += usize::from(r2 < wide_thr);
        }
        // Even if every remaining datum were perfect, could it still win on either count?
        let rest = n - start - block.len();
        score + rest as f64 > to_beat || wide_support + rest > wide_to_beat
    });
    complete.then_some(Evaluation {
        score,
        inliers,
        wide_support,
    })
}

/// Indices of the data with squared residual below `scale²` × the inlier threshold, and their
/// weights (the scoring's weight at the true threshold, 1 beyond it).
fn collect_inliers<P: Problem, S: Scoring>(
    problem: &P,
    scoring: &S,
    model: &P::Model,
    scale: f64,
    scratch: &mut Scratch<P::Model>,
    indices: &mut Vec<usize>,
    weights: &mut Vec<f64>,
) {
    indices.clear();
    weights.clear();
    let thr = scoring.inlier_threshold_sq() * scale * scale;
    for_each_block(problem, model, scratch, |start, block| {
        for (k, &r2) in block.iter().enumerate() {
            if r2 < thr {
                indices.push(start + k);
                weights.push(if scale > 1.0 { 1.0 } else { scoring.weight(r2) });
            }
        }
        true
    });
}

/// Hands the squared residuals of all data under `model`, block by block with each block's
/// first index, to `visit`, which returns false to stop early. Returns whether every block was
/// visited. The residuals come from the scratch's cache when a complete pass of `model` left
/// them (as one block); otherwise they are computed into `latest`, and a complete pass leaves
/// them cached there.
fn for_each_block<P: Problem>(
    problem: &P,
    model: &P::Model,
    scratch: &mut Scratch<P::Model>,
    mut visit: impl FnMut(usize, &[f64]) -> bool,
) -> bool {
    if let Some(all) = scratch.cached(model) {
        return visit(0, all);
    }
    scratch.latest_for = None;
    let n = problem.len();
    let mut start = 0;
    while start < n {
        let len = BLOCK.min(n - start);
        let block = &mut scratch.latest[start..start + len];
        problem.residuals(model, start, block);
        scratch.evaluations += len as u64;
        if !visit(start, block) {
            return false;
        }
        start += len;
    }
    scratch.latest_for = Some(model.clone());
    true
}

/// Data per SPRT decision: the likelihood ratio is tested after each chunk of this many data
/// (a group-sequential form of Wald's test).
const SPRT_CHUNK: usize = 16;

/// Wald's sequential probability ratio test of a hypothesis (Matas & Chum, ICCV 2005; Chum &
/// Matas, PAMI 2008), with ε (probability that a datum is consistent with a good model) and δ
/// (with a bad one) estimated during the run.
///
/// Data are visited in a fixed, seeded random order (the input may be sorted, e.g. by plane or
/// by matcher score); after each datum the likelihood ratio λ is multiplied by δ/ε (consistent)
/// or (1 − δ)/(1 − ε) (not), and the hypothesis is rejected once λ > A. A is the optimum of
/// the expected run time, A = t_M·C/m_S + 1 + ln A with C = (1 − δ) ln((1 − δ)/(1 − ε)) +
/// δ ln(δ/ε), t_M the cost of a minimal fit in residuals ([`Problem::model_cost`]) and m_S the
/// mean number of models per sample. A good model is rejected with probability ≤ 1/A, which
/// the iteration bound compensates for.
struct Sprt {
    order: Vec<usize>,
    /// Squared residual below which a datum is consistent.
    threshold_sq: f64,
    epsilon: f64,
    delta: f64,
    log_a: f64,
    /// ln(δ/ε) and ln((1 − δ)/(1 − ε)).
    step_consistent: f64,
    step_inconsistent: f64,
    model_cost: f64,
    samples: u64,
    models: u64,
    /// Consistent and evaluated data over the rejected hypotheses (δ's estimate).
    rejected_consistent: u64,
    rejected_evaluated: u64,
    /// Hypotheses rejected.
    rejections: usize,
}

/// The SPRT's outcome for one hypothesis.
enum Verdict {
    /// Verified on all data.
    Complete(Evaluation),
    /// Rejected by the SPRT.
    Rejected,
    /// Stopped by the exact bail-out (cannot beat the best).
    Beaten,
}

impl Sprt {
    const INITIAL_EPSILON: f64 = 0.1;
    const INITIAL_DELTA: f64 = 0.01;

    fn new(n: usize, threshold_sq: f64, model_cost: f64, rng: &mut Pcg64) -> Self {
        let order = visiting_order(n, rng);
        let mut s = Self {
            order,
            threshold_sq,
            epsilon: Self::INITIAL_EPSILON,
            delta: Self::INITIAL_DELTA,
            log_a: f64::INFINITY,
            step_consistent: 0.0,
            step_inconsistent: 0.0,
            model_cost,
            samples: 0,
            models: 0,
            rejected_consistent: 0,
            rejected_evaluated: 0,
            rejections: 0,
        };
        s.update_threshold();
        s
    }

    /// Recomputes A and the λ steps from ε, δ and m_S.
    fn update_threshold(&mut self) {
        let (e, d) = (self.epsilon, self.delta);
        // The test separates nothing when a bad model explains as much as a good one.
        if !(d < 0.8 * e && e < 1.0) {
            self.log_a = f64::INFINITY;
            return;
        }
        let c = (1.0 - d) * ((1.0 - d) / (1.0 - e)).ln() + d * (d / e).ln();
        let m_s = if self.samples == 0 {
            1.0
        } else {
            (self.models as f64 / self.samples as f64).max(1.0)
        };
        let base = self.model_cost * c / m_s + 1.0;
        let mut a = base;
        for _ in 0..20 {
            let next = base + a.ln();
            if (next - a).abs() < 1e-9 * a {
                a = next;
                break;
            }
            a = next;
        }
        self.log_a = a.ln();
        self.step_consistent = (d / e).ln();
        self.step_inconsistent = ((1.0 - d) / (1.0 - e)).ln();
    }

    /// Probability that a good model passes the test, 1 − 1/A.
    fn pass_probability(&self) -> f64 {
        1.0 - (-self.log_a).exp()
    }

    /// A new best model with `consistent` of `n` data consistent: ε follows it.
    fn new_best(&mut self, consistent: usize, n: usize) {
        let e = (consistent as f64 / n as f64).clamp(1e-6, 1.0 - 1e-6);
        if e > self.epsilon {
            self.epsilon = e;
            self.update_threshold();
        }
    }

    /// Verifies `model`; see [`Verdict`].
    #[allow(clippy::too_many_arguments)]
    fn verify<P: Problem, S: Scoring>(
        &mut self,
        problem: &P,
        scoring: &S,
        model: &P::Model,
        to_beat: f64,
        wide_to_beat: usize,
        scratch: &mut Scratch<P::Model>,
    ) -> Verdict {
        let n = problem.len();
        let thr = scoring.inlier_threshold_sq();
        let wide_thr = thr * LO_TRIGGER_SCALE * LO_TRIGGER_SCALE;
        let (mut score, mut inliers, mut wide_support) = (0.0, 0usize, 0usize);
        let (mut consistent, mut log_lambda) = (0usize, 0.0);
        let mut done = 0;
        while done < n {
            let len = SPRT_CHUNK.min(n - done);
            let buf = &mut scratch.buf[..len];
            problem.residuals_at(model, &self.order[done..done + len], buf);
            scratch.evaluations += len as u64;
            let mut c = 0usize;
            for &r2 in buf.iter() {
                score += scoring.quality(r2);
                inliers += usize::from(r2 < thr);
                wide_support += usize::from(r2 < wide_thr);
                c += usize::from(r2 < self.threshold_sq);
            }
            consistent += c;
            done += len;
            log_lambda +=
                c as f64 * self.step_consistent + (len - c) as f64 * self.step_inconsistent;
            if log_lambda > self.log_a {
                self.rejections += 1;
                self.rejected_consistent += consistent as u64;
                self.rejected_evaluated += done as u64;
                let d = (self.rejected_consistent as f64 / self.rejected_evaluated as f64)
                    .clamp(1e-4, 0.5);
                // Re-derive A when δ's estimate moved by more than 5%.
                if (d - self.delta).abs() > 0.05 * self.delta {
                    self.delta = d;
                    self.update_threshold();
                }
                return Verdict::Rejected;
            }
            let rest = n - done;
            if !(score + rest as f64 > to_beat || wide_support + rest > wide_to_beat) {
                return Verdict::Beaten;
            }
        }
        Verdict::Complete(Evaluation {
            score,
            inliers,
            wide_support,
        })
    }
}

/// A seeded permutation of 0..n that spreads neighbours of the input far apart: k ↦ (a + k·b)
/// mod n with b coprime to n near n/φ (golden-ratio stepping), from a random start a. As good
/// as a shuffle for the SPRT, which only needs early data to represent all (inputs sorted by
/// plane or by matcher score), and 10× cheaper than Fisher–Yates (one draw instead of n).
fn visiting_order(n: usize, rng: &mut Pcg64) -> Vec<usize> {
    if n < 2 {
        return (0..n).collect();
    }
    let gcd = |mut a: usize, mut b: usize| {
        while b != 0 {
            (a, b) = (b, a % b);
        }
        a
    };
    let mut step = ((n as f64 / 1.618_033_988_749_895) as usize).max(1);
    while gcd(step, n) != 1 {
        step += 1;
    }
    let mut at = rng.random_range(0..n);
    (0..n)
        .map(|_| {
            let i = at;
            at += step;
            if at >= n {
                at -= n;
            }
            i
        })
        .collect()
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
    let n = problem.len();
    let m = problem.sample_size();
    if n < m {
        return Err(RansacError::NotEnoughData {
            what: "corrs",
            needed: m,
            got: n,
        });
    }
    let mut rng = Pcg64::seed_from_u64(options.seed);
    let mut sample = vec![0usize; m];
    let mut models: Vec<P::Model> = Vec::with_capacity(16);
    let mut scratch = Scratch::new(n);
    let (mut lo_indices, mut lo_weights) = (Vec::with_capacity(n), Vec::with_capacity(n));
    let lo = options.local_optimization;
    let mut graph = match (lo, options.lo) {
        (true, LoKind::GraphCut) => {
            let (x1, x2) = problem.positions().ok_or(RansacError::InvalidOption {
                name: "lo",
                value: "graph_cut".into(),
                reason: "graph-cut local optimisation needs data with positions",
            })?;
            Some(LoGraph {
                cut: GraphCut::new(x1, x2),
                residuals: vec![0.0; n],
            })
        }
        _ => None,
    };
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

    let mut best: Option<Scored<P::Model>> = None;
    let mut best_wide_support = 0usize;
    let mut bound = options.max_iterations;
    let (mut iterations, mut lo_runs) = (0, 0);
    while iterations
        < bound
            .max(options.min_iterations)
            .min(options.max_iterations)
    {
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
            let e = match sprt.as_mut() {
                None => score_model(
                    problem,
                    scoring,
                    &model,
                    to_beat,
                    wide_to_beat,
                    &mut scratch,
                ),
                Some(s) => match s.verify(
                    problem,
                    scoring,
                    &model,
                    to_beat,
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
            if e.score <= to_beat && !promising {
                continue;
            }
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

    let mut best = best.ok_or(RansacError::NoModel { iterations })?;
    let mut refinements = 0;
    if options.final_refinement {
        // Refine on the inliers, then again on the refined model's inliers while that set
        // changes (at most FINAL_ROUNDS): data that the polished model brings within the
        // threshold join the fit, as in a refinement over all data with the truncated loss.
        let mut previous: Vec<usize> = Vec::new();
        for _ in 0..FINAL_ROUNDS {
            collect_inliers(
                problem,
                scoring,
                &best.model,
                1.0,
                &mut scratch,
                &mut lo_indices,
                &mut lo_weights,
            );
            if lo_indices.len() < m || lo_indices == previous {
                break;
            }
            let Some(refined) = problem.refine(
                &best.model,
                &lo_indices,
                // The scoring's own cost: the refined model optimises what the score measures.
                &scoring.refinement_loss(),
                &LmOptions {
                    max_iterations: FINAL_LM_ITERATIONS,
                    noise_fraction: FINAL_NOISE_FRACTION,
                    ..Default::default()
                },
            ) else {
                break;
            };
            match score_model(
                problem,
                scoring,
                &refined,
                best.score,
                usize::MAX,
                &mut scratch,
            ) {
                Some(e) if e.score > best.score => {
                    scratch.keep(&refined);
                    best = Scored {
                        model: refined,
                        score: e.score,
                        inliers: e.inliers,
                        wide_support: e.wide_support,
                    };
                    refinements += 1;
                }
                _ => break,
            }
            std::mem::swap(&mut previous, &mut lo_indices);
        }
    }
    let inliers = inlier_mask(problem, scoring, &best.model, &mut scratch);
    Ok(Estimate {
        num_inliers: inliers.iter().filter(|&&b| b).count(),
        model: best.model,
        inliers,
        score: best.score,
        iterations,
        lo_runs,
        refinements,
        residual_evaluations: scratch.evaluations,
        sprt_rejections: sprt.map_or(0, |s| s.rejections),
    })
}

/// Threshold multipliers of the local optimisation's least-squares steps: from a wide basin to
/// the true threshold (LO-RANSAC's iterative scheme, Lebeda et al., BMVC 2012). The wide first
/// steps pull in true inliers that a noisy minimal model (e.g. from 2 ACs) misses.
pub(crate) const LO_SCHEDULE: [f64; 5] = [8.0, 4.0, 2.0, 1.4, 1.0];

/// A hypothesis whose support at this multiple of the threshold is the widest so far also gets a
/// local optimisation, even if its score at the threshold is not the best.
const LO_TRIGGER_SCALE: f64 = 3.0;

/// Least relative score gain of a local-optimisation step past [`LO_SCHEDULE`] to go on.
const LO_MIN_GAIN: f64 = 0.005;

/// Levenberg–Marquardt steps per refinement inside local optimisation: each schedule step starts
/// where the last one ended, so a few steps per threshold suffice to leave a rough minimal
/// model's basin (5 instead of 3 changed no median error over the profile example's scenes and
/// cost 15–30% more).
const LO_LM_ITERATIONS: usize = 3;
/// Local optimisation refines with Levenberg–Marquardt only at steps whose threshold is at most
/// this multiple of the true one; the wider first steps take the linear fit alone.
const LO_LM_MAX_SCALE: f64 = 2.0;
/// Levenberg–Marquardt steps of the final refinement.
const FINAL_LM_ITERATIONS: usize = 100;
/// The final refinement's [`LmOptions::noise_fraction`]: it stops once a step would move the
/// model by less than √0.001 ≈ 0.03 standard errors. From a linear fit (H: no LM inside LO)
/// the default 0.01 raised the median H error over 200 profile scenes by 1.5% (0.0357 →
/// 0.0362 px); 0.001 costs one more normal-equation pass on the inliers.
const FINAL_NOISE_FRACTION: f64 = 0.001;
/// Most refine-and-recollect rounds of the final refinement.
const FINAL_ROUNDS: usize = 4;

/// Local optimisation fits on at most this many inliers (an even stride through them): enough
/// to pin a model with ≤ 9 degrees of freedom (LO only has to find the basin and the inlier
/// set; 512 gave the same median errors at 1.3–1.4× the cost), and it keeps LO's cost
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

/// Iterated least squares on the inliers at shrinking thresholds, then at the true threshold
/// while the score improves by more than [`LO_MIN_GAIN`]. Each step starts from the best model
/// so far, collects its inliers at the step's threshold, and tries two candidates: the linear
/// fit on them and, where the problem wants it ([`Problem::lo_refines`]), the nonlinear
/// refinement of the best model on them (robust to the outliers a wide threshold lets in). Every
/// candidate is scored at the true threshold.
#[allow(clippy::too_many_arguments)]
fn local_optimization<P: Problem, S: Scoring>(
    problem: &P,
    scoring: &S,
    mut best: Scored<P::Model>,
    options: &RansacOptions,
    scratch: &mut Scratch<P::Model>,
    mut graph: Option<&mut LoGraph>,
    indices: &mut Vec<usize>,
    weights: &mut Vec<f64>,
) -> Scored<P::Model> {
    for step in 0..options.lo_iterations {
        let scale = LO_SCHEDULE.get(step).copied().unwrap_or(1.0);
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
                        ..Default::default()
                    },
                )
            })
            .flatten();
        // The linear fit at every step, beside LM: LM's few steps from a rough 2-AC model can
        // stall in a wrong basin on real data (graffiti 1→3 with learned ACs: H corner error
        // 2–6.6 px on 6 of 8 seeds at 2 px with the linear fit on the first step only, 0.8 px on
        // all seeds with it at every step; tests/test_pipeline.py).
        let linear = problem.fit_nonminimal(indices, Some(weights));
        let start_score = best.score;
        for model in refined.into_iter().chain(linear) {
            if let Some(e) = score_model(problem, scoring, &model, best.score, usize::MAX, scratch)
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
        // LO_MIN_GAIN: a model crawling up a long valley (typically a wrong one) is not worth
        // more refits.
        if step + 1 >= LO_SCHEDULE.len() && best.score <= start_score * (1.0 + LO_MIN_GAIN) {
            break;
        }
    }
    best
}

/// Graph-cut local optimisation's state: the neighbourhood graph and a buffer for the
/// residuals of all data.
struct LoGraph {
    cut: GraphCut,
    residuals: Vec<f64>,
}

impl LoGraph {
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

fn inlier_mask<P: Problem, S: Scoring>(
    problem: &P,
    scoring: &S,
    model: &P::Model,
    scratch: &mut Scratch<P::Model>,
) -> Vec<bool> {
    let thr = scoring.inlier_threshold_sq();
    let mut mask = Vec::with_capacity(problem.len());
    for_each_block(problem, model, scratch, |_, block| {
        mask.extend(block.iter().map(|&r2| r2 < thr));
        true
    });
    mask
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::loss::Loss;
    use crate::sampler::UniformSampler;
    use crate::score::Msac;
    use rand::Rng;

    /// 2-D line fitting y = a x + b: the smallest problem that exercises every path.
    struct Line {
        x: Vec<f64>,
        y: Vec<f64>,
        lo_refines: bool,
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
            _: &[usize],
            _: &Loss,
            options: &LmOptions,
        ) -> Option<(f64, f64)> {
            self.refine_calls.lock().unwrap().push(*options);
            None
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
            refine_calls: Default::default(),
        };
        (line, truth)
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
    fn visiting_order_is_a_seeded_permutation_that_spreads_sorted_input() {
        for n in [0, 1, 2, 7, 100, 2000, 2001] {
            let mut rng = Pcg64::seed_from_u64(3);
            let order = visiting_order(n, &mut rng);
            let mut seen = vec![false; n];
            for &i in &order {
                assert!(!seen[i], "n = {n}: {i} twice");
                seen[i] = true;
            }
            assert!(seen.iter().all(|&s| s), "n = {n}");
            assert_eq!(order, visiting_order(n, &mut Pcg64::seed_from_u64(3)));
            // The first tenth of the visits covers every tenth of a sorted input.
            if n >= 100 {
                let mut decile = [0usize; 10];
                for &i in &order[..n / 10] {
                    decile[i * 10 / n] += 1;
                }
                assert!(decile.iter().all(|&c| c >= n / 200), "n = {n}: {decile:?}");
            }
        }
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
