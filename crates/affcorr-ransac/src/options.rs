//! Options of the robust estimator, with their defaults.

use crate::problem::Problem;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

/// A flag that stops an estimate early: set it from another thread (e.g. on Ctrl-C) and the
/// loop ends after the current iteration, keeping the best model so far (then the usual local
/// optimisation and refinement of that model). Clones share the flag; two flags are equal when
/// they are the same flag.
#[derive(Debug, Clone, Default)]
pub struct Cancel(Arc<AtomicBool>);

impl Cancel {
    /// A flag not yet set.
    pub fn new() -> Self {
        Self::default()
    }

    /// Sets the flag.
    pub fn cancel(&self) {
        self.0.store(true, Ordering::Relaxed);
    }

    /// Whether the flag is set.
    pub fn is_cancelled(&self) -> bool {
        self.0.load(Ordering::Relaxed)
    }
}

impl PartialEq for Cancel {
    fn eq(&self, other: &Self) -> bool {
        Arc::ptr_eq(&self.0, &other.0)
    }
}

/// How local optimisation picks the data it refits on at each step.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum LoKind {
    /// Iterated re-weighted least squares on the data below each step's threshold (default).
    #[default]
    Irls,
    /// The same schedule, but each step's inliers are the minimum-energy labelling of a graph
    /// cut with spatial coherence (GC-RANSAC; [`crate::graph_cut`]): neighbours in (x1, x2) pull
    /// data just beyond the threshold in and push isolated data just below it out.
    GraphCut,
}

/// The threshold schedules that local optimisation follows from a promising hypothesis.
///
/// The widening schedule starts at 8× the threshold, so a noisy minimal model (e.g. from two
/// ACs) still collects the true inliers; but a second structure a few pixels off the first (a
/// cluster of matches on a nearby surface, a matcher's local misregistration) is inside that
/// wide band, and the fit on both is a compromise that the narrowing steps keep. A track at the
/// threshold alone (PoseLib's LO) refits on the hypothesis's own inliers and stays on the
/// dominant structure, but can stall where a rough hypothesis needs the wide steps. `Both` runs
/// the two tracks from the same hypothesis and keeps the better score. A schedule with the
/// threshold track also optimises every raw record ([`LoSchedule::has_threshold_track`]).
/// docs/estimation.md ("Two structures a few pixels apart") has the measurements.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum LoSchedule {
    /// The problem's measured choice ([`crate::Problem::lo_schedule`]): [`LoSchedule::Both`]
    /// for homographies (a refit is a small DLT, and the failure was measured on real data),
    /// [`LoSchedule::Widening`] for E and F (on the scene families `Both` cost them 1.1–2.0×
    /// the time for median errors 0.88–1.05× the widening track's: their LO refines with
    /// Levenberg–Marquardt).
    #[default]
    Auto,
    /// From 8× the threshold down to it, then at the threshold while the score improves.
    Widening,
    /// At the threshold only, while the score improves.
    Threshold,
    /// The widening and the threshold tracks from the same hypothesis; the better score wins.
    Both,
}

impl LoSchedule {
    /// The schedule itself, or `problem`'s choice for [`LoSchedule::Auto`].
    pub fn resolve<P: Problem>(self, problem: &P) -> Self {
        match self {
            Self::Auto => problem.lo_schedule(),
            chosen => chosen,
        }
    }

    /// Whether local optimisation runs the threshold track. Then every raw hypothesis that
    /// out-scores the earlier raw ones earns a local optimisation on the threshold track too
    /// (not only one that beats the optimised best): that track keeps such a hypothesis in its
    /// own basin, so a raw hypothesis of the dominant structure can still win after local
    /// optimisation has fitted a compromise. (With the widening track alone it fixed none of
    /// the cluster scenes and cost E and F 1.1–1.8× the time: docs/estimation.md.)
    pub fn has_threshold_track(self) -> bool {
        matches!(self, Self::Threshold | Self::Both)
    }
}

/// Where the affine terms of ACs enter the least-squares fits of a model (AC data; point data
/// ignore it; H refines only at the end, so `All` is `Final` there). Each AC then adds its two affine residuals, whitened by the noise
/// scale of A that the fit estimates from its inliers (the ratio of the median point to the
/// median affine Sampson distance), weighted by the AC's confidence and under a Cauchy loss so
/// that a poor A is down-weighted (docs/estimation.md).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum AffineRefinement {
    /// Points only.
    Off,
    /// In the final Levenberg–Marquardt refinement (default: on the scene families of
    /// benches/results/scene_families.md it is as accurate as [`AffineRefinement::All`] and
    /// cheaper, and up to 30× more accurate than points where A is accurate).
    #[default]
    Final,
    /// In local optimisation's refinements and the final one.
    All,
}

/// Options of [`crate::engine::estimate`]. Defaults are documented at each field.
#[derive(Debug, Clone, PartialEq)]
pub struct RansacOptions {
    /// Inlier threshold in residual units (pixels for every problem here). Default 1.0.
    pub threshold: f64,
    /// Confidence of the adaptive stopping rule. Default 0.9999.
    pub confidence: f64,
    /// ρ in (0, 1], the probability that a minimal sample of seeds (see
    /// [`crate::Problem::sample_support`]) leads to the consensus, in the stopping rule
    /// k = log(1 − confidence) / log(1 − ρ wᵐ). Default 1 (the textbook rule); lower it to
    /// search longer when the seeds' noise is large.
    pub sample_reliability: f64,
    /// Never fewer iterations than this. Default 0.
    pub min_iterations: usize,
    /// Never more iterations than this. Default 10 000.
    pub max_iterations: usize,
    /// Seed of the random generator: the same seed and data give the same result. Default 0.
    pub seed: u64,
    /// Run local optimisation (iterated least squares on the inliers) on every new best model.
    /// Default true.
    pub local_optimization: bool,
    /// How local optimisation selects its data: [`LoKind::Irls`] (default) or
    /// [`LoKind::GraphCut`].
    pub lo: LoKind,
    /// Most least-squares refits in one local optimisation (per track). Default 10.
    pub lo_iterations: usize,
    /// The threshold schedules of local optimisation ([`LoSchedule`]). Default
    /// [`LoSchedule::Auto`].
    pub lo_schedule: LoSchedule,
    /// Polish the final model with the problem's refinement (Levenberg–Marquardt). Default true.
    pub final_refinement: bool,
    /// Verify hypotheses with Wald's sequential probability ratio test (Chum & Matas 2008):
    /// data in a seeded random order, a hypothesis rejected as soon as its likelihood ratio of
    /// "bad" to "good" exceeds the threshold A that minimises the expected run time; ε and δ
    /// are estimated as the run goes, and the iteration bound accounts for the good hypotheses
    /// the test rejects (probability ≈ 1/A). Default true: over 20 seeded scenes per problem
    /// and sample kind it finds models as accurate as without it from a fraction of the
    /// residuals (tests/scoring_sprt.rs; run times in benches/results/ransac.md).
    pub sprt: bool,
    /// Stops the loop early when set (see [`Cancel`]). Default `None`.
    pub cancel: Option<Cancel>,
    /// Where the affine terms enter the refinements ([`AffineRefinement`]). Default
    /// [`AffineRefinement::Final`].
    pub affine_refinement: AffineRefinement,
}

impl Default for RansacOptions {
    fn default() -> Self {
        Self {
            threshold: 1.0,
            confidence: 0.9999,
            sample_reliability: 1.0,
            min_iterations: 0,
            max_iterations: 10_000,
            seed: 0,
            local_optimization: true,
            lo: LoKind::Irls,
            lo_iterations: 10,
            lo_schedule: LoSchedule::Auto,
            final_refinement: true,
            sprt: true,
            cancel: None,
            affine_refinement: AffineRefinement::Final,
        }
    }
}
