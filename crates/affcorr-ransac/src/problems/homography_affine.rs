//! The affine terms of the homography's final refinement (`affine_refinement`).
//!
//! An AC (x1, x2, A) of a plane satisfies A = A_H(x1), the Jacobian of x ↦ π(H x̃) at x1
//! (docs/design.md §2). With p = (x, y, 1) = x̃1, w = h₃·p and q_r = (h_r·p)/w (r < 2, the
//! projected point),
//!
//!   A_H,rc = (h_rc − q_r h_2c) / w,
//!   ∂A_H,rc/∂h_rk = δ_kc / w − p_k h_2c / w²,
//!   ∂A_H,rc/∂h_2k = −(p_k / w)(A_H,rc − q_r h_2c / w) − q_r δ_kc / w,
//!
//! and 0 for the other row. Each AC adds the four residuals d = A_H(x1) − A, whitened by λ
//! (px² per unit² of A: the ratio of the point to the affine noise variance, estimated from the
//! inliers as the ratio of the medians of the squared components, on at most
//! `NOISE_RATIO_SAMPLE` of them) and weighted by the AC's
//! confidence c_i: cost Σ_i c_i Σ_k ρ_A(λ d_k²), ρ_A the Cauchy loss at 3σ̂ of the point
//! residuals, so that an AC whose A is off pulls little. This is the homography counterpart of
//! `epipolar_lm`'s affine Sampson terms.

use super::Correspondences;
use super::epipolar_lm::{CHI2_1_MEDIAN, MAX_AFFINE_SCALE};
use super::homography::HomographyProblem;
use super::normal_eq::EntrySums;
use super::simd::{BLOCK, Lanes, UPPER_3X3, add_sums, dispatch};
use crate::loss::Loss;
use crate::refine::{LeastSquares, Mat9, Vec9};
use affcorr_geom::{Mat2, Mat3, Vec2};

/// Most rounds of estimate-λ-then-refine: λ is first estimated at the points-only model.
pub(crate) const AFFINE_ROUNDS: usize = 3;

/// A_H(x1) − A, the four entries row-major: the residuals of [`AffineSums::add_acs`] without
/// their gradients (the costs of LM's trial steps and the scale estimate need none).
#[inline]
pub(crate) fn affine_residuals(h: &Mat3, x1: &Vec2, a: &Mat2) -> [f64; 4] {
    let w = h[(2, 0)] * x1.x + h[(2, 1)] * x1.y + h[(2, 2)];
    let q = |r: usize| (h[(r, 0)] * x1.x + h[(r, 1)] * x1.y + h[(r, 2)]) / w;
    let q = [q(0), q(1)];
    std::array::from_fn(|e| {
        let (r, c) = (e / 2, e % 2);
        (h[(r, c)] - q[r] * h[(2, c)]) / w - a[(r, c)]
    })
}

/// A_H(x1) − A and its dense gradient over the 9 entries of H (row-major), for each of the four
/// entries of A (row-major): the reference that [`AffineSums::add_acs`] is tested against.
#[cfg(test)]
pub(crate) fn affine_residuals_and_gradients(
    h: &Mat3,
    x1: &Vec2,
    a: &Mat2,
) -> [(f64, [f64; 9]); 4] {
    let p = [x1.x, x1.y, 1.0];
    let w = h[(2, 0)] * p[0] + h[(2, 1)] * p[1] + h[(2, 2)];
    let q = |r: usize| (h[(r, 0)] * p[0] + h[(r, 1)] * p[1] + h[(r, 2)]) / w;
    std::array::from_fn(|e| {
        let (r, c) = (e / 2, e % 2);
        let qr = q(r);
        let a_h = (h[(r, c)] - qr * h[(2, c)]) / w;
        let mut g = [0.0; 9];
        for k in 0..3 {
            let delta = if k == c { 1.0 } else { 0.0 };
            g[3 * r + k] = delta / w - p[k] * h[(2, c)] / (w * w);
            g[6 + k] = -(p[k] / w) * (a_h - qr * h[(2, c)] / w) - qr * delta / w;
        }
        (a_h - a[(r, c)], g)
    })
}

/// The sums of the affine terms' normal equations, kept in the structure of their gradients.
///
/// The gradient of residual (r, c) over H's entries (row-major) is u_c in row block r (the same
/// 3-vector for both rows) and v_rc in the third row block, zero elsewhere (module docs). So
/// of Σ ω g gᵀ only the blocks (r, r) = Σ_c ω u_c u_cᵀ,
/// (r, 2) = Σ_c ω u_c v_rcᵀ and (2, 2) = Σ ω v vᵀ are non-zero (block (0, 1) is zero): 21
/// products per residual instead of 45 for a dense upper triangle. [`AffineSums::entry_sums`]
/// lays them out as [`EntrySums`] for the projection onto H's tangent basis.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct AffineSums {
    /// Upper triangles (00, 01, 02, 11, 12, 22) of blocks (0, 0) and (1, 1).
    diag: [[f64; 6]; 2],
    /// Blocks (0, 2) and (1, 2), row-major.
    cross: [[f64; 9]; 2],
    /// Upper triangle of block (2, 2).
    last: [f64; 6],
    /// Σ ω d u for rows 0 and 1, and Σ ω d v.
    g_rows: [[f64; 3]; 2],
    g_last: [f64; 3],
}

impl AffineSums {
    /// Adds the four residuals d = A_H(x1) − A (row-major) of each AC of `indices`, each with
    /// the (cost, weight ω) that `weight(i, d)` gives for AC i; returns the sum of the costs.
    ///
    /// The layout of the transfer error's kernel (`simd`): blocks of [`BLOCK`] ACs gathered
    /// into arrays, residuals and gradients lane by lane (branch-free, vectorised), `weight`
    /// per residual, then every sum a dot product over the block.
    #[inline(always)]
    pub(crate) fn add_acs(
        &mut self,
        h: &Mat3,
        data: &Correspondences,
        indices: &[usize],
        mut weight: impl FnMut(usize, [f64; 4]) -> (f64, [f64; 4]),
    ) -> f64 {
        let mut cost = 0.0;
        let (mut x, mut y) = ([0.0; BLOCK], [0.0; BLOCK]);
        let mut a = [[0.0; BLOCK]; 4];
        // u[c][k]: ∂A_H,rc/∂h_rk (either row r); v[e][k], d[e], ω[e]: residual e = 2r + c.
        let mut u = [[[0.0; BLOCK]; 3]; 2];
        let mut v = [[[0.0; BLOCK]; 3]; 4];
        let (mut d, mut omega) = ([[0.0; BLOCK]; 4], [[0.0; BLOCK]; 4]);
        // The sums of `self`'s fields, in lanes until the last block.
        let mut diag = [[Lanes::default(); 6]; 2];
        let mut cross = [[Lanes::default(); 9]; 2];
        let mut last = [Lanes::default(); 6];
        let mut g_rows = [[Lanes::default(); 3]; 2];
        let mut g_last = [Lanes::default(); 3];
        for chunk in indices.chunks(BLOCK) {
            let len = chunk.len();
            // The lanes past a short last block repeat its first AC (finite wherever the data
            // are) and get ω = 0.
            for j in 0..BLOCK {
                let i = chunk[if j < len { j } else { 0 }];
                (x[j], y[j]) = (data.x1[i].x, data.x1[i].y);
                let m = &data.a[i];
                (a[0][j], a[1][j], a[2][j], a[3][j]) = (m[(0, 0)], m[(0, 1)], m[(1, 0)], m[(1, 1)]);
            }
            for j in 0..BLOCK {
                let inv_w = 1.0 / (h[(2, 0)] * x[j] + h[(2, 1)] * y[j] + h[(2, 2)]);
                let p = [x[j] * inv_w, y[j] * inv_w, inv_w];
                let q = [
                    h[(0, 0)] * p[0] + h[(0, 1)] * p[1] + h[(0, 2)] * p[2],
                    h[(1, 0)] * p[0] + h[(1, 1)] * p[1] + h[(1, 2)] * p[2],
                ];
                for c in 0..2 {
                    let h2c = h[(2, c)] * inv_w;
                    for k in 0..3 {
                        u[c][k][j] = -p[k] * h2c;
                    }
                    u[c][c][j] += inv_w;
                    for r in 0..2 {
                        let e = 2 * r + c;
                        let a_h = (h[(r, c)] - q[r] * h[(2, c)]) * inv_w;
                        d[e][j] = a_h - a[e][j];
                        let s = a_h - q[r] * h2c;
                        for k in 0..3 {
                            v[e][k][j] = -p[k] * s;
                        }
                        v[e][c][j] -= q[r] * inv_w;
                    }
                }
            }
            for (j, &i) in chunk.iter().enumerate() {
                let (rho, w) = weight(i, [d[0][j], d[1][j], d[2][j], d[3][j]]);
                cost += rho;
                for (om, w) in omega.iter_mut().zip(w) {
                    om[j] = w;
                }
            }
            for om in &mut omega {
                om[len..].fill(0.0);
            }
            for e in 0..4 {
                let (r, c) = (e / 2, e % 2);
                let (u, v, om) = (&u[c], &v[e], &omega[e]);
                let (mut wu, mut wv, mut wd) = ([[0.0; BLOCK]; 3], [[0.0; BLOCK]; 3], [0.0; BLOCK]);
                for j in 0..BLOCK {
                    for k in 0..3 {
                        (wu[k][j], wv[k][j]) = (om[j] * u[k][j], om[j] * v[k][j]);
                    }
                    wd[j] = om[j] * d[e][j];
                }
                for (t, &(k, l)) in UPPER_3X3.iter().enumerate() {
                    diag[r][t].add_dot(&wu[k], &u[l]);
                    last[t].add_dot(&wv[k], &v[l]);
                }
                for k in 0..3 {
                    for l in 0..3 {
                        cross[r][3 * k + l].add_dot(&wu[k], &v[l]);
                    }
                    g_rows[r][k].add_dot(&wd, &u[k]);
                    g_last[k].add_dot(&wd, &v[k]);
                }
            }
        }
        for r in 0..2 {
            add_sums(&mut self.diag[r], &diag[r]);
            add_sums(&mut self.cross[r], &cross[r]);
            add_sums(&mut self.g_rows[r], &g_rows[r]);
        }
        add_sums(&mut self.last, &last);
        add_sums(&mut self.g_last, &g_last);
        cost
    }

    /// The same sums as [`EntrySums`] (zeros where the structure has none).
    pub(crate) fn entry_sums(&self) -> EntrySums {
        let mut full = [[0.0; 9]; 9];
        for (k, &(i, j)) in UPPER_3X3.iter().enumerate() {
            for r in 0..2 {
                full[3 * r + i][3 * r + j] = self.diag[r][k];
            }
            full[6 + i][6 + j] = self.last[k];
        }
        for r in 0..2 {
            for i in 0..3 {
                for j in 0..3 {
                    full[3 * r + i][6 + j] = self.cross[r][3 * i + j];
                }
            }
        }
        let mut sums = EntrySums::new();
        let mut k = 0;
        for (a, row) in full.iter().enumerate() {
            for value in &row[a..] {
                sums.gg[k] = *value;
                k += 1;
            }
        }
        sums.g_sum[..3].copy_from_slice(&self.g_rows[0]);
        sums.g_sum[3..6].copy_from_slice(&self.g_rows[1]);
        sums.g_sum[6..].copy_from_slice(&self.g_last);
        sums
    }
}

/// The affine part of a homography refinement.
#[derive(Debug, Clone, Copy)]
pub(crate) struct HomographyAffineTerms<'a> {
    /// λ: px² per unit² of A.
    pub lambda: f64,
    /// Per-AC confidence c_i in [0, 1] (all 1 when `None`).
    pub confidence: Option<&'a [f64]>,
    /// ρ_A, of λ d_k² (px²).
    pub loss: Loss,
}

/// The affine terms at `h` on `inliers`, or `None` (points only) without A or when fewer than
/// 5 inliers have a confidence above 0.
pub(crate) fn affine_terms<'c>(
    data: &Correspondences,
    h: &Mat3,
    inliers: &[usize],
    confidence: Option<&'c [f64]>,
) -> Option<HomographyAffineTerms<'c>> {
    if !data.has_affine() {
        return None;
    }
    let (mut pts, mut aff) = (
        Vec::with_capacity(2 * inliers.len()),
        Vec::with_capacity(4 * inliers.len()),
    );
    for &i in super::noise_ratio_sample(inliers) {
        if confidence.is_some_and(|c| c[i] <= 0.0) {
            continue;
        }
        let (x1, x2) = (data.x1[i], data.x2[i]);
        let wz = h[(2, 0)] * x1.x + h[(2, 1)] * x1.y + h[(2, 2)];
        let u = (h[(0, 0)] * x1.x + h[(0, 1)] * x1.y + h[(0, 2)]) / wz;
        let v = (h[(1, 0)] * x1.x + h[(1, 1)] * x1.y + h[(1, 2)]) / wz;
        pts.extend([(u - x2.x).powi(2), (v - x2.y).powi(2)]);
        aff.extend(affine_residuals(h, &x1, &data.a[i]).map(|d| d * d));
    }
    if pts.len() < 10 {
        return None;
    }
    let (mp, ma) = (
        super::median_of_squares(&pts),
        super::median_of_squares(&aff),
    );
    if !(mp.is_finite() && ma.is_finite()) || mp <= 0.0 {
        return None;
    }
    let lambda = if ma * MAX_AFFINE_SCALE <= mp {
        MAX_AFFINE_SCALE
    } else {
        mp / ma
    };
    Some(HomographyAffineTerms {
        lambda,
        confidence,
        loss: Loss::Cauchy {
            scale_sq: (9.0 * mp / CHI2_1_MEDIAN).max(1e-12),
        },
    })
}

/// The homography's least squares plus the affine terms.
pub(crate) struct HomographyAffineFit<'p, 'a> {
    pub problem: &'p HomographyProblem<'a>,
    pub data: &'a Correspondences,
    pub terms: HomographyAffineTerms<'a>,
}

impl HomographyAffineFit<'_, '_> {
    fn confidence(&self, i: usize) -> f64 {
        self.terms.confidence.map_or(1.0, |c| c[i])
    }
}

impl LeastSquares for HomographyAffineFit<'_, '_> {
    type Model = Mat3;

    fn dof(&self) -> usize {
        8
    }

    fn cost(&self, h: &Mat3, indices: &[usize], loss: &Loss) -> f64 {
        let mut cost = self.problem.cost(h, indices, loss);
        for &i in indices {
            let c = self.confidence(i);
            if c <= 0.0 {
                continue;
            }
            let d = affine_residuals(h, &self.data.x1[i], &self.data.a[i]);
            cost += c * self
                .terms
                .loss
                .total_cost(&d.map(|d| self.terms.lambda * d * d));
        }
        cost
    }

    fn normal_equations<const COST: bool>(
        &self,
        h: &Mat3,
        indices: &[usize],
        loss: &Loss,
        jtj: &mut Mat9,
        jtr: &mut Vec9,
    ) -> f64 {
        let mut cost = self
            .problem
            .normal_equations::<COST>(h, indices, loss, jtj, jtr);
        let mut sums = AffineSums::default();
        let (lambda, affine_loss) = (self.terms.lambda, &self.terms.loss);
        // A confidence of 0 gives the AC no cost and no weight.
        cost += dispatch(
            #[inline(always)]
            || {
                sums.add_acs(
                    h,
                    self.data,
                    indices,
                    #[inline(always)]
                    |i, d| {
                        let (c, s) = (self.confidence(i), d.map(|d| lambda * d * d));
                        if COST {
                            let (rho, w) = affine_loss.total_cost_and_weights(&s);
                            (c * rho, w.map(|w| c * w * lambda))
                        } else {
                            (0.0, s.map(|s| c * affine_loss.weight(s) * lambda))
                        }
                    },
                )
            },
        );
        sums.entry_sums()
            .project(&super::homography::tangent_basis(h), jtj, jtr);
        cost
    }

    fn retract(&self, h: &Mat3, delta: &Vec9) -> Mat3 {
        self.problem.retract(h, delta)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::problem::Problem;
    use crate::problems::SampleKind;
    use crate::refine::LmOptions;
    use affcorr_geom::AffineCorrespondence;
    use affcorr_geom::homography::ac_from_homography;
    use affcorr_geom::synthetic::{NoiseModel, PlaneScene, noisy_correspondences};
    use rand::SeedableRng;

    fn plane_data(seed: u64, n: usize, px: f64, rel: f64) -> (PlaneScene, Correspondences) {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
        let scene = PlaneScene::random(&mut rng);
        let noise = NoiseModel {
            planes: 1,
            outlier_ratio: 0.0,
            pixel_noise: px,
            affine_noise: rel,
        };
        let (acs, _) = noisy_correspondences(&mut rng, &scene, n, &noise);
        (scene, Correspondences::from_acs(&acs).unwrap())
    }

    #[test]
    fn normal_equations_are_half_the_gradient_of_the_cost() {
        let (scene, data) = plane_data(3, 60, 1.0, 0.05);
        let problem = HomographyProblem::new(&data, SampleKind::Affine, 0.0);
        let h = scene.homography() / scene.homography().norm();
        let idx: Vec<usize> = (0..60).collect();
        let terms = affine_terms(&data, &h, &idx, None).unwrap();
        let fit = HomographyAffineFit {
            problem: &problem,
            data: &data,
            terms,
        };
        let loss = Loss::Cauchy { scale_sq: 4.0 };
        let (mut jtj, mut jtr) = (Mat9::zeros(), Vec9::zeros());
        let cost = fit.normal_equations::<true>(&h, &idx, &loss, &mut jtj, &mut jtr);
        assert!((cost - fit.cost(&h, &idx, &loss)).abs() < 1e-9 * cost);
        // Without the cost, the same sums.
        let (mut jtj_k, mut jtr_k) = (Mat9::zeros(), Vec9::zeros());
        fit.normal_equations::<false>(&h, &idx, &loss, &mut jtj_k, &mut jtr_k);
        assert_eq!((jtj, jtr), (jtj_k, jtr_k));
        for k in 0..8 {
            let t = 1e-11;
            let step = |s: f64| {
                let mut d = Vec9::zeros();
                d[k] = s;
                fit.cost(&fit.retract(&h, &d), &idx, &loss)
            };
            let fd = (step(t) - step(-t)) / (2.0 * t);
            assert!(
                (fd - 2.0 * jtr[k]).abs() <= 1e-4 * fd.abs().max(1.0),
                "direction {k}: 2 Jᵀr {} vs central difference {fd}",
                2.0 * jtr[k]
            );
        }
    }

    #[test]
    fn accurate_acs_make_the_refined_homography_more_accurate_than_points() {
        // 1 px on the points, 1% on A, 20 matches: A adds to what the points know about H's
        // local shape (over a 300 px spread, 20 points at 1 px fix the Jacobian to ~0.3%), so
        // the fit with the affine terms is closer to the truth in every scene (by 3–20%).
        let (mut better, mut log_ratio, trials) = (0, 0.0, 6_usize);
        for seed in 0..trials as u64 {
            let (scene, data) = plane_data(100 + seed, 20, 1.0, 0.01);
            let truth = scene.homography();
            let problem = HomographyProblem::new(&data, SampleKind::Affine, 0.0);
            let all: Vec<usize> = (0..20).collect();
            let start = problem.fit_nonminimal(&all, None).unwrap();
            let refine = |affine| {
                let options = LmOptions {
                    affine,
                    ..Default::default()
                };
                problem
                    .refine(&start, &all, &Loss::Squared, &options)
                    .unwrap()
            };
            let error = |h: &Mat3| {
                // Mean transfer distance to the truth over the data's points.
                let mut e = 0.0;
                for x in &data.x1 {
                    let p = |m: &Mat3| {
                        let v = m * affcorr_geom::Vec3::new(x.x, x.y, 1.0);
                        Vec2::new(v.x / v.z, v.y / v.z)
                    };
                    e += (p(h) - p(&truth)).norm();
                }
                e / data.len() as f64
            };
            let (e_points, e_affine) = (error(&refine(false)), error(&refine(true)));
            better += usize::from(e_affine < e_points);
            log_ratio += (e_affine / e_points).ln();
        }
        let mean_ratio = (log_ratio / trials as f64).exp();
        assert_eq!(
            better, trials,
            "the affine terms helped in {better} of {trials} scenes"
        );
        assert!(
            mean_ratio < 0.95,
            "mean error ratio affine / points {mean_ratio}"
        );
    }

    #[test]
    fn structured_sums_equal_the_dense_ones() {
        let h = Mat3::new(0.9, -0.2, 30.0, 0.15, 1.1, -12.0, 4e-4, -2e-4, 1.0);
        // Two full blocks and a short one, in a shuffled order with one AC left out.
        let acs: Vec<_> = (0..2 * BLOCK + 7)
            .map(|k| {
                let k = k as f64;
                AffineCorrespondence {
                    x1: Vec2::new(37.0 * k % 640.0, 300.0 - 41.0 * k % 480.0),
                    x2: Vec2::zeros(),
                    a: Mat2::new(1.0 + 0.01 * k, -0.2, 0.1, 0.9 - 0.02 * k),
                }
            })
            .collect();
        let data = Correspondences::from_acs(&acs).unwrap();
        let indices: Vec<usize> = (1..acs.len()).rev().collect();
        let weight = |i: usize, d: f64| (0.3 * d * d, 0.7 + d.abs() + 0.01 * i as f64);
        let (mut structured, mut dense) = (AffineSums::default(), EntrySums::new());
        let cost_s = structured.add_acs(&h, &data, &indices, |i, d| {
            let mut cost = 0.0;
            let w = d.map(|d| {
                let (rho, w) = weight(i, d);
                cost += rho;
                w
            });
            (cost, w)
        });
        let mut cost_d = 0.0;
        for &i in &indices {
            for (d, grad) in affine_residuals_and_gradients(&h, &data.x1[i], &data.a[i]) {
                let (rho, w) = weight(i, d);
                cost_d += rho;
                dense.add(&grad, w, d);
            }
        }
        let got = structured.entry_sums();
        assert!((cost_s - cost_d).abs() <= 1e-12 * cost_d.abs());
        for (g, e) in got.g_sum.iter().zip(dense.g_sum) {
            assert!((g - e).abs() <= 1e-12 * e.abs().max(1e-9), "{g} vs {e}");
        }
        for (g, e) in got.gg.iter().zip(dense.gg) {
            assert!((g - e).abs() <= 1e-12 * e.abs().max(1e-9), "{g} vs {e}");
        }
    }

    #[test]
    fn gradients_match_central_differences_and_the_residual_vanishes_at_the_truth() {
        let h = Mat3::new(0.9, -0.2, 30.0, 0.15, 1.1, -12.0, 4e-4, -2e-4, 1.0);
        let x1 = Vec2::new(210.0, 95.0);
        let ac = ac_from_homography(&h, &x1, 0).unwrap();
        for (d, _) in affine_residuals_and_gradients(&h, &x1, &ac.a) {
            assert!(d.abs() < 1e-12, "{d}");
        }
        let a = ac.a + Mat2::new(0.01, -0.02, 0.03, 0.0);
        let base = affine_residuals_and_gradients(&h, &x1, &a);
        // The residuals alone are the same numbers: minus the offset of A from A_H.
        let offset = [0.01, -0.02, 0.03, 0.0];
        for ((d, (e, _)), o) in affine_residuals(&h, &x1, &a).iter().zip(base).zip(offset) {
            assert!((d - e).abs() <= 1e-15, "{d} vs {e}");
            assert!((d + o).abs() <= 1e-12, "{d} vs -{o}");
        }
        for k in 0..9 {
            let step = 1e-6 * h[(k / 3, k % 3)].abs().max(1e-4);
            let (mut hp, mut hm) = (h, h);
            hp[(k / 3, k % 3)] += step;
            hm[(k / 3, k % 3)] -= step;
            let (p, m) = (
                affine_residuals_and_gradients(&hp, &x1, &a),
                affine_residuals_and_gradients(&hm, &x1, &a),
            );
            for e in 0..4 {
                let fd = (p[e].0 - m[e].0) / (2.0 * step);
                let an = base[e].1[k];
                assert!(
                    (fd - an).abs() <= 1e-6 * an.abs().max(1e-3),
                    "entry {e}, h[{k}]: analytic {an}, central difference {fd}"
                );
            }
        }
    }
}
