//! Wald's sequential probability ratio test (SPRT) of a hypothesis, the verification the loop
//! runs instead of [`crate::verify::score_model`] when [`crate::RansacOptions::sprt`] is on: it
//! rejects most bad hypotheses after a few dozen residuals, and keeps the exact bail-out of the
//! plain pass. Also the seeded visiting order it reads the data in.

use crate::problem::Problem;
use crate::score::Scoring;
use crate::verify::{Evaluation, LO_TRIGGER_SCALE, Scratch};
use rand::Rng;
use rand_pcg::Pcg64;

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
pub(crate) struct Sprt {
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
    pub(crate) samples: u64,
    pub(crate) models: u64,
    /// Consistent and evaluated data over the rejected hypotheses (δ's estimate).
    rejected_consistent: u64,
    rejected_evaluated: u64,
    /// Hypotheses rejected.
    pub(crate) rejections: usize,
}

/// The SPRT's outcome for one hypothesis.
pub(crate) enum Verdict {
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

    pub(crate) fn new(n: usize, threshold_sq: f64, model_cost: f64, rng: &mut Pcg64) -> Self {
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
    pub(crate) fn pass_probability(&self) -> f64 {
        1.0 - (-self.log_a).exp()
    }

    /// A new best model with `consistent` of `n` data consistent: ε follows it.
    pub(crate) fn new_best(&mut self, consistent: usize, n: usize) {
        let e = (consistent as f64 / n as f64).clamp(1e-6, 1.0 - 1e-6);
        if e > self.epsilon {
            self.epsilon = e;
            self.update_threshold();
        }
    }

    /// Verifies `model`; see [`Verdict`].
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn verify<P: Problem, S: Scoring>(
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
/// plane or by matcher score), and cheaper than Fisher–Yates: one draw instead of n.
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

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

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
}
