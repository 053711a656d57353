//! A calibrated confidence per AC: the probability that its A is good, and a `reliable` flag.
//!
//! The shape network's A is often far off (issue 19: median ‖A − A_gt‖_F 0.7 on an unseen stereo
//! pair), and where the affine Lucas–Kanade refinement ([`crate::refine_affine`]) fails its
//! checks it returns the input A unchanged. So every AC carries `affine_confidence` ∈ [0, 1],
//! the calibrated probability that its A is *good* — cosine similarity of vec(A) and vec(A_gt)
//! of at least 0.9 — and `reliable = affine_confidence ≥ threshold`; where a refinement ran,
//! only a refined AC can be reliable (one whose refinement failed carries the input's A).
//!
//! # Features
//!
//! What is known about an AC, per row (φ₀ = 1, the bias):
//!
//! | φ | name | value |
//! |---|---|---|
//! | 1 | `refined` | 1 where the refinement converged and passed its checks, else 0 |
//! | 2 | `zncc` | −ln(1.001 − z), z the refined AC's final ZNCC (0 unless refined) |
//! | 3 | `shift_std` | ln of the refined shift's standard deviation, px, from σ² H⁻¹ (0 unless refined) |
//! | 4 | `affine_std` | ln of the refined A's expected ‖δA‖_F from σ² H⁻¹ (0 unless refined) |
//! | 5 | `angle_spread` | ln of the network's angular spread, Σ over both patches of 1 − ‖Σ p e^{iθ}‖ |
//! | 6 | `scale_spread` | ln of the network's log-scale spread, √(Var_a ln S + Var_b ln S) |
//! | 7 | `neighbour_spread` | ln(0.01 + median ‖A − A_j‖_F over the [`NEIGHBOURS`] nearest ACs in image A) |
//! | 8 | `local_fit` | ln(0.01 + ‖A − M‖_F), M the least-squares affine map of those neighbours' x1 → x2 |
//!
//! (each clamped to a finite range; without neighbours, φ₇ = φ₈ = ln 0.31). The confidence is
//! a logistic model, c = 1 / (1 + exp(−w·φ)), one weight vector per [`ConfidenceModel`] — what
//! is known: the network's spread, the refinement's outcome, or both; the features of what is
//! not known are 0 and their weights too.
//!
//! # Calibration
//!
//! The weights and thresholds were fitted by `benches/affcorr_bench/confidence.py --calibrate`
//! (L2-regularised logistic regression) on held-out data only: the six validation images of
//! the shape training (`affcorr.train.sources`, never trained on) under random plane-induced
//! homographies (seeds distinct from the evaluation's), at XFeat + LighterGlue's matches (1024
//! and 2048 keypoints per image: the neighbour features depend on the density); the
//! threshold is the least confidence at which, on that data, fewer than 0.6 % of the reliable
//! ACs have cosine < 0.9, and at least 0.9 (an AC is reliable only when it is itself at least
//! 90 % likely good); non-planar synthetic scenes of the same images (A_gt from depth) are in
//! the calibration set too. Fit and figures: benches/results/confidence.md and
//! benches/results/confidence_calibration.json. Graffiti, the chessboard stereo set and the
//! motorcycle pair (the evaluation's) were not used.

use rayon::prelude::*;

use crate::affine_refine::{AffineRefinement, RefineStatus};
use crate::error::{ImageError, Result};

/// The number of neighbouring ACs the agreement features look at.
pub const NEIGHBOURS: usize = 8;
/// The number of features, the bias included.
pub const FEATURES: usize = 9;
/// The features' names, in order (see the module docs).
pub const FEATURE_NAMES: [&str; FEATURES] = [
    "bias",
    "refined",
    "zncc",
    "shift_std",
    "affine_std",
    "angle_spread",
    "scale_spread",
    "neighbour_spread",
    "local_fit",
];

/// The feature value of a missing neighbourhood (fewer than two ACs): ln 0.31.
const MISSING_NEIGHBOURS: f64 = 0.3;

/// The network's own uncertainty about one AC (from the softmax distributions of its angle and
/// scale classifiers, both patches; `affcorr_runner::ShapePrediction::spread`).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct NetworkSpread {
    /// Σ over both patches of 1 − R, R = ‖Σ_k p_k e^{iθ_k}‖ the mean resultant length: 0 for a
    /// certain orientation, up to 2.
    pub angle: f64,
    /// √(Var_a ln S + Var_b ln S) under the two scale distributions.
    pub scale: f64,
}

/// What the confidence is computed from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum ConfidenceModel {
    /// The network's ACs alone (no refinement).
    #[default]
    Network,
    /// Refined ACs without the network's spread (`refine_affine` on any ACs).
    Refinement,
    /// The network's ACs, refined (the default output of the pipeline and the estimator).
    NetworkRefinement,
}

impl ConfidenceModel {
    /// Every model.
    pub const ALL: [ConfidenceModel; 3] =
        [Self::Network, Self::Refinement, Self::NetworkRefinement];

    /// `"network"`, `"refinement"` or `"network_refinement"`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Network => "network",
            Self::Refinement => "refinement",
            Self::NetworkRefinement => "network_refinement",
        }
    }

    /// The logistic weights over [`FEATURE_NAMES`] (calibrated, see the module docs).
    pub fn weights(self) -> &'static [f64; FEATURES] {
        &self.constants().0
    }

    /// The least `affine_confidence` of a reliable AC.
    pub fn threshold(self) -> f64 {
        self.constants().1
    }

    fn constants(self) -> &'static ([f64; FEATURES], f64) {
        match self {
            Self::Network => &calibration::NETWORK,
            Self::Refinement => &calibration::REFINEMENT,
            Self::NetworkRefinement => &calibration::NETWORK_REFINEMENT,
        }
    }
}

/// The calibrated constants: (weights over [`FEATURE_NAMES`], threshold).
mod calibration {
    use super::FEATURES;

    // benches/results/confidence_calibration.json, written by
    // `.venv/bin/python -m affcorr_bench.confidence --calibrate --per-image 20 --scenes 30`
    // (82 349 correct matches of 150 held-out pairs at 1024 and 2048 keypoints;
    // AUC of "good": network 0.965, refinement 0.996, network + refinement
    // 0.996).
    pub const NETWORK: ([f64; FEATURES], f64) = (
        [
            0.531055, 0.000000, 0.000000, 0.000000, 0.000000, -0.600868, 0.681778, -0.777954,
            -1.653646,
        ],
        0.949870,
    );
    pub const REFINEMENT: ([f64; FEATURES], f64) = (
        [
            0.057337, 0.058388, 0.299841, -0.160290, -0.261480, 0.000000, 0.000000, -0.618527,
            -0.608045,
        ],
        0.900000,
    );
    pub const NETWORK_REFINEMENT: ([f64; FEATURES], f64) = (
        [
            -0.358659, 0.059730, 0.296927, -0.175691, -0.277665, -0.284932, 0.069515, -0.582230,
            -0.586563,
        ],
        0.900000,
    );
}

/// The confidence of each AC.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct AcConfidence {
    /// The calibrated probability that A is good (cosine with A_gt ≥ 0.9), in [0, 1].
    pub confidence: Vec<f64>,
    /// `confidence ≥ model.threshold()`, and, when a refinement is given, refined (an AC whose
    /// refinement failed is never reliable).
    pub reliable: Vec<bool>,
    /// The features of each AC ([`FEATURE_NAMES`]).
    pub features: Vec<[f64; FEATURES]>,
    /// The model the confidence came from.
    pub model: ConfidenceModel,
}

/// The confidence of `corrs` (rows `[x1, y1, x2, y2, a11, a12, a21, a22]`, the ACs as they
/// are returned) from the network's spread (one per row) and/or the refinement that returned
/// them; see the module docs.
///
/// Errors: neither given, or a length other than `corrs.len()` (naming it).
pub fn affine_confidence(
    corrs: &[[f64; 8]],
    network: Option<&[NetworkSpread]>,
    refinement: Option<&AffineRefinement>,
) -> Result<AcConfidence> {
    let n = corrs.len();
    let model = match (network.is_some(), refinement.is_some()) {
        (true, true) => ConfidenceModel::NetworkRefinement,
        (true, false) => ConfidenceModel::Network,
        (false, true) => ConfidenceModel::Refinement,
        (false, false) => {
            return Err(ImageError::invalid(
                "network",
                "the confidence needs the network's spread, the refinement, or both",
            ));
        }
    };
    if let Some(s) = network.filter(|s| s.len() != n) {
        return Err(ImageError::invalid(
            "network",
            format!("{} spreads for {n} ACs", s.len()),
        ));
    }
    if let Some(r) = refinement {
        let lens = [
            r.status.len(),
            r.zncc.len(),
            r.shift_std.len(),
            r.affine_std.len(),
        ];
        if lens.iter().any(|&l| l != n) {
            return Err(ImageError::invalid(
                "refinement",
                format!("per-AC lengths {lens:?} for {n} ACs"),
            ));
        }
    }
    let agreement = neighbour_agreement(corrs);
    let features: Vec<[f64; FEATURES]> = (0..n)
        .map(|i| {
            let mut f = [0.0; FEATURES];
            f[0] = 1.0;
            if let Some(r) = refinement
                && r.status[i] == RefineStatus::Refined
            {
                f[1] = 1.0;
                let z = if r.zncc[i].is_finite() {
                    r.zncc[i].clamp(-1.0, 1.0)
                } else {
                    0.0
                };
                f[2] = -(1.001 - z).ln();
                f[3] = clamp_ln(r.shift_std[i], 1e-3, 10.0);
                f[4] = clamp_ln(r.affine_std[i], 1e-4, 10.0);
            }
            if let Some(s) = network {
                f[5] = clamp_ln(s[i].angle, 1e-4, 2.0);
                f[6] = clamp_ln(s[i].scale, 1e-3, 5.0);
            }
            let (spread, fit) = agreement[i];
            f[7] = clamp_ln(0.01 + spread, 0.01, 10.0);
            f[8] = clamp_ln(0.01 + fit, 0.01, 10.0);
            f
        })
        .collect();
    let w = model.weights();
    let confidence: Vec<f64> = features
        .iter()
        .zip(corrs)
        .map(|(f, c)| {
            let z: f64 = f.iter().zip(w).map(|(a, b)| a * b).sum();
            if z.is_finite() && c.iter().all(|v| v.is_finite()) {
                1.0 / (1.0 + (-z).exp())
            } else {
                0.0
            }
        })
        .collect();
    let threshold = model.threshold();
    // A refinement that failed returned its input: never reliable, whatever the score.
    let refined = |i: usize| refinement.is_none_or(|r| r.status[i] == RefineStatus::Refined);
    Ok(AcConfidence {
        reliable: confidence
            .iter()
            .enumerate()
            .map(|(i, &c)| c >= threshold && refined(i))
            .collect(),
        confidence,
        features,
        model,
    })
}

/// ln(v) with v clamped to [lo, hi] (NaN to hi: an unknown spread is a wide one).
fn clamp_ln(v: f64, lo: f64, hi: f64) -> f64 {
    let v = if v.is_nan() { hi } else { v.clamp(lo, hi) };
    v.ln()
}

/// Per AC: (median ‖A − A_j‖_F over its [`NEIGHBOURS`] nearest ACs in image A, ‖A − M‖_F with
/// M the least-squares affine map of their x1 → x2 displacements); a missing value (too few
/// ACs, collinear neighbours) is `MISSING_NEIGHBOURS` (0.3).
pub fn neighbour_agreement(corrs: &[[f64; 8]]) -> Vec<(f64, f64)> {
    let points: Vec<[f64; 2]> = corrs.iter().map(|c| [c[0], c[1]]).collect();
    let knn = nearest_neighbours(&points, NEIGHBOURS);
    corrs
        .par_iter()
        .zip(knn.par_iter())
        .map(|(c, nb)| {
            if nb.is_empty() {
                return (MISSING_NEIGHBOURS, MISSING_NEIGHBOURS);
            }
            let a = [c[4], c[5], c[6], c[7]];
            let mut d: Vec<f64> = nb
                .iter()
                .map(|&j| {
                    let b = &corrs[j];
                    (0..4)
                        .map(|k| (a[k] - b[4 + k]).powi(2))
                        .sum::<f64>()
                        .sqrt()
                })
                .collect();
            d.sort_by(f64::total_cmp);
            let m = d.len();
            let median = if m % 2 == 1 {
                d[m / 2]
            } else {
                0.5 * (d[m / 2 - 1] + d[m / 2])
            };
            // x2_j − x2_i ≈ M (x1_j − x1_i): M = S21 S11⁻¹.
            let (mut s11, mut s21) = ([0.0; 4], [0.0; 4]);
            for &j in nb {
                let b = &corrs[j];
                let d1 = [b[0] - c[0], b[1] - c[1]];
                let d2 = [b[2] - c[2], b[3] - c[3]];
                for r in 0..2 {
                    for q in 0..2 {
                        s11[2 * r + q] += d1[r] * d1[q];
                        s21[2 * r + q] += d2[r] * d1[q];
                    }
                }
            }
            let det = s11[0] * s11[3] - s11[1] * s11[2];
            let trace = s11[0] + s11[3];
            let fit = if nb.len() >= 3 && det > 1e-6 * trace * trace {
                let inv = [s11[3] / det, -s11[1] / det, -s11[2] / det, s11[0] / det];
                let m = [
                    s21[0] * inv[0] + s21[1] * inv[2],
                    s21[0] * inv[1] + s21[1] * inv[3],
                    s21[2] * inv[0] + s21[3] * inv[2],
                    s21[2] * inv[1] + s21[3] * inv[3],
                ];
                (0..4).map(|k| (a[k] - m[k]).powi(2)).sum::<f64>().sqrt()
            } else {
                MISSING_NEIGHBOURS
            };
            (median, fit)
        })
        .collect()
}

/// The indices of the (at most) `k` nearest other points of each point, nearest first (ties by
/// index); a point with a non-finite coordinate has none and is nobody's neighbour.
///
/// A uniform grid of about `k` points per cell, searched in square rings of cells around the
/// query until the k-th distance found is within the next ring's reach: O(N k) for spread-out
/// points (10 000 ACs in a few milliseconds).
pub fn nearest_neighbours(points: &[[f64; 2]], k: usize) -> Vec<Vec<usize>> {
    let n = points.len();
    let finite: Vec<usize> = (0..n)
        .filter(|&i| points[i].iter().all(|v| v.is_finite()))
        .collect();
    if k == 0 || finite.len() < 2 {
        return vec![Vec::new(); n];
    }
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for &i in &finite {
        for d in 0..2 {
            lo[d] = lo[d].min(points[i][d]);
            hi[d] = hi[d].max(points[i][d]);
        }
    }
    let (w, h) = (hi[0] - lo[0], hi[1] - lo[1]);
    // About k points per cell, at most 1024 cells a side.
    let cell = ((w.max(1e-9) * h.max(1e-9) * k as f64 / finite.len() as f64).sqrt())
        .max(w.max(h) / 1024.0)
        .max(1e-9);
    let (gx, gy) = ((w / cell) as usize + 1, (h / cell) as usize + 1);
    let cell_of = |p: &[f64; 2]| {
        let cx = (((p[0] - lo[0]) / cell) as usize).min(gx - 1);
        let cy = (((p[1] - lo[1]) / cell) as usize).min(gy - 1);
        (cx, cy)
    };
    // Counting sort of the finite points by cell.
    let mut start = vec![0usize; gx * gy + 1];
    for &i in &finite {
        let (cx, cy) = cell_of(&points[i]);
        start[cy * gx + cx + 1] += 1;
    }
    for c in 0..gx * gy {
        start[c + 1] += start[c];
    }
    let mut fill = start.clone();
    let mut members = vec![0usize; finite.len()];
    for &i in &finite {
        let (cx, cy) = cell_of(&points[i]);
        let c = cy * gx + cx;
        members[fill[c]] = i;
        fill[c] += 1;
    }
    (0..n)
        .into_par_iter()
        .map(|i| {
            let p = points[i];
            if !p.iter().all(|v| v.is_finite()) {
                return Vec::new();
            }
            let (cx, cy) = cell_of(&p);
            // (squared distance, index), sorted, at most k.
            let mut best: Vec<(f64, usize)> = Vec::with_capacity(k + 1);
            let visit = |x: usize, y: usize, best: &mut Vec<(f64, usize)>| {
                let c = y * gx + x;
                for &j in &members[start[c]..start[c + 1]] {
                    if j == i {
                        continue;
                    }
                    let q = points[j];
                    let d = (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2);
                    if best.len() < k || (d, j) < *best.last().expect("k > 0 when full") {
                        let at = best.partition_point(|e| *e < (d, j));
                        best.insert(at, (d, j));
                        best.truncate(k);
                    }
                }
            };
            for r in 0..gx.max(gy) {
                let (x0, x1) = (cx.saturating_sub(r), (cx + r).min(gx - 1));
                let (y0, y1) = (cy.saturating_sub(r), (cy + r).min(gy - 1));
                for y in y0..=y1 {
                    // The ring: whole rows at its top and bottom, the two side cells between.
                    if y == cy.wrapping_sub(r) || y == cy + r {
                        for x in x0..=x1 {
                            visit(x, y, &mut best);
                        }
                    } else {
                        if cx >= r {
                            visit(cx - r, y, &mut best);
                        }
                        if r > 0 && cx + r < gx {
                            visit(cx + r, y, &mut best);
                        }
                    }
                }
                // Every point of ring r + 1 or beyond is at least r cells away.
                let reach = r as f64 * cell;
                if best.len() == k && best.last().expect("full").0 <= reach * reach {
                    break;
                }
            }
            best.into_iter().map(|(_, j)| j).collect()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_neighbours_match_brute_force() {
        let mut s = 3u64;
        let mut next = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        let pts: Vec<[f64; 2]> = (0..400)
            .map(|i| {
                if i % 50 == 0 {
                    [10.0, 10.0] // duplicates
                } else if i % 3 == 0 {
                    [70.0 + 0.01 * next(), 5.0 + 0.01 * next()] // a tight cluster
                } else {
                    [100.0 * next(), 60.0 * next()]
                }
            })
            .collect();
        let knn = nearest_neighbours(&pts, 8);
        for (i, nb) in knn.iter().enumerate() {
            let mut all: Vec<(f64, usize)> = (0..pts.len())
                .filter(|&j| j != i)
                .map(|j| {
                    (
                        (pts[i][0] - pts[j][0]).powi(2) + (pts[i][1] - pts[j][1]).powi(2),
                        j,
                    )
                })
                .collect();
            all.sort_by(|a, b| a.partial_cmp(b).unwrap());
            let want: Vec<usize> = all[..8].iter().map(|e| e.1).collect();
            assert_eq!(nb, &want, "point {i}");
        }
        assert_eq!(
            nearest_neighbours(&[[1.0, 2.0]], 8),
            vec![Vec::<usize>::new()]
        );
        assert!(nearest_neighbours(&[], 8).is_empty());
        // Non-finite points have no neighbours and are nobody's; a line of points works.
        let knn = nearest_neighbours(&[[0.0, 0.0], [f64::NAN, 1.0], [2.0, 0.0], [5.0, 0.0]], 8);
        assert_eq!(knn, vec![vec![2, 3], vec![], vec![0, 3], vec![2, 0]]);
    }

    #[test]
    fn agreement_is_zero_on_a_global_affine_map() {
        // x2 = M x1 + c and A = M everywhere: both features vanish.
        let m = [1.1, 0.2, -0.1, 0.9];
        let corrs: Vec<[f64; 8]> = (0..50)
            .map(|i| {
                let (x, y) = (
                    (i % 7) as f64 * 13.0,
                    (i / 7) as f64 * 11.0 + (i % 3) as f64,
                );
                [
                    x,
                    y,
                    m[0] * x + m[1] * y + 5.0,
                    m[2] * x + m[3] * y - 2.0,
                    m[0],
                    m[1],
                    m[2],
                    m[3],
                ]
            })
            .collect();
        for (spread, fit) in neighbour_agreement(&corrs) {
            assert!(spread < 1e-12 && fit < 1e-9, "{spread} {fit}");
        }
        // One AC with a wrong A stands out.
        let mut bad = corrs.clone();
        bad[20][4] = 0.2;
        let g = neighbour_agreement(&bad);
        assert!(g[20].0 > 0.8 && g[20].1 > 0.8, "{:?}", g[20]);
    }

    #[test]
    fn confidence_is_a_probability_and_needs_an_input() {
        let corrs = vec![[1.0, 2.0, 3.0, 4.0, 1.0, 0.0, 0.0, 1.0]; 3];
        let spread = vec![
            NetworkSpread {
                angle: 0.1,
                scale: 0.2
            };
            3
        ];
        let c = affine_confidence(&corrs, Some(&spread), None).unwrap();
        assert_eq!(c.model, ConfidenceModel::Network);
        assert!(c.confidence.iter().all(|v| (0.0..=1.0).contains(v)));
        let e = affine_confidence(&corrs, None, None)
            .unwrap_err()
            .to_string();
        assert!(e.contains("network"), "{e}");
        let e = affine_confidence(&corrs, Some(&spread[..2]), None)
            .unwrap_err()
            .to_string();
        assert!(e.contains("2 spreads for 3"), "{e}");
        // A non-finite row is never confident.
        let mut nan = corrs.clone();
        nan[1][4] = f64::NAN;
        let c = affine_confidence(&nan, Some(&spread), None).unwrap();
        assert_eq!(c.confidence[1], 0.0);
        assert!(!c.reliable[1]);
    }
}
