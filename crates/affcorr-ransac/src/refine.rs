//! Levenberg–Marquardt with robust losses (iteratively re-weighted), shared by the problems.
//!
//! A problem implements [`LeastSquares`]: the robust cost of a model over some data, the
//! weighted normal equations JᵀWJ δ = −JᵀW r at a model (W from the loss, IRLS), and a retraction
//! that applies a tangent step (so rotations stay rotations and rank-2 matrices stay rank 2).
//! [`levenberg_marquardt`] adds the damping: (JᵀWJ + λ·diag(JᵀWJ)) δ = −JᵀW r, accepting a step
//! only if the cost decreases (then λ /= 10), else λ *= 10; it stops when the linearised model
//! promises a relative decrease below the tolerance.

pub use crate::loss::Loss;
use nalgebra::{SMatrix, SVector};

/// Normal-equation matrix; a problem with d < 9 degrees of freedom uses the top-left d×d block.
pub type Mat9 = SMatrix<f64, 9, 9>;
/// Normal-equation vector (top d entries used).
pub type Vec9 = SVector<f64, 9>;

/// A robust nonlinear least-squares problem over a model.
pub trait LeastSquares {
    /// The model.
    type Model: Clone;
    /// Degrees of freedom (≤ 9).
    fn dof(&self) -> usize;
    /// Σ ρ(rᵢ²) over `indices`.
    fn cost(&self, model: &Self::Model, indices: &[usize], loss: &Loss) -> f64;
    /// Adds JᵀWJ and JᵀWr over `indices` at `model` (W = ρ′(r²)) and returns the cost. With
    /// `COST` false the caller knows the cost at `model` already ([`levenberg_marquardt`] after
    /// an accepted step, whose cost it has just evaluated) and a kernel may skip the loss's
    /// value and return 0: the Cauchy loss's logarithm costs more than its weight.
    fn normal_equations<const COST: bool>(
        &self,
        model: &Self::Model,
        indices: &[usize],
        loss: &Loss,
        jtj: &mut Mat9,
        jtr: &mut Vec9,
    ) -> f64;
    /// The model moved by the tangent step `delta` (first `dof()` entries).
    fn retract(&self, model: &Self::Model, delta: &Vec9) -> Self::Model;
}

/// Options of [`levenberg_marquardt`].
#[derive(Debug, Clone, Copy)]
pub struct LmOptions {
    /// Most iterations (accepted or rejected steps). Default 25.
    pub max_iterations: usize,
    /// Stop when the relative cost decrease falls below this. Default 1e-6: the model then moves
    /// by ~1e-3 of its standard error, far below the noise (1e-10 made pose and F runs slower
    /// for no measurable gain: benches/results/ransac.md).
    pub cost_tolerance: f64,
    /// Stop when ‖δ‖ falls below this. Default 1e-10.
    pub step_tolerance: f64,
    /// Stop when a step (the one the linearised model promises, or the one just taken) lowers
    /// the cost by less than this fraction of the mean cost per datum. Default 0.01.
    ///
    /// Near the optimum, cost(x) ≈ cost* + δᵀJᵀWJδ with δ = x − x*, and the mean cost per
    /// datum estimates the noise variance σ² times the residuals per datum; a decrease below
    /// 0.01·σ² means the model is less than 0.1 standard error (√0.01) from the optimum in
    /// every direction, far below its noise. Unlike [`LmOptions::cost_tolerance`] the rule does
    /// not tighten with N: on 1000 inliers with a truncated loss, 1e-6 of the cost kept LM
    /// chasing the few residuals that cross the threshold for 4 more steps of no gain.
    pub noise_fraction: f64,
    /// Add the affine terms of ACs to the cost where the problem has them
    /// ([`crate::options::AffineRefinement`]). Default false.
    pub affine: bool,
    /// The damping λ of the first step, relative to the diagonal of JᵀJ (Marquardt's
    /// scaling; each rejected step multiplies it by 10, each accepted one divides it by 10).
    /// Default 1e-3, for starts that may be far from the optimum. Scaling by the diagonal does
    /// not undo correlations between the parameters: a homography's entries in pixel
    /// coordinates are so correlated that λ = 1e-3 shortened the Gauss–Newton step in the
    /// flat directions, and LM crept to the optimum over several steps where one does. A start
    /// known to be close on a convex cost (the homography's points-only refinement from the
    /// linear fit) takes a smaller one.
    pub initial_damping: f64,
}

impl Default for LmOptions {
    fn default() -> Self {
        Self {
            max_iterations: 25,
            cost_tolerance: 1e-6,
            step_tolerance: 1e-10,
            noise_fraction: 0.01,
            affine: false,
            initial_damping: 1e-3,
        }
    }
}

/// Minimises Σ ρ(rᵢ²) from `model`; returns the final model and its cost. Never increases the
/// cost.
pub fn levenberg_marquardt<P: LeastSquares>(
    problem: &P,
    model: &P::Model,
    indices: &[usize],
    loss: &Loss,
    options: &LmOptions,
) -> (P::Model, f64) {
    let d = problem.dof();
    let n = indices.len().max(1) as f64;
    let mut model = model.clone();
    let mut lambda = options.initial_damping;
    let (mut jtj, mut jtr) = (Mat9::zeros(), Vec9::zeros());
    let mut cost = problem.normal_equations::<true>(&model, indices, loss, &mut jtj, &mut jtr);
    let mut fresh = true;
    for _ in 0..options.max_iterations {
        if !fresh {
            // After an accepted step: `cost` is the cost at `model` already.
            jtj.fill(0.0);
            jtr.fill(0.0);
            problem.normal_equations::<false>(&model, indices, loss, &mut jtj, &mut jtr);
        }
        let mut damped = jtj;
        for k in 0..d {
            damped[(k, k)] += lambda * jtj[(k, k)].max(1e-12);
        }
        for k in d..9 {
            damped[(k, k)] = 1.0;
        }
        let Some(chol) = damped.cholesky() else {
            lambda *= 10.0;
            fresh = true;
            continue;
        };
        let mut rhs = -jtr;
        for k in d..9 {
            rhs[k] = 0.0;
        }
        let delta = chol.solve(&rhs);
        // The decrease of Σ w r² that the linearised model promises, −2δᵀJᵀWr − δᵀJᵀWJδ: at
        // the optimum it vanishes, and evaluating (then rejecting) ever more damped steps
        // would only burn cost evaluations until λ overflows.
        let predicted = -(2.0 * delta.dot(&jtr) + delta.dot(&(jtj * delta)));
        let negligible = (options.cost_tolerance * cost).max(options.noise_fraction * cost / n);
        if predicted <= negligible {
            break;
        }
        let candidate = problem.retract(&model, &delta);
        let new_cost = problem.cost(&candidate, indices, loss);
        if new_cost < cost {
            let decrease = cost - new_cost;
            model = candidate;
            cost = new_cost;
            lambda = (lambda / 10.0).max(1e-12);
            fresh = false;
            if decrease < negligible || delta.norm() < options.step_tolerance {
                break;
            }
        } else {
            lambda *= 10.0;
            fresh = true;
            if lambda > 1e12 {
                break;
            }
        }
    }
    (model, cost)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Fit y = exp(a x) + b: a small nonlinear problem with a known optimum.
    struct ExpFit {
        x: Vec<f64>,
        y: Vec<f64>,
    }

    impl LeastSquares for ExpFit {
        type Model = (f64, f64);
        fn dof(&self) -> usize {
            2
        }
        fn cost(&self, m: &(f64, f64), idx: &[usize], loss: &Loss) -> f64 {
            idx.iter()
                .map(|&i| loss.cost((self.y[i] - (m.0 * self.x[i]).exp() - m.1).powi(2)))
                .sum()
        }
        fn normal_equations<const COST: bool>(
            &self,
            m: &(f64, f64),
            idx: &[usize],
            loss: &Loss,
            jtj: &mut Mat9,
            jtr: &mut Vec9,
        ) -> f64 {
            let mut cost = 0.0;
            for &i in idx {
                let e = (m.0 * self.x[i]).exp();
                let r = e + m.1 - self.y[i];
                let j = [self.x[i] * e, 1.0];
                let w = loss.weight(r * r);
                cost += loss.cost(r * r);
                for a in 0..2 {
                    jtr[a] += w * j[a] * r;
                    for b in 0..2 {
                        jtj[(a, b)] += w * j[a] * j[b];
                    }
                }
            }
            cost
        }
        fn retract(&self, m: &(f64, f64), d: &Vec9) -> (f64, f64) {
            (m.0 + d[0], m.1 + d[1])
        }
    }

    #[test]
    fn converges_and_robust_losses_ignore_outliers() {
        let x: Vec<f64> = (0..40).map(|i| i as f64 / 20.0).collect();
        let mut y: Vec<f64> = x.iter().map(|x| (0.7 * x).exp() + 0.3).collect();
        let idx: Vec<usize> = (0..40).collect();
        let p = ExpFit {
            x: x.clone(),
            y: y.clone(),
        };
        let (m, cost) =
            levenberg_marquardt(&p, &(0.0, 0.0), &idx, &Loss::Squared, &LmOptions::default());
        assert!(
            (m.0 - 0.7).abs() < 1e-8 && (m.1 - 0.3).abs() < 1e-8 && cost < 1e-16,
            "{m:?}"
        );
        y[5] += 50.0;
        y[17] -= 30.0;
        let p = ExpFit { x, y };
        let (sq, _) =
            levenberg_marquardt(&p, &(0.5, 0.0), &idx, &Loss::Squared, &LmOptions::default());
        let (rob, _) = levenberg_marquardt(
            &p,
            &(0.5, 0.0),
            &idx,
            &Loss::Cauchy { scale_sq: 0.01 },
            &LmOptions::default(),
        );
        assert!(
            (rob.0 - 0.7).abs() < 1e-3 && (rob.1 - 0.3).abs() < 1e-2,
            "{rob:?}"
        );
        assert!(
            (sq.1 - 0.3).abs() > 0.1,
            "the squared loss is pulled by outliers: {sq:?}"
        );
    }

    /// A counting wrapper: how many normal-equation passes LM takes.
    struct Counted<'a>(&'a ExpFit, std::cell::Cell<usize>);

    impl LeastSquares for Counted<'_> {
        type Model = (f64, f64);
        fn dof(&self) -> usize {
            2
        }
        fn cost(&self, m: &(f64, f64), idx: &[usize], loss: &Loss) -> f64 {
            self.0.cost(m, idx, loss)
        }
        fn normal_equations<const COST: bool>(
            &self,
            m: &(f64, f64),
            idx: &[usize],
            loss: &Loss,
            jtj: &mut Mat9,
            jtr: &mut Vec9,
        ) -> f64 {
            self.1.set(self.1.get() + 1);
            self.0.normal_equations::<COST>(m, idx, loss, jtj, jtr)
        }
        fn retract(&self, m: &(f64, f64), d: &Vec9) -> (f64, f64) {
            self.0.retract(m, d)
        }
    }

    #[test]
    fn stops_once_steps_are_below_the_noise() {
        // Noisy data (σ = 0.05), so the optimum's cost is about N σ².
        let x: Vec<f64> = (0..400).map(|i| i as f64 / 200.0).collect();
        let y: Vec<f64> = x
            .iter()
            .enumerate()
            .map(|(i, x)| (0.7 * x).exp() + 0.3 + 0.05 * ((i * 7919 % 1000) as f64 / 500.0 - 1.0))
            .collect();
        let idx: Vec<usize> = (0..400).collect();
        let fit = ExpFit { x, y };
        let run = |noise_fraction| {
            let p = Counted(&fit, std::cell::Cell::new(0));
            let options = LmOptions {
                noise_fraction,
                cost_tolerance: 1e-15,
                ..Default::default()
            };
            let (_, cost) = levenberg_marquardt(&p, &(0.0, 0.0), &idx, &Loss::Squared, &options);
            (cost, p.1.get())
        };
        let ((exact, passes_exact), (early, passes_early)) = (run(0.0), run(0.01));
        assert!(
            passes_early < passes_exact,
            "{passes_early} vs {passes_exact}"
        );
        // Stopping early costs less than the promised 0.01 σ² per datum in total.
        assert!(early - exact < 0.01 * exact / 400.0, "{early} vs {exact}");
    }
}
