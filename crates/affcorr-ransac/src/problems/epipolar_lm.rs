//! The signed Sampson residual and its use in Levenberg–Marquardt, shared by the fundamental
//! and relative-pose refinements.
//!
//! With e = p2ᵀ F p1 and d = (F p1)₁² + (F p1)₂² + (Fᵀ p2)₁² + (Fᵀ p2)₂², the residual is
//! r = e / √d (so r² = SD_P, docs/design.md §3) and
//! ∂r/∂F_mn = p2_m p1_n / √d − e / (2 d^{3/2}) · ∂d/∂F_mn, with
//! ∂d/∂F_mn = 2 (F p1)_m p1_n [m < 2] + 2 (Fᵀ p2)_n p2_m [n < 2].
//! A model with tangent basis ∂F/∂θ_k (k < dof) then has Jacobian rows J_k = ⟨∂r/∂F, ∂F/∂θ_k⟩.
//!
//! With [`AffineTerms`], each AC i adds its two signed affine Sampson residuals s_k = r_k/√G_k
//! (s_k² = SD_A,k, docs/design.md §3; gradients in `affcorr_geom::sampson`), whitened by λ
//! (px² per unit² of A: the ratio of the point to the affine noise variance, [`affine_scale`])
//! and weighted by the AC's confidence c_i: cost Σ_i c_i Σ_k ρ_A(λ s_k²), ρ_A the Cauchy loss
//! at the inlier threshold, so an AC whose A is far off pulls little.

use super::Correspondences;
use super::normal_eq::EntrySums;
use super::simd::{BLOCK, Lanes, add_sums, dispatch, gather};
use crate::loss::Loss;
use crate::refine::{Mat9, Vec9};
use affcorr_geom::Mat3;
use affcorr_geom::sampson::{sampson_affine, sampson_affine_signed_grad_f, sampson_point};

/// The affine part of an epipolar refinement (see the module docs).
#[derive(Debug, Clone, Copy)]
pub(crate) struct AffineTerms<'a> {
    /// λ: px² per unit² of A.
    pub lambda: f64,
    /// Per-AC confidence c_i in [0, 1] (all 1 when `None`).
    pub confidence: Option<&'a [f64]>,
    /// ρ_A, of λ s_k² (px²).
    pub loss: Loss,
}

impl AffineTerms<'_> {
    #[inline]
    fn confidence(&self, i: usize) -> f64 {
        self.confidence.map_or(1.0, |c| c[i])
    }
}

/// The affine terms of a refinement under `options` starting at `f` on `inliers`, or `None`
/// (points only) when `options.affine` is off, the data have no A, or λ cannot be estimated.
/// ρ_A is the Cauchy loss at 3σ̂ of the point residuals (σ̂² = median SD_P / 0.455, the median
/// of χ²₁), so it needs no threshold.
pub(crate) fn affine_terms<'c>(
    data: &Correspondences,
    f: &Mat3,
    inliers: &[usize],
    confidence: Option<&'c [f64]>,
    options: &crate::refine::LmOptions,
) -> Option<AffineTerms<'c>> {
    if !options.affine {
        return None;
    }
    let (lambda, point_median) = affine_scale(data, f, inliers, confidence)?;
    Some(AffineTerms {
        lambda,
        confidence,
        loss: Loss::Cauchy {
            scale_sq: (9.0 * point_median / CHI2_1_MEDIAN).max(1e-12),
        },
    })
}

/// Most rounds of estimate-λ-then-refine in one refinement: the model the scale is first
/// estimated at fits the points only, so its affine residuals overstate the noise of A (F has
/// directions that points barely fix); refitting with the new λ and re-estimating reaches the
/// scale of the joint fit in 2–3 rounds.
pub(crate) const AFFINE_ROUNDS: usize = 4;

/// Whether λ at the refined `f` differs from the `lambda` it was refined with by more than 20%
/// (always false without affine terms, or with a single LM pass to spare).
pub(crate) fn rescale_again(
    data: &Correspondences,
    f: &Mat3,
    inliers: &[usize],
    confidence: Option<&[f64]>,
    lambda: Option<f64>,
) -> bool {
    let Some(old) = lambda else {
        return false;
    };
    affine_scale(data, f, inliers, confidence).is_some_and(|(new, _)| {
        let r = new / old;
        !(0.8..=1.25).contains(&r)
    })
}

/// The median of χ²₁.
pub(crate) const CHI2_1_MEDIAN: f64 = 0.454_936_423_119_572_8;

/// Largest λ (px² per unit² of A) that [`affine_scale`] and the homography's affine terms
/// return: A exact to 0.05% at 0.5 px of point noise. The affine terms of exact ACs then
/// dominate, as they should, without making the normal equations singular in the directions
/// points alone fix.
pub(crate) const MAX_AFFINE_SCALE: f64 = 1e6;

/// (λ, median SD_P) estimated on `indices` under `f`: λ is the median SD_P over the median
/// SD_A,k (each a squared residual with one degree of freedom, so the ratio of their medians is
/// the ratio of the noise variances). `None` when fewer than 5 of them carry a confidence
/// above 0 (too few to tell the scale; the fit then uses points only).
pub(crate) fn affine_scale(
    data: &Correspondences,
    f: &Mat3,
    indices: &[usize],
    confidence: Option<&[f64]>,
) -> Option<(f64, f64)> {
    if !data.has_affine() {
        return None;
    }
    let (mut p, mut a) = (Vec::with_capacity(indices.len()), Vec::new());
    a.reserve(2 * indices.len());
    for &i in super::noise_ratio_sample(indices) {
        if confidence.is_some_and(|c| c[i] <= 0.0) {
            continue;
        }
        let ac = data.ac(i);
        p.push(sampson_point(f, &ac.points()));
        let [a0, a1] = sampson_affine(f, &ac);
        a.push(a0);
        a.push(a1);
    }
    if p.len() < 5 {
        return None;
    }
    let (mp, ma) = (super::median_of_squares(&p), super::median_of_squares(&a));
    if !(mp.is_finite() && ma.is_finite()) {
        return None;
    }
    if ma * MAX_AFFINE_SCALE <= mp || ma == 0.0 {
        let lambda = if mp > 0.0 {
            MAX_AFFINE_SCALE
        } else {
            super::SEED_AFFINE_WEIGHT
        };
        return Some((lambda, mp));
    }
    Some((mp / ma, mp))
}

/// Σ_i c_i Σ_k ρ_A(λ s_k²) over `indices` under `f`.
pub(crate) fn affine_cost(
    data: &Correspondences,
    f: &Mat3,
    indices: &[usize],
    terms: &AffineTerms<'_>,
) -> f64 {
    let mut cost = 0.0;
    for &i in indices {
        let c = terms.confidence(i);
        if c <= 0.0 {
            continue;
        }
        let a = sampson_affine(f, &data.ac(i));
        cost += c * terms.loss.total_cost(&a.map(|a| terms.lambda * a));
    }
    cost
}

/// [`normal_equations`] of the affine terms: adds their JᵀWJ and JᵀWr for the tangent `basis`
/// and returns their cost. Blocked like [`normal_equations`]: each block's ACs are gathered,
/// their two signed residuals and gradients computed lane-wise, the loss per AC, and the sums
/// (both rows of an AC into the same 54) as dot products over the block.
pub(crate) fn affine_normal_equations(
    data: &Correspondences,
    f: &Mat3,
    basis: &[Mat3],
    indices: &[usize],
    terms: &AffineTerms<'_>,
    jtj: &mut Mat9,
    jtr: &mut Vec9,
) -> f64 {
    let mut sums = EntrySums::new();
    let cost = dispatch(
        #[inline(always)]
        || accumulate_affine(data, f, indices, terms, &mut sums.g_sum, &mut sums.gg),
    );
    sums.project(&flat(basis)[..basis.len()], jtj, jtr);
    cost
}

/// The affine counterpart of [`accumulate`]: Σ c ρ_A over `indices`, and the sums of Σ w s g
/// and Σ w g gᵀ of both affine rows, w = c λ ρ_A′ (an AC with c ≤ 0 adds nothing).
#[inline(always)]
fn accumulate_affine(
    data: &Correspondences,
    f: &Mat3,
    indices: &[usize],
    terms: &AffineTerms<'_>,
    g_sum: &mut [f64; 9],
    gg: &mut [f64; 45],
) -> f64 {
    let mut cost = 0.0;
    let mut s = [[0.0; BLOCK]; 2];
    let mut g = [[[0.0; BLOCK]; 9]; 2];
    let (mut w, mut wr) = ([[0.0; BLOCK]; 2], [[0.0; BLOCK]; 2]);
    let (mut g_lanes, mut gg_lanes) = ([Lanes::default(); 9], [Lanes::default(); 45]);
    for chunk in indices.chunks(BLOCK) {
        let acs = gather(chunk, |i| data.ac(i));
        for (j, ac) in acs.iter().enumerate() {
            let rows = sampson_affine_signed_grad_f(f, ac);
            for (k, (sk, gk)) in rows.iter().enumerate() {
                s[k][j] = *sk;
                for a in 0..9 {
                    g[k][a][j] = gk[a];
                }
            }
        }
        for j in 0..BLOCK {
            let c = chunk.get(j).map_or(0.0, |&i| terms.confidence(i));
            if c <= 0.0 {
                // Also the tail of a short last block (its gathered copies must not count).
                for k in 0..2 {
                    (w[k][j], wr[k][j]) = (0.0, 0.0);
                }
                continue;
            }
            let sq = [s[0][j], s[1][j]].map(|sk| terms.lambda * sk * sk);
            let (rho, wk) = terms.loss.total_cost_and_weights(&sq);
            cost += c * rho;
            for k in 0..2 {
                w[k][j] = c * wk[k] * terms.lambda;
                wr[k][j] = w[k][j] * s[k][j];
            }
        }
        for k in 0..2 {
            add_block(&mut g_lanes, &mut gg_lanes, &w[k], &wr[k], &g[k]);
        }
    }
    add_sums(g_sum, &g_lanes);
    add_sums(gg, &gg_lanes);
    cost
}

/// r and ∂r/∂F (row-major) of one correspondence.
#[inline(always)]
fn residual_and_gradient(f: &Mat3, x1: [f64; 2], x2: [f64; 2]) -> (f64, [f64; 9]) {
    let p1 = [x1[0], x1[1], 1.0];
    let p2 = [x2[0], x2[1], 1.0];
    let mut l1 = [0.0; 3]; // F p1
    let mut l2 = [0.0; 3]; // Fᵀ p2
    for m in 0..3 {
        for n in 0..3 {
            l1[m] += f[(m, n)] * p1[n];
            l2[n] += f[(m, n)] * p2[m];
        }
    }
    let e = p2[0] * l1[0] + p2[1] * l1[1] + l1[2];
    let d = l1[0] * l1[0] + l1[1] * l1[1] + l2[0] * l2[0] + l2[1] * l2[1];
    // r = 0 and g = 0 where d ≤ 0; a select, not a branch, so that blocks vectorise.
    let inv_sqrt_d = if d > 0.0 { 1.0 / d.sqrt() } else { 0.0 };
    let r = e * inv_sqrt_d;
    let c = r * inv_sqrt_d * inv_sqrt_d; // e / d^{3/2}
    let mut g = [0.0; 9];
    for m in 0..3 {
        for n in 0..3 {
            let mut dd = 0.0;
            if m < 2 {
                dd += l1[m] * p1[n];
            }
            if n < 2 {
                dd += l2[n] * p2[m];
            }
            // ∂d = 2·dd, so the second term is e/(2 d^{3/2})·2·dd = c·dd.
            g[3 * m + n] = p2[m] * p1[n] * inv_sqrt_d - c * dd;
        }
    }
    (r, g)
}

/// Σ ρ(SD_P) over `indices` under `f`, block by block like [`normal_equations`] (LM calls it
/// once per trial step).
pub(crate) fn cost(data: &Correspondences, f: &Mat3, indices: &[usize], loss: &Loss) -> f64 {
    dispatch(
        #[inline(always)]
        || {
            let mut cost = 0.0;
            let (mut x, mut y, mut u, mut v) =
                ([0.0; BLOCK], [0.0; BLOCK], [0.0; BLOCK], [0.0; BLOCK]);
            let mut s = [0.0; BLOCK];
            for chunk in indices.chunks(BLOCK) {
                for (j, &i) in chunk.iter().enumerate() {
                    (x[j], y[j]) = (data.x1[i].x, data.x1[i].y);
                    (u[j], v[j]) = (data.x2[i].x, data.x2[i].y);
                }
                for j in 0..BLOCK {
                    let (r, _) = residual_and_gradient(f, [x[j], y[j]], [u[j], v[j]]);
                    s[j] = r * r;
                }
                cost += s[..chunk.len()]
                    .iter()
                    .map(|&sj| loss.cost(sj))
                    .sum::<f64>();
            }
            cost
        },
    )
}

/// Adds JᵀWJ and JᵀWr for the tangent `basis` (∂F/∂θ_k) and returns the cost.
///
/// The robust normal equations are accumulated once in the 9 entries of F (G = Σ w g gᵀ, 45
/// distinct products, and Σ w r g) and projected onto the basis at the end: JᵀWJ = Bᵀ G B and
/// JᵀWr = Bᵀ (Σ w r g), cheaper per datum than projecting every gradient (9·dof products) and
/// accumulating dof² terms. The accumulation runs over blocks of [`BLOCK`] data in structure-
/// of-arrays form so that the residuals, gradients and the 54 sums vectorise (4 lanes of f64
/// with AVX2, chosen at run time; 2 with the baseline SSE2).
pub(crate) fn normal_equations(
    data: &Correspondences,
    f: &Mat3,
    basis: &[Mat3],
    indices: &[usize],
    loss: &Loss,
    jtj: &mut Mat9,
    jtr: &mut Vec9,
) -> f64 {
    let mut sums = EntrySums::new();
    let cost = dispatch(
        #[inline(always)]
        || accumulate(data, f, indices, loss, &mut sums.g_sum, &mut sums.gg),
    );
    sums.project(&flat(basis)[..basis.len()], jtj, jtr);
    cost
}

/// The tangent `basis` (at most 9 directions) as rows of the 9 entries (row-major), padded
/// with zeros, for [`EntrySums::project`] on its first `basis.len()`.
fn flat(basis: &[Mat3]) -> [Vec9; 9] {
    std::array::from_fn(|k| {
        basis.get(k).map_or_else(Vec9::zeros, |b| {
            Vec9::from_column_slice(&affcorr_geom::types::mat3_to_row(b))
        })
    })
}

/// Σ ρ(r²) over `indices`, and adds Σ w r g to `g_sum` and the upper triangle of Σ w g gᵀ to
/// `gg` (row-major), block by block: gather, residuals and gradients lane-wise (the formulas of
/// [`residual_and_gradient`]), the loss per datum, then the sums as dot
/// products over the block.
#[inline(always)]
fn accumulate(
    data: &Correspondences,
    f: &Mat3,
    indices: &[usize],
    loss: &Loss,
    g_sum: &mut [f64; 9],
    gg: &mut [f64; 45],
) -> f64 {
    let mut cost = 0.0;
    let (mut x, mut y, mut u, mut v) = ([0.0; BLOCK], [0.0; BLOCK], [0.0; BLOCK], [0.0; BLOCK]);
    let mut r = [0.0; BLOCK];
    let mut g = [[0.0; BLOCK]; 9];
    let (mut w, mut wr) = ([0.0; BLOCK], [0.0; BLOCK]);
    let (mut g_lanes, mut gg_lanes) = ([Lanes::default(); 9], [Lanes::default(); 45]);
    for chunk in indices.chunks(BLOCK) {
        let len = chunk.len();
        for (j, &i) in chunk.iter().enumerate() {
            (x[j], y[j]) = (data.x1[i].x, data.x1[i].y);
            (u[j], v[j]) = (data.x2[i].x, data.x2[i].y);
        }
        for j in 0..BLOCK {
            let (rj, gj) = residual_and_gradient(f, [x[j], y[j]], [u[j], v[j]]);
            r[j] = rj;
            for a in 0..9 {
                g[a][j] = gj[a];
            }
        }
        for j in 0..len {
            let (c, wj) = loss.cost_and_weight(r[j] * r[j]);
            cost += c;
            w[j] = wj;
            wr[j] = wj * r[j];
        }
        // The tail of a short last block (stale but finite values) must not count.
        w[len..].fill(0.0);
        wr[len..].fill(0.0);
        add_block(&mut g_lanes, &mut gg_lanes, &w, &wr, &g);
    }
    add_sums(g_sum, &g_lanes);
    add_sums(gg, &gg_lanes);
    cost
}

/// Adds a block's Σ w r g (`wr` = w r) to `g_lanes` and the upper triangle of its Σ w g gᵀ
/// (row-major) to `gg_lanes`, as dot products over the block; `g[a]` is the a-th entry of
/// every datum's gradient. Lanes whose w is 0 add nothing.
#[inline(always)]
fn add_block(
    g_lanes: &mut [Lanes; 9],
    gg_lanes: &mut [Lanes; 45],
    w: &[f64; BLOCK],
    wr: &[f64; BLOCK],
    g: &[[f64; BLOCK]; 9],
) {
    let mut k = 0;
    for a in 0..9 {
        g_lanes[a].add_dot(wr, &g[a]);
        let wg: [f64; BLOCK] = std::array::from_fn(|j| w[j] * g[a][j]);
        for b in a..9 {
            gg_lanes[k].add_dot(&wg, &g[b]);
            k += 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gradient_matches_central_differences() {
        let f = Mat3::new(1e-6, -3e-5, 0.01, 2e-5, 4e-6, -0.02, -0.012, 0.018, 0.4);
        let (x1, x2) = ([123.0, 456.0], [150.0, 430.0]);
        let (r, g) = residual_and_gradient(&f, x1, x2);
        for q in 0..9 {
            let h = 1e-6 * f[(q / 3, q % 3)].abs().max(1e-6);
            let (mut fp, mut fm) = (f, f);
            fp[(q / 3, q % 3)] += h;
            fm[(q / 3, q % 3)] -= h;
            let fd = (residual_and_gradient(&fp, x1, x2).0 - residual_and_gradient(&fm, x1, x2).0)
                / (2.0 * h);
            assert!(
                (fd - g[q]).abs() < 1e-6 * g[q].abs().max(1.0),
                "F[{q}]: {fd} vs {}",
                g[q]
            );
        }
        // r² is SD_P.
        let sd = affcorr_geom::sampson::sampson_point(
            &f,
            &affcorr_geom::PointCorrespondence {
                x1: x1.into(),
                x2: x2.into(),
            },
        );
        assert!((r * r - sd).abs() < 1e-12 * sd.max(1e-300));
    }

    #[test]
    fn normal_equations_equal_the_projected_jacobians() {
        let f = Mat3::new(1e-6, -3e-5, 0.01, 2e-5, 4e-6, -0.02, -0.012, 0.018, 0.4);
        let mut data = Correspondences::default();
        for k in 0..30 {
            let t = k as f64;
            data.x1
                .push(affcorr_geom::Vec2::new(10.0 + 17.0 * t, 400.0 - 9.0 * t));
            data.x2.push(affcorr_geom::Vec2::new(
                30.0 + 15.0 * t,
                380.0 - 11.0 * t + (t * 0.7).sin(),
            ));
        }
        let basis = [
            Mat3::new(1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
            Mat3::new(0.0, 0.3, 0.0, -0.2, 0.0, 0.0, 0.0, 0.0, 0.1),
            Mat3::new(0.0, 0.0, 1e-3, 0.0, 0.5, 0.0, 0.2, 0.0, 0.0),
        ];
        let idx: Vec<usize> = (0..30).collect();
        let loss = Loss::Cauchy { scale_sq: 2.0 };
        let (mut jtj, mut jtr) = (Mat9::zeros(), Vec9::zeros());
        let cost = normal_equations(&data, &f, &basis, &idx, &loss, &mut jtj, &mut jtr);
        let (mut ejtj, mut ejtr, mut ecost) = (Mat9::zeros(), Vec9::zeros(), 0.0);
        for &i in &idx {
            let (r, g) = residual_and_gradient(
                &f,
                [data.x1[i].x, data.x1[i].y],
                [data.x2[i].x, data.x2[i].y],
            );
            let w = loss.weight(r * r);
            ecost += loss.cost(r * r);
            let j: Vec<f64> = basis
                .iter()
                .map(|b| (0..9).map(|q| g[q] * b[(q / 3, q % 3)]).sum())
                .collect();
            for a in 0..3 {
                ejtr[a] += w * j[a] * r;
                for b in 0..3 {
                    ejtj[(a, b)] += w * j[a] * j[b];
                }
            }
        }
        assert!((cost - ecost).abs() < 1e-12 * ecost);
        assert!((jtj - ejtj).norm() < 1e-10 * ejtj.norm(), "{jtj} vs {ejtj}");
        assert!((jtr - ejtr).norm() < 1e-10 * ejtr.norm().max(1e-300));
        // The baseline build of the kernel (the one non-AVX2 CPUs run) agrees with the
        // dispatched one, short last block included (30 = 16 + 14).
        let (mut s1, mut g1, mut s2, mut g2) = ([0.0; 9], [0.0; 45], [0.0; 9], [0.0; 45]);
        let c1 = accumulate(&data, &f, &idx, &loss, &mut s1, &mut g1);
        let c2 = dispatch(|| accumulate(&data, &f, &idx, &loss, &mut s2, &mut g2));
        assert!((c1 - c2).abs() < 1e-12 * c1);
        for (a, b) in s1.iter().zip(&s2).chain(g1.iter().zip(&g2)) {
            assert!((a - b).abs() <= 1e-12 * a.abs().max(1e-300), "{a} vs {b}");
        }
    }

    /// A scene's exact ACs with Gaussian noise: `px` on x2, `rel` relative on A.
    fn noisy_acs(seed: u64, n: usize, px: f64, rel: f64) -> (Mat3, Correspondences) {
        use affcorr_geom::synthetic::{NoiseModel, PlaneScene, noisy_correspondences};
        use rand::SeedableRng;
        let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
        let scene = PlaneScene::random(&mut rng);
        let noise = NoiseModel {
            planes: 3,
            outlier_ratio: 0.0,
            pixel_noise: px,
            affine_noise: rel,
        };
        let (acs, _) = noisy_correspondences(&mut rng, &scene, n, &noise);
        (
            scene.fundamental().normalize(),
            Correspondences::from_acs(&acs).unwrap(),
        )
    }

    #[test]
    fn affine_normal_equations_are_half_the_gradient_of_the_affine_cost() {
        let (f, data) = noisy_acs(21, 40, 1.0, 0.05);
        let idx: Vec<usize> = (0..40).collect();
        let conf: Vec<f64> = (0..40).map(|i| (i % 5) as f64 / 4.0).collect();
        let terms = AffineTerms {
            lambda: 400.0,
            confidence: Some(&conf),
            loss: Loss::Cauchy { scale_sq: 2.0 },
        };
        let basis = [
            Mat3::new(0.0, 1e-6, 0.0, -2e-6, 0.0, 1e-3, 0.0, -1e-3, 0.0),
            Mat3::new(0.0, 0.0, 1e-3, 0.0, 0.0, 0.0, 2e-3, 0.0, 1e-2),
            Mat3::new(3e-7, 0.0, 0.0, 0.0, -1e-6, 0.0, 0.0, 0.0, 0.0),
        ];
        let (mut jtj, mut jtr) = (Mat9::zeros(), Vec9::zeros());
        let cost = affine_normal_equations(&data, &f, &basis, &idx, &terms, &mut jtj, &mut jtr);
        assert!((cost - affine_cost(&data, &f, &idx, &terms)).abs() < 1e-12 * cost);
        for (k, b) in basis.iter().enumerate() {
            let h = 1e-4;
            let fd = (affine_cost(&data, &(f + b * h), &idx, &terms)
                - affine_cost(&data, &(f - b * h), &idx, &terms))
                / (2.0 * h);
            assert!(
                (2.0 * jtr[k] - fd).abs() < 1e-5 * fd.abs().max(1e-9),
                "θ{k}: {} vs {fd}",
                2.0 * jtr[k]
            );
            // JᵀWJ is positive semi-definite and symmetric.
            assert!(jtj[(k, k)] >= 0.0);
        }
        assert!((jtj - jtj.transpose()).norm() <= 1e-12 * jtj.norm());
    }

    #[test]
    fn the_affine_scale_is_the_ratio_of_the_noise_variances() {
        // With noise on x2 only, SD_P ≈ σ_x²·|l1|²/(|l1|² + |l2|²) and SD_A,k ≈ (σ_A a)², so
        // the ratio λ scales as σ_x² / σ_A²: 4× the affine noise divides it by ~16, 2× the
        // point noise multiplies it by ~4.
        let idx: Vec<usize> = (0..600).collect();
        let scale = |px, rel| {
            let (f, data) = noisy_acs(22, 600, px, rel);
            affine_scale(&data, &f, &idx, None).unwrap().0
        };
        let base = scale(0.5, 0.01);
        let r_affine = base / scale(0.5, 0.04);
        let r_points = scale(1.0, 0.01) / base;
        assert!((r_affine / 16.0 - 1.0).abs() < 0.25, "{r_affine}");
        assert!((r_points / 4.0 - 1.0).abs() < 0.25, "{r_points}");
        // Exact A (only the noise of x2 reaches the affine residuals): a far larger scale,
        // capped; exact data: a finite scale; too few confident ACs or no A: none.
        let (f, data) = noisy_acs(22, 600, 0.5, 0.0);
        let exact = affine_scale(&data, &f, &idx, None).unwrap().0;
        assert!(
            exact > 50.0 * base && exact <= MAX_AFFINE_SCALE,
            "{exact} vs {base}"
        );
        let (f0, data0) = noisy_acs(22, 600, 0.0, 0.0);
        let capped = affine_scale(&data0, &f0, &idx, None).unwrap().0;
        assert!(capped > 0.0 && capped <= MAX_AFFINE_SCALE, "{capped}");
        let mut conf = vec![0.0; 600];
        conf[..4].fill(1.0);
        assert!(affine_scale(&data, &f, &idx, Some(&conf)).is_none());
        let points = data.points_only();
        assert!(affine_scale(&points, &f, &idx, None).is_none());
    }
}
