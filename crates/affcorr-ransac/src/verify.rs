//! The verification pass of one hypothesis over all data, and the residual cache it fills.
//!
//! [`score_model`] scores a model block by block with an exact bail-out: it stops as soon as even
//! all-perfect remaining data could beat neither the best score nor the best wide support (the
//! support at [`LO_TRIGGER_SCALE`] × the threshold that earns a local optimisation).
//! [`collect_inliers`] and [`inlier_mask`] read the same residuals. Every complete pass leaves its
//! residuals in the [`Scratch`] cache, so that the inlier collection that follows a new best model
//! (local optimisation's, the final refinement's, the final mask) reads them instead of
//! recomputing. [`Scored`] and [`Evaluation`] are what a pass reports.

use crate::problem::Problem;
use crate::score::Scoring;

/// Residuals are scored in blocks of this many data, checking the bail-out between blocks.
const BLOCK: usize = 256;

/// A hypothesis whose support at this multiple of the threshold is the widest so far also gets a
/// local optimisation, even if its score at the threshold is not the best.
pub(crate) const LO_TRIGGER_SCALE: f64 = 3.0;

/// A model with its score, inlier count and support at [`LO_TRIGGER_SCALE`] × the threshold.
#[derive(Clone)]
pub(crate) struct Scored<M> {
    pub(crate) model: M,
    pub(crate) score: f64,
    pub(crate) inliers: usize,
    pub(crate) wide_support: usize,
}

/// A model's score, its inliers, and its support at [`LO_TRIGGER_SCALE`] × the threshold.
pub(crate) struct Evaluation {
    pub(crate) score: f64,
    pub(crate) inliers: usize,
    pub(crate) wide_support: usize,
}

/// The residual buffers and the count of residuals computed.
///
/// Every complete [`for_each_block`] pass leaves all residuals in `latest`; [`Scratch::keep`]
/// moves them to `kept` when that model becomes the one local optimisation or the final
/// refinement goes on from, so that their next inlier collection (and the final inlier mask)
/// read them instead of recomputing (the instructions it saves: benches/results/ransac.md).
/// `buf` is the SPRT's block buffer.
pub(crate) struct Scratch<M> {
    pub(crate) buf: Vec<f64>,
    pub(crate) evaluations: u64,
    latest: Vec<f64>,
    latest_for: Option<M>,
    kept: Vec<f64>,
    kept_for: Option<M>,
}

impl<M: PartialEq> Scratch<M> {
    pub(crate) fn new(n: usize) -> Self {
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
    pub(crate) fn keep(&mut self, model: &M) {
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
pub(crate) fn score_model<P: Problem, S: Scoring>(
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
pub(crate) fn collect_inliers<P: Problem, S: Scoring>(
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

pub(crate) fn inlier_mask<P: Problem, S: Scoring>(
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
