//! Fundamental-matrix estimation, p2ᵀ F p1 = 0 in pixels.
//!
//! - Minimal samples: 7 points ([`fundamental_7pt`], ≤ 3 models), 3 ACs
//!   ([`fundamental_3ac`]) or 1 AC and 4 points ([`fundamental_1ac4pt`], ≤ 3 models).
//! - Non-minimal fit: the normalised 8-point algorithm on the inliers, from its normal equations
//!   ([`fundamental_8pt_normal_equations`]), or AC least squares when fewer than 8.
//! - Residual (px²): the point Sampson distance SD_P, plus, with `affine_weight` λ > 0,
//!   min(λ·c·(SD_A,1 + SD_A,2), cap), the affine Sampson distances of docs/design.md §3 with the
//!   AC's confidence c (1 without) and a cap (+∞ unless set).

use super::simd::{BLOCK, dispatch, gather};
use super::{
    Correspondences, SEED_AFFINE_WEIGHT, SampleKind, count_below, epipolar_lm, hybrid_support,
    most_models,
};
use crate::loss::Loss;
use crate::problem::Problem;
use crate::refine::{LeastSquares, LmOptions, Mat9, Vec9, levenberg_marquardt};
use affcorr_geom::epipolar::skew;
use affcorr_geom::homography::ac_from_homography;
use affcorr_geom::sampson::{sampson_point, sampson_point_affine};
use affcorr_geom::{AffineCorrespondence, Mat3, PointCorrespondence, Vec2, Vec3};
use affcorr_solvers::fundamental::{
    FUNDAMENTAL_1AC4PT_MAX_SOLUTIONS, FUNDAMENTAL_3AC_MAX_SOLUTIONS, FUNDAMENTAL_7PT_MAX_SOLUTIONS,
    fundamental_1ac4pt, fundamental_3ac, fundamental_7pt, fundamental_8pt_normal_equations,
    fundamental_ac_lsq,
};
use affcorr_solvers::homography::homography_2ac;

const MAX_MODELS: usize = most_models(&[
    FUNDAMENTAL_7PT_MAX_SOLUTIONS,
    FUNDAMENTAL_3AC_MAX_SOLUTIONS,
    FUNDAMENTAL_1AC4PT_MAX_SOLUTIONS,
]);

/// A fundamental-matrix problem over a set of correspondences.
pub struct FundamentalProblem<'a> {
    data: &'a Correspondences,
    kind: SampleKind,
    affine_weight: f64,
    /// Per-AC confidence in [0, 1] of the affine terms (scoring and refinement).
    confidence: Option<&'a [f64]>,
    /// The most the affine term adds to a residual (px²).
    affine_cap: f64,
    threshold: f64,
    /// Hartley normalisations of the two images (centroid at 0, mean distance √2): the
    /// refinement parametrises F̃ = T2⁻ᵀ F T1⁻¹, whose singular values are of one order, where
    /// the pixel F's are not (σ₂/σ₁ ~ 1e-3 makes the rank-2 manifold's charts so curved that
    /// Levenberg–Marquardt crawls).
    t1: Mat3,
    t2: Mat3,
}

impl<'a> FundamentalProblem<'a> {
    /// `data` sampled as `kind`, scored with `affine_weight` λ (0: points only); `threshold`
    /// (pixels) is the inlier threshold, used to detect planar samples.
    pub fn new(
        data: &'a Correspondences,
        kind: SampleKind,
        affine_weight: f64,
        threshold: f64,
    ) -> Self {
        Self {
            data,
            kind,
            affine_weight,
            confidence: None,
            affine_cap: f64::INFINITY,
            threshold,
            t1: hartley(&data.x1),
            t2: hartley(&data.x2),
        }
    }

    /// Weighs each AC's affine terms (in scoring and in the refinements) by `confidence` (one
    /// value in [0, 1] per datum, checked by the estimators).
    pub fn with_affine_confidence(mut self, confidence: Option<&'a [f64]>) -> Self {
        self.confidence = confidence;
        self
    }

    /// Caps the affine term of the residual at `cap` px² (default +∞), so that a poor A can
    /// cost an AC at most that much of its score and never its inlier status when its point
    /// fits (the estimators' default weight uses a quarter of the threshold²).
    pub fn with_affine_cap(mut self, cap: f64) -> Self {
        self.affine_cap = cap;
        self
    }

    fn affine_score(&self) -> AffineScore<'a> {
        AffineScore {
            weight: self.affine_weight,
            confidence: self.confidence,
            cap: self.affine_cap,
        }
    }

    /// The pixel F of a normalised F̃: T2ᵀ F̃ T1.
    #[inline]
    fn to_pixels(&self, f: &Mat3) -> Mat3 {
        self.t2.transpose() * f * self.t1
    }

    /// Whether 3 ACs lie on one plane: the homography of the first two explains the third to
    /// within the threshold. Such a sample fixes F only up to the epipole (F = [e]× H), so the
    /// 3AC solver's F is arbitrary within that family (the planar degeneracy that DEGENSAC
    /// handles for points).
    fn planar(&self, acs: &[AffineCorrespondence; 3]) -> bool {
        let mut h = [Mat3::zeros(); 1];
        if homography_2ac(&acs[..2], &mut h) == 0 {
            return false;
        }
        let Ok(induced) = ac_from_homography(&h[0], &acs[2].x1, 2) else {
            return false;
        };
        // The affine term is measured as the displacement on a circle of radius 10 px.
        let tol = 3.0 * self.threshold;
        (induced.x2 - acs[2].x2).norm() < tol && (induced.a - acs[2].a).norm() * 10.0 < tol
    }
}

/// How the affine Sampson distances enter an epipolar residual: weight λ (px²), per-AC
/// confidence (scaling λ), and the most (px²) the affine term may add.
#[derive(Debug, Clone, Copy)]
pub(crate) struct AffineScore<'a> {
    pub weight: f64,
    pub confidence: Option<&'a [f64]>,
    pub cap: f64,
}

impl AffineScore<'_> {
    /// Points only.
    pub(crate) const NONE: AffineScore<'static> = AffineScore {
        weight: 0.0,
        confidence: None,
        cap: f64::INFINITY,
    };
}

/// Squared Sampson residual of datum `i` under `f`: SD_P + min(λ c_i (SD_A,0 + SD_A,1), cap).
#[inline(always)]
fn epipolar_residual(data: &Correspondences, f: &Mat3, a: &AffineScore<'_>, i: usize) -> f64 {
    if a.weight == 0.0 {
        let points = PointCorrespondence {
            x1: data.x1[i],
            x2: data.x2[i],
        };
        return sampson_point(f, &points);
    }
    let w = a.weight * a.confidence.map_or(1.0, |c| c[i]);
    mixed_residual(f, &data.ac(i), w, a.cap)
}

/// SD_P + min(w (SD_A,0 + SD_A,1), cap) of one AC, the point and affine forms sharing F p1 and
/// Fᵀ p2 ([`sampson_point_affine`]); branch-free, so that loops over it vectorise.
#[inline(always)]
fn mixed_residual(f: &Mat3, ac: &AffineCorrespondence, w: f64, cap: f64) -> f64 {
    let (p, [a0, a1]) = sampson_point_affine(f, ac);
    p + (w * (a0 + a1)).min(cap)
}

/// The data that can seed a good AC sample of `sample_size` under `f`
/// (`Problem::sample_support`; for a hybrid sample the support of [`hybrid_support`]); `None`
/// for point samples.
pub(crate) fn epipolar_seeds(
    data: &Correspondences,
    f: &Mat3,
    kind: SampleKind,
    sample_size: usize,
    threshold_sq: f64,
) -> Option<usize> {
    let below = |weight| {
        let score = AffineScore {
            weight,
            ..AffineScore::NONE
        };
        count_below(data.len(), threshold_sq, |i| {
            epipolar_residual(data, f, &score, i)
        })
    };
    match kind {
        SampleKind::Points => None,
        SampleKind::Affine => Some(below(SEED_AFFINE_WEIGHT)),
        SampleKind::Hybrid => Some(hybrid_support(
            below(SEED_AFFINE_WEIGHT),
            below(0.0),
            data.len(),
            sample_size,
        )),
    }
}

/// Squared Sampson residuals (point, plus weighted affine) of `data[start..]` under `f`.
pub(crate) fn epipolar_residuals(
    data: &Correspondences,
    f: &Mat3,
    affine: &AffineScore<'_>,
    start: usize,
    out: &mut [f64],
) {
    // The hot loops of scoring: slices instead of indices and no loop-invariant branch inside,
    // so that the compiler can vectorise them.
    let end = start + out.len();
    let (x1, x2) = (&data.x1[start..end], &data.x2[start..end]);
    if affine.weight != 0.0 {
        let (weight, cap, a) = (affine.weight, affine.cap, &data.a[start..end]);
        let ac = |k: usize| AffineCorrespondence {
            x1: x1[k],
            x2: x2[k],
            a: a[k],
        };
        match affine.confidence {
            Some(c) => {
                let c = &c[start..end];
                dispatch(
                    #[inline(always)]
                    || {
                        for (k, o) in out.iter_mut().enumerate() {
                            *o = mixed_residual(f, &ac(k), weight * c[k], cap);
                        }
                    },
                );
            }
            None => dispatch(
                #[inline(always)]
                || {
                    for (k, o) in out.iter_mut().enumerate() {
                        *o = mixed_residual(f, &ac(k), weight, cap);
                    }
                },
            ),
        }
        return;
    }
    dispatch(
        #[inline(always)]
        || {
            for ((o, x1), x2) in out.iter_mut().zip(x1).zip(x2) {
                *o = sampson_point(f, &PointCorrespondence { x1: *x1, x2: *x2 });
            }
        },
    );
}

/// [`epipolar_residuals`] of the data `indices`, in their order (the SPRT's random order),
/// gathered block by block so that they vectorise as [`epipolar_residuals`]' do.
pub(crate) fn epipolar_residuals_at(
    data: &Correspondences,
    f: &Mat3,
    affine: &AffineScore<'_>,
    indices: &[usize],
    out: &mut [f64],
) {
    let (weight, cap) = (affine.weight, affine.cap);
    for (idx, out) in indices.chunks(BLOCK).zip(out.chunks_mut(BLOCK)) {
        let mut r = [0.0; BLOCK];
        if weight == 0.0 {
            let points = gather(idx, |i| PointCorrespondence {
                x1: data.x1[i],
                x2: data.x2[i],
            });
            dispatch(
                #[inline(always)]
                || {
                    for (r, c) in r.iter_mut().zip(&points) {
                        *r = sampson_point(f, c);
                    }
                },
            );
        } else {
            let acs = gather(idx, |i| data.ac(i));
            let w = gather(idx, |i| weight * affine.confidence.map_or(1.0, |c| c[i]));
            dispatch(
                #[inline(always)]
                || {
                    for ((r, ac), w) in r.iter_mut().zip(&acs).zip(&w) {
                        *r = mixed_residual(f, ac, *w, cap);
                    }
                },
            );
        }
        out.copy_from_slice(&r[..out.len()]);
    }
}

impl Problem for FundamentalProblem<'_> {
    type Model = Mat3;

    fn len(&self) -> usize {
        self.data.len()
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

    fn sample_support(&self, f: &Mat3, threshold_sq: f64) -> Option<usize> {
        epipolar_seeds(self.data, f, self.kind, self.sample_size(), threshold_sq)
    }

    fn sample_size(&self) -> usize {
        match self.kind {
            SampleKind::Points => 7,
            SampleKind::Affine => 3,
            SampleKind::Hybrid => 5,
        }
    }

    fn fit_minimal(&self, sample: &[usize], out: &mut Vec<Mat3>) {
        let mut f = [Mat3::zeros(); MAX_MODELS];
        let n = match self.kind {
            SampleKind::Points => {
                let x1: [Vec2; 7] = std::array::from_fn(|k| self.data.x1[sample[k]]);
                let x2: [Vec2; 7] = std::array::from_fn(|k| self.data.x2[sample[k]]);
                fundamental_7pt(&x1, &x2, &mut f)
            }
            SampleKind::Affine => {
                let acs: [AffineCorrespondence; 3] =
                    std::array::from_fn(|k| self.data.ac(sample[k]));
                if self.planar(&acs) {
                    return;
                }
                fundamental_3ac(&acs, &mut f)
            }
            SampleKind::Hybrid => {
                let x1: [Vec2; 4] = std::array::from_fn(|k| self.data.x1[sample[k + 1]]);
                let x2: [Vec2; 4] = std::array::from_fn(|k| self.data.x2[sample[k + 1]]);
                fundamental_1ac4pt(&self.data.ac(sample[0]), &x1, &x2, &mut f)
            }
        };
        out.extend_from_slice(&f[..n]);
    }

    fn fit_nonminimal(&self, indices: &[usize], _weights: Option<&[f64]>) -> Option<Mat3> {
        let mut f = [Mat3::zeros(); 1];
        let n = if indices.len() >= 8 {
            // The normal equations: LO refits hundreds of points many times per run.
            fundamental_8pt_normal_equations(&self.data.x1, &self.data.x2, indices, None, &mut f)
        } else if self.data.has_affine() && indices.len() >= 3 {
            let acs: Vec<AffineCorrespondence> = indices.iter().map(|&i| self.data.ac(i)).collect();
            fundamental_ac_lsq(&acs, &mut f)
        } else {
            0
        };
        (n == 1).then_some(f[0])
    }

    fn residuals(&self, f: &Mat3, start: usize, out: &mut [f64]) {
        epipolar_residuals(self.data, f, &self.affine_score(), start, out);
    }

    fn residuals_at(&self, f: &Mat3, indices: &[usize], out: &mut [f64]) {
        epipolar_residuals_at(self.data, f, &self.affine_score(), indices, out);
    }

    /// Levenberg–Marquardt on the rank-2 manifold of the Sampson error (plus, with
    /// `options.affine`, the affine terms of `epipolar_lm`).
    fn refine(
        &self,
        model: &Mat3,
        inliers: &[usize],
        loss: &Loss,
        options: &LmOptions,
    ) -> Option<Mat3> {
        let (t1_inv, t2_inv) = (self.t1.try_inverse()?, self.t2.try_inverse()?);
        let start = RankTwo::new(&(t2_inv.transpose() * model * t1_inv))?;
        let mut m = start;
        let mut f = *model;
        for _ in 0..epipolar_lm::AFFINE_ROUNDS {
            let affine =
                epipolar_lm::affine_terms(self.data, &f, inliers, self.confidence, options);
            let lambda = affine.map(|t| t.lambda);
            let fit = FundamentalFit {
                problem: self,
                affine,
            };
            m = levenberg_marquardt(&fit, &m, inliers, loss, options).0;
            f = self.to_pixels(&m.matrix());
            f /= f.norm();
            if !epipolar_lm::rescale_again(self.data, &f, inliers, self.confidence, lambda) {
                break;
            }
        }
        Some(f)
    }
}

/// F = U diag(1, σ, 0) Vᵀ with U, V rotations and 0 ≤ σ ≤ 1: every rank-2 matrix up to scale
/// (Bartoli & Sturm's orthonormal representation, 7 degrees of freedom).
#[derive(Debug, Clone, Copy)]
pub struct RankTwo {
    u: Mat3,
    v: Mat3,
    sigma: f64,
    f: Mat3,
}

impl RankTwo {
    /// From any F of rank ≥ 2 (the smallest singular value is dropped).
    pub fn new(f: &Mat3) -> Option<Self> {
        let svd = f.svd(true, true);
        let (mut u, mut v_t) = (svd.u?, svd.v_t?);
        let mut s = svd.singular_values;
        // Sort descending (nalgebra does not guarantee the order).
        for i in 0..3 {
            for j in i + 1..3 {
                if s[j] > s[i] {
                    s.swap_rows(i, j);
                    u.swap_columns(i, j);
                    v_t.swap_rows(i, j);
                }
            }
        }
        if !(s[0] > 0.0) {
            return None;
        }
        if u.determinant() < 0.0 {
            u.column_mut(2).neg_mut();
        }
        if v_t.determinant() < 0.0 {
            v_t.row_mut(2).neg_mut();
        }
        Some(Self::from_parts(u, v_t.transpose(), s[1] / s[0]))
    }

    fn from_parts(u: Mat3, v: Mat3, sigma: f64) -> Self {
        let f = u * Mat3::from_diagonal(&Vec3::new(1.0, sigma, 0.0)) * v.transpose();
        Self {
            u,
            v,
            sigma,
            f: f / f.norm(),
        }
    }

    /// F with unit Frobenius norm.
    pub fn matrix(&self) -> Mat3 {
        self.f
    }
}

/// Centroid to 0, mean distance to √2 (identity for degenerate input).
fn hartley(x: &[Vec2]) -> Mat3 {
    if x.is_empty() {
        return Mat3::identity();
    }
    let n = x.len() as f64;
    let c = x.iter().fold(Vec2::zeros(), |a, p| a + p) / n;
    let d = x.iter().map(|p| (p - c).norm()).sum::<f64>() / n;
    if !(d > 0.0 && d.is_finite()) {
        return Mat3::identity();
    }
    let s = std::f64::consts::SQRT_2 / d;
    Mat3::new(s, 0.0, -s * c.x, 0.0, s, -s * c.y, 0.0, 0.0, 1.0)
}

/// The least-squares problem of [`FundamentalProblem::refine`]: its data, with or without the
/// affine terms.
struct FundamentalFit<'p, 'a> {
    problem: &'p FundamentalProblem<'a>,
    affine: Option<epipolar_lm::AffineTerms<'a>>,
}

/// In the normalised frame (F̃, see [`FundamentalProblem`]): ∂F/∂a_k = U \[e_k\]× S Vᵀ, ∂F/∂b_k = −U S \[e_k\]× Vᵀ (U ← U exp(\[a\]×), V ← V exp(\[b\]×)),
/// ∂F/∂σ = U diag(0, 1, 0) Vᵀ; the unit-norm rescaling of F does not change the Sampson error.
impl LeastSquares for FundamentalFit<'_, '_> {
    type Model = RankTwo;

    fn dof(&self) -> usize {
        7
    }

    fn cost(&self, m: &RankTwo, indices: &[usize], loss: &Loss) -> f64 {
        let f = self.problem.to_pixels(&m.f);
        let data = self.problem.data;
        epipolar_lm::cost(data, &f, indices, loss)
            + self
                .affine
                .as_ref()
                .map_or(0.0, |t| epipolar_lm::affine_cost(data, &f, indices, t))
    }

    fn normal_equations<const COST: bool>(
        &self,
        m: &RankTwo,
        indices: &[usize],
        loss: &Loss,
        jtj: &mut Mat9,
        jtr: &mut Vec9,
    ) -> f64 {
        let s = Mat3::from_diagonal(&Vec3::new(1.0, m.sigma, 0.0));
        let (u, vt) = (m.u, m.v.transpose());
        let e = [Vec3::x(), Vec3::y(), Vec3::z()];
        let scale = 1.0 / (u * s * vt).norm();
        let basis: [Mat3; 7] = std::array::from_fn(|k| {
            let d = match k {
                0..=2 => u * skew(&e[k]) * s * vt,
                3..=5 => -(u * s * skew(&e[k - 3]) * vt),
                _ => u * Mat3::from_diagonal(&Vec3::new(0.0, 1.0, 0.0)) * vt,
            };
            self.problem.to_pixels(&(d * scale))
        });
        let f = self.problem.to_pixels(&m.f);
        let data = self.problem.data;
        let mut cost = epipolar_lm::normal_equations(data, &f, &basis, indices, loss, jtj, jtr);
        if let Some(t) = &self.affine {
            cost += epipolar_lm::affine_normal_equations(data, &f, &basis, indices, t, jtj, jtr);
        }
        cost
    }

    fn retract(&self, m: &RankTwo, d: &Vec9) -> RankTwo {
        let rot = |w: Vec3| {
            let angle = w.norm();
            if angle > 0.0 {
                affcorr_geom::synthetic::rotation_about(&(w / angle), angle)
            } else {
                Mat3::identity()
            }
        };
        let u = m.u * rot(Vec3::new(d[0], d[1], d[2]));
        let v = m.v * rot(Vec3::new(d[3], d[4], d[5]));
        RankTwo::from_parts(u, v, (m.sigma + d[6]).clamp(0.0, 1.0))
    }
}
