//! The [`Problem`] trait: what the engine needs to know about a model-fitting problem.
//!
//! A problem owns its data (structure of arrays, so residual loops vectorise) and knows its
//! minimal and non-minimal solvers, its residual and its refinement. The engine never looks at
//! the data itself: samplers, scoring and local optimisation vary independently of the problem.

use crate::loss::Loss;
use crate::options::LoSchedule;
use crate::refine::LmOptions;
use affcorr_geom::Vec2;

/// A hypothesise-and-verify problem.
pub trait Problem: Sync {
    /// The model type (e.g. a 3×3 matrix, a pose).
    type Model: Clone + PartialEq + Send + Sync;

    /// Number of data (correspondences).
    fn len(&self) -> usize;

    /// True when there are no data.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Size of a minimal sample.
    fn sample_size(&self) -> usize;

    /// Fits the models of a minimal sample (indices into the data) and appends them to `out`
    /// (the engine clears it). A degenerate sample appends nothing.
    fn fit_minimal(&self, sample: &[usize], out: &mut Vec<Self::Model>);

    /// Fits one model to a non-minimal set of data (`indices.len() ≥ sample_size()`), optionally
    /// weighted; `None` when the set is degenerate.
    fn fit_nonminimal(&self, indices: &[usize], weights: Option<&[f64]>) -> Option<Self::Model>;

    /// Squared residuals, in the units of the squared threshold, of the data `start..start +
    /// out.len()` under `model`.
    fn residuals(&self, model: &Self::Model, start: usize, out: &mut [f64]);

    /// Squared residuals of the data `indices` (in any order) under `model`, as
    /// [`Problem::residuals`] computes them; used by the SPRT, which verifies data in random
    /// order. The default calls `residuals` once per index.
    fn residuals_at(&self, model: &Self::Model, indices: &[usize], out: &mut [f64]) {
        for (o, &i) in out.iter_mut().zip(indices) {
            self.residuals(model, i, std::slice::from_mut(o));
        }
    }

    /// How many data could each seed a good minimal sample under `model` (the inlier
    /// threshold² is `threshold_sq`), when that differs from its inliers: the stopping rule's
    /// inlier ratio. `None` (the default): the inliers. AC samples override it, since a
    /// 2-AC model is only as good as the samples' affine parts, which the point residual does
    /// not see.
    fn sample_support(&self, model: &Self::Model, threshold_sq: f64) -> Option<usize> {
        let _ = (model, threshold_sq);
        None
    }

    /// Pixel positions (x1, x2) of the data, for the neighbourhood graph of graph-cut local
    /// optimisation; `None` (the default) when the data have none, which makes
    /// [`crate::options::LoKind::GraphCut`] an error.
    fn positions(&self) -> Option<(&[Vec2], &[Vec2])> {
        None
    }

    /// Cost of fitting one minimal sample (all its models) in units of one residual: the SPRT's
    /// t_M, which sets how eagerly it rejects. Default 200.
    fn model_cost(&self) -> f64 {
        200.0
    }

    /// Polishes `model` on `inliers` by minimising Σ `loss`(rᵢ²) of a geometric error with
    /// Levenberg–Marquardt ([`crate::refine::levenberg_marquardt`] under `options`); `None` to
    /// keep the model as it is. The default does nothing.
    fn refine(
        &self,
        model: &Self::Model,
        inliers: &[usize],
        loss: &Loss,
        options: &LmOptions,
    ) -> Option<Self::Model> {
        let _ = (model, inliers, loss, options);
        None
    }

    /// Whether [`Problem::refine`] adds affine terms when [`LmOptions::affine`] asks for them
    /// (H, F and the relative pose on AC data with some confidence above 0). The final
    /// refinement then accepts a model that scores slightly lower on the point residuals, and
    /// falls back to the points-only refinement when it scores lower still (engine). A problem
    /// that adds affine terms without saying so has every such model held to the points-only
    /// score. Default false.
    fn refines_affine(&self) -> bool {
        false
    }

    /// The weight λ (px²) of the affine residual in [`Problem::residuals`] (0: points only),
    /// reported in [`crate::engine::Estimate::affine_weight`]. Default 0.
    fn scoring_affine_weight(&self) -> f64 {
        0.0
    }

    /// Whether local optimisation tries [`Problem::refine`] beside the linear fit
    /// ([`Problem::fit_nonminimal`]) at its narrow steps. Default true. A problem whose linear
    /// fit on the inliers already lands in the final refinement's basin can skip it: LO only
    /// has to find the inlier set, and the final refinement does the geometric fit. (The
    /// fundamental matrix cannot: without LM inside LO, a peer-harness scene at 50% outliers
    /// ended in an F that leaves out a plane, and one refining LO on the best model instead
    /// fixed that scene but lost inliers on another; benches/results/ransac.md.)
    fn lo_refines(&self) -> bool {
        true
    }

    /// The threshold schedules of local optimisation under [`LoSchedule::Auto`]. Default
    /// [`LoSchedule::Widening`].
    fn lo_schedule(&self) -> LoSchedule {
        LoSchedule::Widening
    }
}
