//! Relative pose (calibrated): X2 = R X1 + t from correspondences and intrinsics K1, K2.
//!
//! - Minimal samples in normalised coordinates (docs/design.md §2): 5 points
//!   ([`relative_pose_5pt`], ≤ 10 poses), 2 ACs ([`relative_pose_2ac`]) or 1 AC and 2 points
//!   ([`relative_pose_1ac2pt`]); each essential matrix
//!   is decomposed and only factorisations with the sample in front of both cameras are kept.
//! - Non-minimal fit: the 8-point essential matrix on the inliers (plus their AC equations when
//!   there are fewer than 8), decomposed with cheirality on those inliers.
//! - Residual (px²): the Sampson distance of F = K2⁻ᵀ E K1⁻¹ on the pixel coordinates, exact
//!   for any fx ≠ fy (no mean-focal approximation), plus the weighted affine Sampson distances.

use super::fundamental::{AffineScore, epipolar_residuals, epipolar_residuals_at, epipolar_seeds};
use super::simd::{BLOCK, dispatch, gather};
use super::{Correspondences, SampleKind, epipolar_lm, most_models};
use crate::loss::Loss;
use crate::problem::Problem;
use crate::refine::{LeastSquares, LmOptions, Mat9, Vec9, levenberg_marquardt};
use affcorr_geom::camera::{Intrinsics, normalize_ac};
use affcorr_geom::epipolar::{
    Cheirality, Pose, cheirality, fundamental_from_essential, pose_from_essential, skew,
};
use affcorr_geom::{AffineCorrespondence, Mat3, Vec2, Vec3};
use affcorr_solvers::essential::essential_lsq;
use affcorr_solvers::relpose::{
    RELPOSE_1AC2PT_MAX_SOLUTIONS, RELPOSE_2AC_MAX_SOLUTIONS, RELPOSE_5PT_MAX_SOLUTIONS,
    relative_pose_1ac2pt, relative_pose_2ac, relative_pose_5pt,
};

const MAX_POSES: usize = most_models(&[
    RELPOSE_5PT_MAX_SOLUTIONS,
    RELPOSE_2AC_MAX_SOLUTIONS,
    RELPOSE_1AC2PT_MAX_SOLUTIONS,
]);

/// A pose with the pixel fundamental matrix it induces (cached for scoring).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseModel {
    /// X2 = R X1 + t, |t| = 1.
    pub pose: Pose,
    /// E = \[t\]× R.
    pub essential: Mat3,
    /// F = K2⁻ᵀ E K1⁻¹ (pixels).
    pub fundamental: Mat3,
}

/// A relative-pose problem: pixel data for scoring, normalised data for the solvers.
pub struct RelativePoseProblem<'a> {
    pixels: &'a Correspondences,
    normalized: Correspondences,
    k1: Intrinsics,
    k2: Intrinsics,
    kind: SampleKind,
    affine_weight: f64,
    /// Per-AC confidence in [0, 1] of the affine terms (scoring and refinement).
    confidence: Option<&'a [f64]>,
    /// The most the affine term adds to a residual (px²).
    affine_cap: f64,
    /// Squared residual below which cheirality is checked.
    cheirality_cap_sq: f64,
}

impl<'a> RelativePoseProblem<'a> {
    /// `pixels` with intrinsics `k1`, `k2`, sampled as `kind`, scored with `affine_weight`; the
    /// data whose residual is below `cheirality_threshold` (px) are checked for cheirality. The
    /// estimators pass the widest threshold the run's local optimisation uses (a multiple of the
    /// inlier threshold), so that every datum that can count as an inlier at any step is checked.
    pub fn new(
        pixels: &'a Correspondences,
        k1: Intrinsics,
        k2: Intrinsics,
        kind: SampleKind,
        affine_weight: f64,
        cheirality_threshold: f64,
    ) -> Self {
        let normalized = if pixels.has_affine() {
            let acs: Vec<AffineCorrespondence> = (0..pixels.len())
                .map(|i| normalize_ac(&pixels.ac(i), &k1, &k2))
                .collect();
            Correspondences {
                x1: acs.iter().map(|a| a.x1).collect(),
                x2: acs.iter().map(|a| a.x2).collect(),
                a: acs.iter().map(|a| a.a).collect(),
            }
        } else {
            Correspondences {
                x1: pixels.x1.iter().map(|p| k1.normalize_point(p)).collect(),
                x2: pixels.x2.iter().map(|p| k2.normalize_point(p)).collect(),
                a: Vec::new(),
            }
        };
        Self {
            pixels,
            normalized,
            k1,
            k2,
            kind,
            affine_weight,
            confidence: None,
            affine_cap: f64::INFINITY,
            cheirality_cap_sq: cheirality_threshold.powi(2),
        }
    }

    /// Weighs each AC's affine terms (in scoring and in the refinements) by `confidence` (one
    /// value in [0, 1] per datum, checked by the estimators).
    pub fn with_affine_confidence(mut self, confidence: Option<&'a [f64]>) -> Self {
        self.confidence = confidence;
        self
    }

    /// Caps the affine term of the residual at `cap` px² (as
    /// [`super::fundamental::FundamentalProblem::with_affine_cap`]).
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

    /// The model of a pose.
    pub fn model(&self, pose: Pose) -> PoseModel {
        let essential = pose.essential();
        PoseModel {
            pose,
            essential,
            fundamental: fundamental_from_essential(&essential, &self.k1, &self.k2),
        }
    }

    /// Normalised coordinates of the data.
    pub fn normalized(&self) -> &Correspondences {
        &self.normalized
    }
}

/// The squared residual `r2` of a correspondence (normalised x1, x2), or +∞ when it is below
/// the cheirality threshold² `cap` (of [`RelativePoseProblem::new`]) and its point lies behind
/// either camera under `pose`: such a correspondence can satisfy the epipolar constraint but
/// not the pose (PoseLib's relative-pose score checks the same). Parallel rays (points at
/// infinity) pass. Branch-free ([`cheirality`]), so that the scoring loop vectorises.
#[inline(always)]
fn behind_is_outlier(pose: &Pose, x1: &Vec2, x2: &Vec2, r2: f64, cap: f64) -> f64 {
    if r2 < cap && cheirality(pose, x1, x2) == Cheirality::Behind {
        f64::INFINITY
    } else {
        r2
    }
}

impl Problem for RelativePoseProblem<'_> {
    type Model = PoseModel;

    fn len(&self) -> usize {
        self.pixels.len()
    }

    fn positions(&self) -> Option<(&[Vec2], &[Vec2])> {
        Some((&self.pixels.x1, &self.pixels.x2))
    }

    fn refines_affine(&self) -> bool {
        self.pixels.has_usable_affine(self.confidence)
    }

    fn scoring_affine_weight(&self) -> f64 {
        self.affine_weight
    }

    fn sample_support(&self, m: &PoseModel, threshold_sq: f64) -> Option<usize> {
        epipolar_seeds(
            self.pixels,
            &m.fundamental,
            self.kind,
            self.sample_size(),
            threshold_sq,
        )
    }

    fn sample_size(&self) -> usize {
        match self.kind {
            SampleKind::Points => 5,
            SampleKind::Affine => 2,
            SampleKind::Hybrid => 3,
        }
    }

    fn fit_minimal(&self, sample: &[usize], out: &mut Vec<PoseModel>) {
        let mut poses = [Pose {
            r: Mat3::identity(),
            t: Default::default(),
        }; MAX_POSES];
        let n = match self.kind {
            SampleKind::Points => {
                let x1: [Vec2; 5] = std::array::from_fn(|k| self.normalized.x1[sample[k]]);
                let x2: [Vec2; 5] = std::array::from_fn(|k| self.normalized.x2[sample[k]]);
                relative_pose_5pt(&x1, &x2, &mut poses)
            }
            SampleKind::Affine => {
                let acs: [AffineCorrespondence; 2] =
                    std::array::from_fn(|k| self.normalized.ac(sample[k]));
                relative_pose_2ac(&acs, &mut poses)
            }
            SampleKind::Hybrid => {
                let x1 = [self.normalized.x1[sample[1]], self.normalized.x1[sample[2]]];
                let x2 = [self.normalized.x2[sample[1]], self.normalized.x2[sample[2]]];
                relative_pose_1ac2pt(&self.normalized.ac(sample[0]), &x1, &x2, &mut poses)
            }
        };
        out.extend(poses[..n].iter().map(|p| self.model(*p)));
    }

    fn fit_nonminimal(&self, indices: &[usize], _weights: Option<&[f64]>) -> Option<PoseModel> {
        let x1: Vec<Vec2> = indices.iter().map(|&i| self.normalized.x1[i]).collect();
        let x2: Vec<Vec2> = indices.iter().map(|&i| self.normalized.x2[i]).collect();
        let mut e = [Mat3::zeros(); 1];
        let acs: Vec<AffineCorrespondence> = if indices.len() < 8 && self.normalized.has_affine() {
            indices.iter().map(|&i| self.normalized.ac(i)).collect()
        } else {
            Vec::new()
        };
        if essential_lsq(&x1, &x2, &acs, &mut e) != 1 {
            return None;
        }
        let (pose, in_front) = pose_from_essential(&e[0], &x1, &x2).ok()?;
        (in_front > 0).then(|| self.model(pose))
    }

    fn residuals(&self, m: &PoseModel, start: usize, out: &mut [f64]) {
        epipolar_residuals(
            self.pixels,
            &m.fundamental,
            &self.affine_score(),
            start,
            out,
        );
        let end = start + out.len();
        let (x1, x2) = (
            &self.normalized.x1[start..end],
            &self.normalized.x2[start..end],
        );
        let cap = self.cheirality_cap_sq;
        // Slices and a branch-free kernel, so that the loop vectorises.
        dispatch(
            #[inline(always)]
            || {
                for ((o, x1), x2) in out.iter_mut().zip(x1).zip(x2) {
                    *o = behind_is_outlier(&m.pose, x1, x2, *o, cap);
                }
            },
        );
    }

    fn residuals_at(&self, m: &PoseModel, indices: &[usize], out: &mut [f64]) {
        epipolar_residuals_at(
            self.pixels,
            &m.fundamental,
            &self.affine_score(),
            indices,
            out,
        );
        let cap = self.cheirality_cap_sq;
        for (idx, out) in indices.chunks(BLOCK).zip(out.chunks_mut(BLOCK)) {
            let x1 = gather(idx, |i| self.normalized.x1[i]);
            let x2 = gather(idx, |i| self.normalized.x2[i]);
            dispatch(
                #[inline(always)]
                || {
                    for ((o, x1), x2) in out.iter_mut().zip(&x1).zip(&x2) {
                        *o = behind_is_outlier(&m.pose, x1, x2, *o, cap);
                    }
                },
            );
        }
    }

    /// Levenberg–Marquardt on the manifold (R, t ∈ S²) of the pixel Sampson error (plus, with
    /// `options.affine`, the affine terms of `epipolar_lm`).
    fn refine(
        &self,
        model: &PoseModel,
        inliers: &[usize],
        loss: &Loss,
        options: &LmOptions,
    ) -> Option<PoseModel> {
        let mut m = *model;
        for _ in 0..epipolar_lm::AFFINE_ROUNDS {
            let affine = epipolar_lm::affine_terms(
                self.pixels,
                &m.fundamental,
                inliers,
                self.confidence,
                options,
            );
            let lambda = affine.map(|t| t.lambda);
            let fit = PoseFit {
                problem: self,
                affine,
            };
            m = levenberg_marquardt(&fit, &m, inliers, loss, options).0;
            if !epipolar_lm::rescale_again(
                self.pixels,
                &m.fundamental,
                inliers,
                self.confidence,
                lambda,
            ) {
                break;
            }
        }
        Some(m)
    }
}

/// Two unit vectors completing `t` (unit) to an orthonormal basis.
fn tangent_basis(t: &Vec3) -> (Vec3, Vec3) {
    let helper = if t.x.abs() < 0.9 {
        Vec3::x()
    } else {
        Vec3::y()
    };
    let b1 = t.cross(&helper).normalize();
    (b1, t.cross(&b1))
}

/// The least-squares problem of [`RelativePoseProblem::refine`]: its data, with or without the
/// affine terms.
struct PoseFit<'p, 'a> {
    problem: &'p RelativePoseProblem<'a>,
    affine: Option<epipolar_lm::AffineTerms<'a>>,
}

/// Pose refinement: R ← R·exp(\[ω\]×), t ← (t + α₁b₁ + α₂b₂)/‖·‖, θ = (ω, α), 5 degrees of
/// freedom. ∂E/∂ω_k = \[t\]× R \[e_k\]×, ∂E/∂α_i = \[b_i\]× R, and ∂F = K2⁻ᵀ ∂E K1⁻¹.
impl LeastSquares for PoseFit<'_, '_> {
    type Model = PoseModel;

    fn dof(&self) -> usize {
        5
    }

    fn cost(&self, m: &PoseModel, indices: &[usize], loss: &Loss) -> f64 {
        let data = self.problem.pixels;
        epipolar_lm::cost(data, &m.fundamental, indices, loss)
            + self.affine.as_ref().map_or(0.0, |t| {
                epipolar_lm::affine_cost(data, &m.fundamental, indices, t)
            })
    }

    fn normal_equations<const COST: bool>(
        &self,
        m: &PoseModel,
        indices: &[usize],
        loss: &Loss,
        jtj: &mut Mat9,
        jtr: &mut Vec9,
    ) -> f64 {
        let (r, t) = (&m.pose.r, &m.pose.t);
        let (b1, b2) = tangent_basis(t);
        let p = self.problem;
        let (k1i, k2it) = (p.k1.inverse(), p.k2.inverse().transpose());
        let tx = skew(t);
        let de = [
            tx * r * skew(&Vec3::x()),
            tx * r * skew(&Vec3::y()),
            tx * r * skew(&Vec3::z()),
            skew(&b1) * r,
            skew(&b2) * r,
        ];
        let basis = de.map(|d| k2it * d * k1i);
        let f = &m.fundamental;
        let mut cost = epipolar_lm::normal_equations(p.pixels, f, &basis, indices, loss, jtj, jtr);
        if let Some(t) = &self.affine {
            cost += epipolar_lm::affine_normal_equations(p.pixels, f, &basis, indices, t, jtj, jtr);
        }
        cost
    }

    fn retract(&self, m: &PoseModel, d: &Vec9) -> PoseModel {
        let w = Vec3::new(d[0], d[1], d[2]);
        let angle = w.norm();
        let rot = if angle > 0.0 {
            affcorr_geom::synthetic::rotation_about(&(w / angle), angle)
        } else {
            Mat3::identity()
        };
        let (b1, b2) = tangent_basis(&m.pose.t);
        let t = (m.pose.t + b1 * d[3] + b2 * d[4]).normalize();
        self.problem.model(Pose {
            r: m.pose.r * rot,
            t,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use affcorr_geom::synthetic::PlaneScene;
    use rand::SeedableRng;

    #[test]
    fn a_point_behind_a_camera_is_an_outlier_even_on_its_epipolar_line() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(3);
        let scene = PlaneScene::random(&mut rng);
        let pixel = |k: &Intrinsics, x: &Vec3| {
            let p = k.matrix() * x;
            Vec2::new(p.x / p.z, p.y / p.z)
        };
        // X in front of both cameras, and −X: same image in camera 1, and its image in camera 2
        // lies on the same epipolar line, but it triangulates behind the cameras.
        let x = Vec3::new(0.1, -0.2, 4.0);
        let (front, behind) = (
            scene.pose.r * x + scene.pose.t,
            -scene.pose.r * x + scene.pose.t,
        );
        let data = Correspondences {
            x1: vec![pixel(&scene.k1, &x); 2],
            x2: vec![pixel(&scene.k2, &front), pixel(&scene.k2, &behind)],
            a: Vec::new(),
        };
        let problem =
            RelativePoseProblem::new(&data, scene.k1, scene.k2, SampleKind::Points, 0.0, 8.0);
        let model = problem.model(scene.pose);
        let mut r = [0.0; 2];
        problem.residuals(&model, 0, &mut r);
        assert!(r[0] < 1e-12, "{r:?}");
        assert_eq!(r[1], f64::INFINITY);
        // The epipolar constraint alone accepts it.
        let mut sampson = [0.0; 2];
        epipolar_residuals(
            &data,
            &model.fundamental,
            &AffineScore::NONE,
            0,
            &mut sampson,
        );
        assert!(sampson[1] < 1e-12, "{sampson:?}");
        // The SPRT's indexed form agrees.
        let mut at = [0.0; 2];
        problem.residuals_at(&model, &[1, 0], &mut at);
        assert_eq!(at, [r[1], r[0]]);
    }
}
