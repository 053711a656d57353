//! Homography estimation, p2 ~ H p1 in pixels.
//!
//! - Minimal samples: 4 points ([`homography_4pt`]), 2 ACs ([`homography_2ac`]) or 1 AC and
//!   2 points ([`homography_1ac2pt`]).
//! - Non-minimal fit (local optimisation): the normalised DLT on the inliers
//!   from its normal equations ([`homography_lsq_normal_equations`]), or on their ACs when
//!   fewer than 4.
//! - Residual (px²): the transfer error ‖x2 − π(H p1)‖², plus, with `affine_weight` λ > 0,
//!   λ·‖A − A_H(x1)‖²_F, where A_H(x1) is the AC H induces (docs/design.md §2). λ is in px²: with
//!   λ = ρ²/2 the affine term is the mean squared displacement of a circle of radius ρ px mapped
//!   by A instead of A_H.

use super::simd::{BLOCK, Lanes, UPPER_3X3, add_sums, dispatch};
use super::{
    Correspondences, SEED_AFFINE_WEIGHT, SampleKind, count_below, homography_affine, hybrid_support,
};
use crate::loss::Loss;
use crate::options::LoSchedule;
use crate::problem::Problem;
use crate::refine::{LeastSquares, LmOptions, Mat9, Vec9, levenberg_marquardt};
use affcorr_geom::{AffineCorrespondence, Mat2, Mat3, Vec2};
use affcorr_solvers::homography::{
    homography_1ac2pt, homography_2ac, homography_4pt, homography_ac_lsq,
    homography_lsq_normal_equations,
};

/// A homography problem over a set of correspondences.
pub struct HomographyProblem<'a> {
    data: &'a Correspondences,
    kind: SampleKind,
    affine_weight: f64,
    /// Per-AC confidence in [0, 1] of the affine term of scoring.
    confidence: Option<&'a [f64]>,
}

impl<'a> HomographyProblem<'a> {
    /// `data` sampled as `kind`, scored with `affine_weight` λ (0: points only). The caller has
    /// validated that affine samples/weights come with affine data.
    pub fn new(data: &'a Correspondences, kind: SampleKind, affine_weight: f64) -> Self {
        Self {
            data,
            kind,
            affine_weight,
            confidence: None,
        }
    }

    /// Weighs each AC's affine terms (scoring and the affine refinement) by `confidence` (one
    /// value in [0, 1] per datum, checked by the estimators).
    pub fn with_affine_confidence(mut self, confidence: Option<&'a [f64]>) -> Self {
        self.confidence = confidence;
        self
    }
}

/// The first damping of the refinement's points-only Levenberg–Marquardt
/// ([`LmOptions::initial_damping`]). It starts from the linear fit on the inliers, close to
/// the transfer-error optimum, where the Gauss–Newton step is the right one; in pixel
/// coordinates H's entries are so correlated that the default damping shortened that step in
/// the flat directions and LM crept to the optimum. The affine stage that follows keeps the
/// default: its Cauchy terms make the cost non-convex, and started undamped it moved single
/// scenes' errors either way, where the points-only stage alone leaves them as they were
/// (docs/estimation.md has the measurements).
const POINT_REFINEMENT_DAMPING: f64 = 1e-9;

impl HomographyProblem<'_> {
    /// Squared residual of datum `i` (see the module docs).
    #[inline(always)]
    fn residual(&self, h: &Mat3, i: usize) -> f64 {
        let c = self.confidence.map_or(1.0, |c| c[i]);
        self.residual_weighted(h, i, self.affine_weight * c)
    }

    /// Squared residual of datum `i` with affine weight `affine_weight`.
    #[inline(always)]
    fn residual_weighted(&self, h: &Mat3, i: usize, affine_weight: f64) -> f64 {
        let (r2, x2h, inv_w) = transfer(h, &self.data.x1[i], &self.data.x2[i]);
        if affine_weight == 0.0 {
            return r2;
        }
        // A_H(x1) = (H[0:2,0:2] − x2·H[2,0:2]) / w at the projected x2.
        let a_h = Mat2::new(
            h[(0, 0)] - x2h.x * h[(2, 0)],
            h[(0, 1)] - x2h.x * h[(2, 1)],
            h[(1, 0)] - x2h.y * h[(2, 0)],
            h[(1, 1)] - x2h.y * h[(2, 1)],
        ) * inv_w;
        r2 + affine_weight * (self.data.a[i] - a_h).norm_squared()
    }
}

/// Squared transfer error of one point and the projected point's homogeneous scale.
#[inline(always)]
fn transfer(h: &Mat3, x1: &Vec2, x2: &Vec2) -> (f64, Vec2, f64) {
    let w = h[(2, 0)] * x1.x + h[(2, 1)] * x1.y + h[(2, 2)];
    let inv_w = 1.0 / w;
    let u = (h[(0, 0)] * x1.x + h[(0, 1)] * x1.y + h[(0, 2)]) * inv_w;
    let v = (h[(1, 0)] * x1.x + h[(1, 1)] * x1.y + h[(1, 2)]) * inv_w;
    let (du, dv) = (u - x2.x, v - x2.y);
    (du * du + dv * dv, Vec2::new(u, v), inv_w)
}

impl Problem for HomographyProblem<'_> {
    type Model = Mat3;

    fn len(&self) -> usize {
        self.data.len()
    }

    fn sample_support(&self, h: &Mat3, threshold_sq: f64) -> Option<usize> {
        let seeds = || {
            count_below(self.len(), threshold_sq, |i| {
                self.residual_weighted(h, i, SEED_AFFINE_WEIGHT)
            })
        };
        match self.kind {
            SampleKind::Points => None,
            SampleKind::Affine => Some(seeds()),
            SampleKind::Hybrid => {
                let inliers = count_below(self.len(), threshold_sq, |i| {
                    self.residual_weighted(h, i, 0.0)
                });
                Some(hybrid_support(
                    seeds(),
                    inliers,
                    self.len(),
                    self.sample_size(),
                ))
            }
        }
    }

    fn positions(&self) -> Option<(&[Vec2], &[Vec2])> {
        Some((&self.data.x1, &self.data.x2))
    }

    fn refines_affine(&self) -> bool {
        self.data.has_usable_affine(self.confidence)
    }

    fn scoring_affine_weight(&self) -> f64 {
        self.affine_weight
    }

    fn sample_size(&self) -> usize {
        match self.kind {
            SampleKind::Points => 4,
            SampleKind::Affine => 2,
            SampleKind::Hybrid => 3,
        }
    }

    fn fit_minimal(&self, sample: &[usize], out: &mut Vec<Mat3>) {
        let mut h = [Mat3::zeros(); 1];
        let n = match self.kind {
            SampleKind::Points => {
                let x1: [Vec2; 4] = std::array::from_fn(|k| self.data.x1[sample[k]]);
                let x2: [Vec2; 4] = std::array::from_fn(|k| self.data.x2[sample[k]]);
                homography_4pt(&x1, &x2, &mut h)
            }
            SampleKind::Affine => {
                let acs: [AffineCorrespondence; 2] =
                    std::array::from_fn(|k| self.data.ac(sample[k]));
                homography_2ac(&acs, &mut h)
            }
            SampleKind::Hybrid => {
                let x1 = [self.data.x1[sample[1]], self.data.x1[sample[2]]];
                let x2 = [self.data.x2[sample[1]], self.data.x2[sample[2]]];
                homography_1ac2pt(&self.data.ac(sample[0]), &x1, &x2, &mut h)
            }
        };
        out.extend_from_slice(&h[..n]);
    }

    fn fit_nonminimal(&self, indices: &[usize], _weights: Option<&[f64]>) -> Option<Mat3> {
        let mut h = [Mat3::zeros(); 1];
        let n = if indices.len() >= 4 {
            // The normal equations: LO fits hundreds of points many times per run, and the QR
            // of the 2N×9 system was a large share of a homography run (benches/results/ransac.md).
            homography_lsq_normal_equations(&self.data.x1, &self.data.x2, indices, None, &mut h)
        } else if self.data.has_affine() {
            let acs: Vec<AffineCorrespondence> = indices.iter().map(|&i| self.data.ac(i)).collect();
            homography_ac_lsq(&acs, &mut h)
        } else {
            0
        };
        (n == 1).then_some(h[0])
    }

    fn residuals(&self, h: &Mat3, start: usize, out: &mut [f64]) {
        if self.affine_weight != 0.0 {
            for (k, o) in out.iter_mut().enumerate() {
                *o = self.residual(h, start + k);
            }
            return;
        }
        // The hot loop of scoring: slices instead of indices and no loop-invariant branch
        // inside, so that the compiler can vectorise it.
        let end = start + out.len();
        let (x1, x2) = (&self.data.x1[start..end], &self.data.x2[start..end]);
        dispatch(
            #[inline(always)]
            || {
                for ((o, p), q) in out.iter_mut().zip(x1).zip(x2) {
                    *o = transfer(h, p, q).0;
                }
            },
        );
    }

    fn residuals_at(&self, h: &Mat3, indices: &[usize], out: &mut [f64]) {
        for (o, &i) in out.iter_mut().zip(indices) {
            *o = self.residual(h, i);
        }
    }

    /// Levenberg–Marquardt of the transfer error on the unit sphere of H (8 degrees of freedom);
    /// with `options.affine` and ACs, plus their affine terms (`homography_affine`), λ
    /// re-estimated at each round's result.
    fn refine(
        &self,
        model: &Mat3,
        inliers: &[usize],
        loss: &Loss,
        options: &LmOptions,
    ) -> Option<Mat3> {
        let mut h = model / model.norm();
        let points = LmOptions {
            initial_damping: POINT_REFINEMENT_DAMPING,
            ..*options
        };
        if !(options.affine && self.data.has_affine()) {
            return Some(levenberg_marquardt(self, &h, inliers, loss, &points).0);
        }
        h = levenberg_marquardt(self, &h, inliers, loss, &points).0;
        let mut lambda: Option<f64> = None;
        for _ in 0..homography_affine::AFFINE_ROUNDS {
            let Some(terms) =
                homography_affine::affine_terms(self.data, &h, inliers, self.confidence)
            else {
                break;
            };
            if lambda.is_some_and(|l| (0.8..=1.25).contains(&(terms.lambda / l))) {
                break;
            }
            lambda = Some(terms.lambda);
            let fit = homography_affine::HomographyAffineFit {
                problem: self,
                data: self.data,
                terms,
            };
            h = levenberg_marquardt(&fit, &h, inliers, loss, options).0;
        }
        Some(h)
    }

    /// The normalised DLT on the inliers is close to the transfer-error optimum: LM inside LO
    /// changed no median error over the profile scenes and was a large share of a run's
    /// instructions (benches/results/ransac.md).
    fn lo_refines(&self) -> bool {
        false
    }

    /// Both tracks: a homography's refit is a 9×9 DLT, so the second track costs little, and
    /// the widening track alone returned a compromise between a wall and a cluster of matches
    /// 5 px off it in 16 of 20 seeds on real data (DISK on graffiti; docs/estimation.md).
    fn lo_schedule(&self) -> LoSchedule {
        LoSchedule::Both
    }
}

impl HomographyProblem<'_> {
    /// The sums of [`LeastSquares::normal_equations`] over blocks: gather, [`transfer`] lane by
    /// lane, the loss per datum, then the 33 sums as dot products over the block. Returns the
    /// cost if `COST`, else 0.
    #[inline(always)]
    fn accumulate<const COST: bool>(
        &self,
        h: &Mat3,
        indices: &[usize],
        loss: &Loss,
        pp_sums: [&mut [f64; 6]; 4],
        g: [&mut [f64; 3]; 3],
    ) -> f64 {
        let mut cost = 0.0;
        let (mut x1, mut x2) = ([Vec2::zeros(); BLOCK], [Vec2::zeros(); BLOCK]);
        let (mut r2, mut u, mut v) = ([0.0; BLOCK], [0.0; BLOCK], [0.0; BLOCK]);
        let mut p = [[0.0; BLOCK]; 3];
        let (mut w, mut wu, mut wv, mut wuv) =
            ([0.0; BLOCK], [0.0; BLOCK], [0.0; BLOCK], [0.0; BLOCK]);
        let (mut ru, mut rv, mut rr) = ([0.0; BLOCK], [0.0; BLOCK], [0.0; BLOCK]);
        let mut pp_lanes = [[Lanes::default(); 6]; 4];
        let mut g_lanes = [[Lanes::default(); 3]; 3];
        for chunk in indices.chunks(BLOCK) {
            let len = chunk.len();
            for (j, &i) in chunk.iter().enumerate() {
                (x1[j], x2[j]) = (self.data.x1[i], self.data.x2[i]);
            }
            for j in 0..BLOCK {
                let (e, proj, inv_w) = transfer(h, &x1[j], &x2[j]);
                (r2[j], u[j], v[j]) = (e, proj.x, proj.y);
                (p[0][j], p[1][j], p[2][j]) = (x1[j].x * inv_w, x1[j].y * inv_w, inv_w);
            }
            for j in 0..len {
                if COST {
                    let c;
                    (c, w[j]) = loss.cost_and_weight(r2[j]);
                    cost += c;
                } else {
                    w[j] = loss.weight(r2[j]);
                }
            }
            // The tail of a short last block (stale but finite values) must not count.
            w[len..].fill(0.0);
            for j in 0..BLOCK {
                (wu[j], wv[j]) = (w[j] * u[j], w[j] * v[j]);
                wuv[j] = w[j] * (u[j] * u[j] + v[j] * v[j]);
                (ru[j], rv[j]) = (w[j] * (u[j] - x2[j].x), w[j] * (v[j] - x2[j].y));
                rr[j] = u[j] * ru[j] + v[j] * rv[j];
            }
            for (k, &(a, b)) in UPPER_3X3.iter().enumerate() {
                let pp: [f64; BLOCK] = std::array::from_fn(|j| p[a][j] * p[b][j]);
                for (sum, weight) in [(0, &w), (1, &wu), (2, &wv), (3, &wuv)] {
                    pp_lanes[sum][k].add_dot(weight, &pp);
                }
            }
            for k in 0..3 {
                g_lanes[0][k].add_dot(&ru, &p[k]);
                g_lanes[1][k].add_dot(&rv, &p[k]);
                g_lanes[2][k].add_dot(&rr, &p[k]);
            }
        }
        for (sums, lanes) in pp_sums.into_iter().zip(&pp_lanes) {
            add_sums(sums, lanes);
        }
        let [g0, g1, g2] = g;
        add_sums(g0, &g_lanes[0]);
        add_sums(g1, &g_lanes[1]);
        for (gk, lanes) in g2.iter_mut().zip(&g_lanes[2]) {
            *gk -= lanes.sum();
        }
        cost
    }
}

/// An orthonormal basis of the tangent space of the unit sphere at vec(H): the last 8 columns of
/// the Householder reflection that maps vec(H) to ±e₁.
pub(crate) fn tangent_basis(h: &Mat3) -> [Vec9; 8] {
    let v = Vec9::from_iterator((0..9).map(|k| h[(k / 3, k % 3)]));
    let sign = if v[0] >= 0.0 { 1.0 } else { -1.0 };
    let mut u = v;
    u[0] += sign * v.norm();
    let uu = u.norm_squared();
    std::array::from_fn(|c| {
        // Column c + 1 of I − 2uuᵀ/uᵀu.
        let mut col = u * (-2.0 * u[c + 1] / uu);
        col[c + 1] += 1.0;
        col
    })
}

/// Transfer error r = π(H p1) − x2 (2 residuals per datum); ∂u/∂h₁ = p1/w, ∂u/∂h₃ = −u p1/w,
/// ∂v/∂h₂ = p1/w, ∂v/∂h₃ = −v p1/w, accumulated in the 9 entries of H and projected onto the
/// tangent basis once.
impl LeastSquares for HomographyProblem<'_> {
    type Model = Mat3;

    fn dof(&self) -> usize {
        8
    }

    fn cost(&self, h: &Mat3, indices: &[usize], loss: &Loss) -> f64 {
        indices
            .iter()
            .map(|&i| loss.cost(transfer(h, &self.data.x1[i], &self.data.x2[i]).0))
            .sum()
    }

    fn normal_equations<const COST: bool>(
        &self,
        h: &Mat3,
        indices: &[usize],
        loss: &Loss,
        jtj: &mut Mat9,
        jtr: &mut Vec9,
    ) -> f64 {
        // With p = p1/w, J_u = [pᵀ, 0, −u pᵀ] and J_v = [0, pᵀ, −v pᵀ], so JᵀWJ has four
        // distinct 3×3 blocks, all weighted sums of p pᵀ: Σw ppᵀ (rows 0–2 and 3–5), −Σwu ppᵀ,
        // −Σwv ppᵀ and Σw(u² + v²) ppᵀ; 24 sums per datum instead of 45 products of 9-vectors,
        // accumulated over blocks (`simd`).
        let (mut s, mut su, mut sv, mut suv) = ([0.0; 6], [0.0; 6], [0.0; 6], [0.0; 6]);
        let (mut g0, mut g1, mut g2) = ([0.0; 3], [0.0; 3], [0.0; 3]);
        let cost = dispatch(
            #[inline(always)]
            || {
                self.accumulate::<COST>(
                    h,
                    indices,
                    loss,
                    [&mut s, &mut su, &mut sv, &mut suv],
                    [&mut g0, &mut g1, &mut g2],
                )
            },
        );
        let sym = |m: &[f64; 6], r: usize, c: usize| {
            const IDX: [[usize; 3]; 3] = [[0, 1, 2], [1, 3, 4], [2, 4, 5]];
            m[IDX[r][c]]
        };
        let mut a = Mat9::zeros();
        for r in 0..3 {
            for c in 0..3 {
                a[(r, c)] = sym(&s, r, c);
                a[(3 + r, 3 + c)] = sym(&s, r, c);
                a[(r, 6 + c)] = -sym(&su, r, c);
                a[(6 + c, r)] = -sym(&su, r, c);
                a[(3 + r, 6 + c)] = -sym(&sv, r, c);
                a[(6 + c, 3 + r)] = -sym(&sv, r, c);
                a[(6 + r, 6 + c)] = sym(&suv, r, c);
            }
        }
        let g = Vec9::from_column_slice(&[
            g0[0], g0[1], g0[2], g1[0], g1[1], g1[2], g2[0], g2[1], g2[2],
        ]);
        let basis = tangent_basis(h);
        for r in 0..8 {
            let ab = a * basis[r];
            jtr[r] += basis[r].dot(&g);
            for c in 0..8 {
                jtj[(r, c)] += basis[c].dot(&ab);
            }
        }
        cost
    }

    fn retract(&self, h: &Mat3, delta: &Vec9) -> Mat3 {
        let basis = tangent_basis(h);
        let mut v = Vec9::from_iterator((0..9).map(|k| h[(k / 3, k % 3)]));
        for k in 0..8 {
            v += basis[k] * delta[k];
        }
        let v = v / v.norm();
        Mat3::from_fn(|r, c| v[3 * r + c])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use affcorr_geom::Vec3;
    use affcorr_geom::synthetic::{NoiseModel, PlaneScene, noisy_correspondences};
    use rand::SeedableRng;

    #[test]
    fn tangent_basis_is_orthonormal_and_tangent() {
        let h = Mat3::new(0.7, -0.3, 225.0, 0.33, 1.01, -77.0, 3e-4, -1e-5, 1.0);
        let h = h / h.norm();
        let v = Vec9::from_iterator((0..9).map(|k| h[(k / 3, k % 3)]));
        let b = tangent_basis(&h);
        for i in 0..8 {
            assert!(b[i].dot(&v).abs() < 1e-14);
            for j in 0..8 {
                let expected = if i == j { 1.0 } else { 0.0 };
                assert!((b[i].dot(&b[j]) - expected).abs() < 1e-14);
            }
        }
    }

    #[test]
    fn normal_equations_equal_the_projected_jacobians() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(8);
        let scene = PlaneScene::random(&mut rng);
        let noise = NoiseModel {
            planes: 1,
            outlier_ratio: 0.3,
            pixel_noise: 1.0,
            affine_noise: 0.0,
        };
        let (acs, _) = noisy_correspondences(&mut rng, &scene, 40, &noise);
        let data = Correspondences::from_acs(&acs).unwrap();
        let problem = HomographyProblem::new(&data, SampleKind::Points, 0.0);
        let h = scene.homography() / scene.homography().norm();
        let idx: Vec<usize> = (0..40).collect();
        let loss = Loss::Cauchy { scale_sq: 4.0 };
        let (mut jtj, mut jtr) = (Mat9::zeros(), Vec9::zeros());
        let cost = problem.normal_equations::<true>(&h, &idx, &loss, &mut jtj, &mut jtr);
        assert!((cost - problem.cost(&h, &idx, &loss)).abs() <= 1e-12 * cost);
        // Without the cost, the same sums.
        let (mut jtj_k, mut jtr_k) = (Mat9::zeros(), Vec9::zeros());
        problem.normal_equations::<false>(&h, &idx, &loss, &mut jtj_k, &mut jtr_k);
        assert_eq!((jtj, jtr), (jtj_k, jtr_k));
        // Explicit: the 2×9 Jacobian of π(H p1) per datum, weighted, projected on the basis.
        let (mut a, mut g) = (Mat9::zeros(), Vec9::zeros());
        for &i in &idx {
            let (r2, proj, inv_w) = transfer(&h, &data.x1[i], &data.x2[i]);
            let w = loss.weight(r2);
            let p = Vec3::new(data.x1[i].x, data.x1[i].y, 1.0) * inv_w;
            let (mut ju, mut jv) = (Vec9::zeros(), Vec9::zeros());
            for k in 0..3 {
                ju[k] = p[k];
                jv[3 + k] = p[k];
                ju[6 + k] = -proj.x * p[k];
                jv[6 + k] = -proj.y * p[k];
            }
            a += (ju * ju.transpose() + jv * jv.transpose()) * w;
            g += (ju * (proj.x - data.x2[i].x) + jv * (proj.y - data.x2[i].y)) * w;
        }
        let basis = tangent_basis(&h);
        for r in 0..8 {
            let expected = basis[r].dot(&g);
            assert!((jtr[r] - expected).abs() < 1e-9 * g.norm(), "{r}");
            for c in 0..8 {
                let expected = basis[r].dot(&(a * basis[c]));
                assert!((jtj[(r, c)] - expected).abs() < 1e-9 * a.norm(), "{r} {c}");
            }
        }
        // The baseline build of the kernel (non-AVX2 CPUs) agrees with the dispatched one;
        // 40 data = 16 + 16 + a short block of 8.
        let run = |dispatched: bool| {
            let (mut s, mut g) = ([[0.0; 6]; 4], [[0.0; 3]; 3]);
            let [s0, s1, s2, s3] = &mut s;
            let [g0, g1, g2] = &mut g;
            let mut k =
                || problem.accumulate::<true>(&h, &idx, &loss, [s0, s1, s2, s3], [g0, g1, g2]);
            let c = if dispatched { dispatch(k) } else { k() };
            (c, s, g)
        };
        let ((c1, s1, g1), (c2, s2, g2)) = (run(false), run(true));
        assert!((c1 - c2).abs() < 1e-12 * c1);
        for (a, b) in s1.iter().flatten().zip(s2.iter().flatten()) {
            assert!((a - b).abs() <= 1e-12 * a.abs().max(1e-300), "{a} vs {b}");
        }
        for (a, b) in g1.iter().flatten().zip(g2.iter().flatten()) {
            assert!((a - b).abs() <= 1e-12 * a.abs().max(1e-300), "{a} vs {b}");
        }
    }

    /// `n` matches of one random plane with 1 px of noise on the points and no outliers.
    fn one_plane(seed: u64, n: usize) -> Correspondences {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
        let scene = PlaneScene::random(&mut rng);
        let noise = NoiseModel {
            planes: 1,
            outlier_ratio: 0.0,
            pixel_noise: 1.0,
            affine_noise: 0.0,
        };
        let (acs, _) = noisy_correspondences(&mut rng, &scene, n, &noise);
        Correspondences::from_acs(&acs).unwrap()
    }

    #[test]
    fn refinement_reaches_the_geometric_optimum_from_a_rough_fit() {
        let data = one_plane(5, 200);
        let problem = HomographyProblem::new(&data, SampleKind::Points, 0.0);
        let all: Vec<usize> = (0..200).collect();
        // A rough start: the linear fit on 6 points. (On all 200 the linear fit is already
        // within a tenth of a standard error of the optimum, and LM stops at once.)
        let rough = problem.fit_nonminimal(&all[..6], None).unwrap();
        let refined = problem
            .refine(
                &rough,
                &all,
                &Loss::Squared,
                &LmOptions {
                    max_iterations: 50,
                    ..Default::default()
                },
            )
            .unwrap();
        let linear = problem.fit_nonminimal(&all, None).unwrap();
        let (c0, c1, c_linear) = (
            problem.cost(&rough, &all, &Loss::Squared),
            problem.cost(&refined, &all, &Loss::Squared),
            problem.cost(&linear, &all, &Loss::Squared),
        );
        assert!(c1 < 0.5 * c0, "{c1} vs {c0}");
        // The geometric optimum leaves ~χ²(2N − 8)·σ² of residual: about 392 px² here, and
        // the linear fit on all data is close to it.
        assert!(c1 > 300.0 && c1 < 500.0, "{c1}");
        assert!(
            c1 <= c_linear * (1.0 + 1e-4),
            "{c1} vs the linear fit's {c_linear}"
        );
        assert!((refined.norm() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn a_start_near_the_optimum_takes_the_gauss_newton_step_with_little_damping() {
        // The final refinement's case: the linear fit on every inlier, a small step from the
        // geometric optimum, in pixel coordinates (a badly conditioned JᵀJ).
        let data = one_plane(8, 500);
        let problem = HomographyProblem::new(&data, SampleKind::Points, 0.0);
        let all: Vec<usize> = (0..500).collect();
        let linear = problem.fit_nonminimal(&all, None).unwrap();
        let options = |max_iterations: usize, initial_damping: f64| LmOptions {
            max_iterations,
            initial_damping,
            noise_fraction: 0.0,
            cost_tolerance: 0.0,
            ..Default::default()
        };
        let cost_after = |max_iterations: usize, initial_damping: f64| {
            let o = options(max_iterations, initial_damping);
            let h = levenberg_marquardt(&problem, &linear, &all, &Loss::Squared, &o).0;
            problem.cost(&h, &all, &Loss::Squared)
        };
        let optimum = cost_after(100, 1e-3);
        let excess = |cost: f64| (cost - optimum) / optimum;
        // One step with λ = 1e-9 (Gauss–Newton) lands on the optimum, to 1e-9 of its cost ...
        let gauss_newton = excess(cost_after(1, 1e-9));
        assert!(gauss_newton < 1e-9, "{gauss_newton}");
        // ... while the default damping shortens the steps in the flat directions: three
        // steps still leave more than the final refinement's stopping rule allows (0.001 of
        // the cost per datum, 2e-6 of the cost here).
        let damped = excess(cost_after(3, 1e-3));
        assert!(damped > 2e-6, "{damped}");
        // The refinement's points-only stage starts undamped, whatever damping it is given.
        let refined = problem
            .refine(&linear, &all, &Loss::Squared, &options(1, 1e-3))
            .unwrap();
        let refined = excess(problem.cost(&refined, &all, &Loss::Squared));
        assert!(refined < 1e-9, "{refined}");
    }
}
