//! What the pipeline returns: the ACs of a pair with their timings, and a model estimated from
//! them.

use std::fmt;
use std::time::Duration;

use affcorr_ransac::Estimate;

use crate::views::ViewReport;

/// Wall time of each stage of one pair (see the module docs for what each covers).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Timings {
    /// Decoding, downscaling to `max_side`, resizing to the network's multiples of 32.
    pub decode: Duration,
    /// The backbone network(s), or the dense matcher (with the resizing to its input).
    pub matcher: Duration,
    /// Keypoints and descriptors from the backbone's maps (0 for a dense matcher).
    pub detection: Duration,
    /// Mutual nearest neighbours, the refinement model or LighterGlue; a dense matcher's
    /// balanced sampling.
    pub matching: Duration,
    /// Cutting the 32×32 patches.
    pub patches: Duration,
    /// The shape network and the synthesis of A.
    pub shape_net: Duration,
    /// The affine Lucas–Kanade refinement of the ACs (0 unless enabled,
    /// [`crate::PipelineBuilder::affine_refinement`]).
    pub affine_refine: Duration,
    /// The view cascade: verifying the plain pass and matching synthetic views (0 unless it
    /// ran, [`crate::PipelineBuilder::views`]); the views' own stages are counted in the stages
    /// above as well.
    pub views: Duration,
    /// Guided re-matching (0 unless enabled, [`crate::PipelineBuilder::guided_matching`]).
    pub guided: Duration,
    /// Robust estimation (0 for `match_pair`).
    pub ransac: Duration,
    /// The whole call.
    pub total: Duration,
}

impl Timings {
    /// (name, duration) of each stage in order, then `"total"`.
    pub fn stages(&self) -> [(&'static str, Duration); 11] {
        [
            ("decode", self.decode),
            ("matcher", self.matcher),
            ("detection", self.detection),
            ("matching", self.matching),
            ("patches", self.patches),
            ("shape_net", self.shape_net),
            ("affine_refine", self.affine_refine),
            ("views", self.views),
            ("guided", self.guided),
            ("ransac", self.ransac),
            ("total", self.total),
        ]
    }
}

impl fmt::Display for Timings {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let parts: Vec<String> = self
            .stages()
            .iter()
            .map(|(n, d)| format!("{n} {:.1} ms", d.as_secs_f64() * 1e3))
            .collect();
        f.write_str(&parts.join(", "))
    }
}

/// The ACs of one image pair.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Matches {
    /// `[x1, y1, x2, y2, a11, a12, a21, a22]` in the original images' pixels, A = ∂x2/∂x1,
    /// sorted by decreasing certainty.
    pub corrs: Vec<[f64; 8]>,
    /// The matcher's certainty of each match (MNN: cosine similarity; XFeat*: refinement
    /// confidence; LighterGlue: match score; dense: the certainty map), higher is better.
    pub certainty: Vec<f64>,
    /// The calibrated probability that each AC's A is good (cosine with the true A ≥ 0.9), in
    /// [0, 1], from the shape network's spread, the refinement's outcome and the neighbouring
    /// ACs ([`affcorr_image::confidence`]).
    pub affine_confidence: Vec<f64>,
    /// Whether each AC's A can be trusted: `affine_confidence` at least the calibrated
    /// threshold (an AC whose refinement failed is not reliable). With
    /// [`crate::PipelineBuilder::drop_unreliable`] only reliable ACs are returned.
    pub reliable: Vec<bool>,
    /// Keypoints (or semi-dense cells) found in image A and in image B; for a dense matcher the
    /// cells of its grid with certainty > 0 that warp into B (the same number twice).
    pub num_keypoints: (usize, usize),
    /// Wall time per stage.
    pub timings: Timings,
    /// The views the cascade tried, the plain pair first (empty when it did not run, e.g.
    /// with [`crate::views::ViewMode::Off`]).
    pub views: Vec<ViewReport>,
}

impl Matches {
    /// The view that produced these ACs ([`ViewReport::used`]; `None` when the cascade did
    /// not run).
    pub fn view(&self) -> Option<&ViewReport> {
        self.views.iter().find(|v| v.used).or(self.views.first())
    }

    /// Keeps only the reliable ACs (all per-AC fields alike; an AC without a flag is dropped).
    pub fn retain_reliable(&mut self) {
        fn keep_flagged<T>(v: &mut Vec<T>, keep: &[bool]) {
            let mut flags = keep.iter();
            v.retain(|_| flags.next().copied().unwrap_or(false));
        }
        let keep = std::mem::take(&mut self.reliable);
        keep_flagged(&mut self.corrs, &keep);
        keep_flagged(&mut self.certainty, &keep);
        keep_flagged(&mut self.affine_confidence, &keep);
        self.reliable = vec![true; self.corrs.len()];
    }

    /// The number of ACs.
    pub fn len(&self) -> usize {
        self.corrs.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.corrs.is_empty()
    }
}

/// Matches and the model estimated from them.
#[derive(Debug, Clone)]
pub struct Estimated<M> {
    /// The ACs the model was estimated from (their `timings.ransac` is set).
    pub matches: Matches,
    /// The robust estimate; `inliers` indexes `matches.corrs`.
    pub estimate: Estimate<M>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn retain_reliable_keeps_the_per_ac_fields_aligned() {
        let row = |k: f64| [k, 0.0, k, 0.0, 1.0, 0.0, 0.0, 1.0];
        let mut m = Matches {
            corrs: vec![row(0.0), row(1.0), row(2.0)],
            certainty: vec![0.9, 0.8, 0.7],
            affine_confidence: vec![0.95, 0.2, 0.99],
            reliable: vec![true, false, true],
            ..Default::default()
        };
        m.retain_reliable();
        assert_eq!(m.corrs, vec![row(0.0), row(2.0)]);
        assert_eq!(m.certainty, vec![0.9, 0.7]);
        assert_eq!(m.affine_confidence, vec![0.95, 0.99]);
        assert_eq!(m.reliable, vec![true, true]);
        // An AC without a flag is not kept (and nothing panics).
        m.reliable.pop();
        m.retain_reliable();
        assert_eq!((m.corrs.len(), m.certainty.len()), (1, 1));
    }
}
